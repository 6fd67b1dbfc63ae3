#!/usr/bin/env bash
# --sampler independent|stratified|sobol from the command line.
#   a. render: the default is the sobol sampler, bit for bit, and grad's and
#      optimize's too (the independent one where a batch renders its own
#      primal; their --json says so); independent numbers give a
#      different image of the same mean, with a larger error against a
#      high-sample reference at equal spp; --json names the sampler; a
#      sobol crop equals the same rectangle of the full sobol render
#   b. fdcheck --sampler sobol agrees for prb and tape, detached and attached
#   c. grad forward mode: prb and tape give the same derivative image with sobol
#   d. errors: an unknown sampler is a usage error naming the option
#   e. stratified as sobol in a-c (crop, fdcheck with prb and tape, detached
#      and attached, at a spp that is not a square; prb = tape), the same
#      seed gives the same image, and on a smooth primal case (the Cornell box
#      with a diffuse sphere, direct light) the pixel RMS error at 64 spp of
#      stratified and sobol is well below independent's
# Run by tests/run.sh (env: DRENDER, DR_TESTDIR); also runs alone.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
cli_setup sampler
require_drender
same_image() { oiiotool "$1" "$2" --diff --fail 0 --failpercent 0 --warn 0 >/dev/null 2>&1; }
# rms A B: the RMS difference of two images (idiff's "RMS error")
rms() { idiff -a "$1" "$2" 2>&1 | awk '/RMS error/ { print $NF }'; }
R="--res 32x32 --seed 4"

# ---- a. render ----
run render -o default.exr $R --spp 8 --json
expect_rc 0 "render, default sampler"
expect_in out '"sampler": "sobol"' "render --json names sobol as the default sampler"
run render -o sobol8.exr $R --spp 8 --sampler sobol
expect_rc 0 "render --sampler sobol"
same_image default.exr sobol8.exr || fail "render's default sampler is not the sobol one"
run render -o indep.exr $R --spp 8 --sampler independent
expect_rc 0 "render --sampler independent"
same_image default.exr indep.exr && fail "render --sampler independent gave the default (sobol) image"
# grad's and optimize's default: sobol (forward mode, and reverse mode where
# the cross primal runs), independent where a batch renders its own primal
red=/materials/1/pbrMetallicRoughness/baseColorFactor
run grad --param $red -o dgrad.exr $R --spp 4 --json
expect_rc 0 "grad, default sampler"
expect_in out '"sampler": "sobol"' "grad's default sampler (forward mode) is the sobol one"
run render -o gtarget.exr $R --spp 16 --sampler independent
expect_rc 0 "render a target"
default_sampler() {   # default_sampler WANT PRIMAL GRAD-OPTIONS...: grad --json names WANT and runs PRIMAL
    local want=$1 primal=$2
    shift 2
    run grad --param $red --set $red=0.3,0.3,0.3 --target gtarget.exr $R "$@" --json
    expect_rc 0 "grad $*"
    expect_in out "\"sampler\": \"$want\"" "grad $*: the default sampler is $want"
    expect_in out "\"primal\": \"$primal\"" "grad $*: the $primal primal runs"
}
default_sampler sobol cross --spp 16
default_sampler independent separate --spp 4 --batches 4   # (one sample a batch)
default_sampler independent separate --spp 16 --primal separate
# the default is the sobol sampler itself: the same gradient to the last digit
run grad --param $red --set $red=0.3,0.3,0.3 --target gtarget.exr $R --spp 16
expect_rc 0 "grad, default sampler (text)"
cp "$tmp/out" grad_default.txt
grep -q "; prb, detached, sobol numbers, cross primal):" grad_default.txt ||
    fail "grad's text output does not name the numbers and the primal it ran"
run grad --param $red --set $red=0.3,0.3,0.3 --target gtarget.exr $R --spp 16 --sampler sobol
expect_rc 0 "grad --sampler sobol (text)"
cmp -s grad_default.txt "$tmp/out" || fail "grad's default gradient is not the sobol sampler's"
run optimize --param $red --set $red=0.3,0.3,0.3 --target gtarget.exr $R --iters 1 --out-dir opt --json
expect_rc 0 "optimize, default sampler"
expect_in out '"sampler": "sobol"' "optimize's default sampler is the sobol one"
run render -o ref.exr --res 32x32 --seed 77 --spp 1024 --sampler sobol
expect_rc 0 "reference render"
run render -o sobol.exr $R --spp 16 --sampler sobol --json
expect_rc 0 "render --sampler sobol"
expect_in out '"sampler": "sobol"' "render --json names the sampler"
run render -o indep16.exr $R --spp 16 --sampler independent
e_ind=$(rms ref.exr indep16.exr) e_sob=$(rms ref.exr sobol.exr)
awk -v a="$e_sob" -v b="$e_ind" 'BEGIN { exit !(a > 0 && a < 0.6 * b) }' ||
    fail "sobol's RMS error at 16 spp ($e_sob) is not well below independent's ($e_ind)"
echo "RMS error against a 1024-spp reference at 16 spp: independent $e_ind, sobol $e_sob"
run render -o crop.exr $R --spp 8 --sampler sobol --crop 5,7,12,9
expect_rc 0 "sobol crop"
run render -o full.exr $R --spp 8 --sampler sobol
oiiotool full.exr --cut 12x9+5+7 --origin +0+0 --fullpixels -o cut.exr >/dev/null 2>&1 || fail "oiiotool --cut"
same_image crop.exr cut.exr || fail "a sobol crop is not the same rectangle of the full sobol render"

# ---- b. fdcheck ----
albedo=/materials/1/pbrMetallicRoughness/baseColorFactor
rough=/materials/5/pbrMetallicRoughness/roughnessFactor
for est in prb tape; do
    for smp in detached attached; do
        run fdcheck --param "$albedo" --param "$rough" --estimator "$est" --sampling "$smp" --sampler sobol \
            --res 16x16 --spp 16 --batches 6
        expect_rc 0 "fdcheck --sampler sobol ($est, $smp)"
        expect_in out "entries agree" "fdcheck $est $smp verdict"
    done
done

# ---- c. grad forward: prb and tape agree ----
run grad --param "$albedo" -o dprb.exr $R --spp 4 --sampler sobol --estimator prb
expect_rc 0 "grad prb sobol"
run grad --param "$albedo" -o dtape.exr $R --spp 4 --sampler sobol --estimator tape
expect_rc 0 "grad tape sobol"
d=$(rms dprb.exr dtape.exr)
awk -v d="$d" 'BEGIN { exit !(d < 1e-6) }' || fail "prb and tape differ with sobol (RMS $d)"

# ---- d. errors ----
run render -o x.png $R --sampler halton
expect_rc 2 "unknown sampler"
expect_in err "--sampler" "the message names the option"
[ ! -e x.png ] || fail "an image was written after a usage error"

# ---- e. stratified ----
run render -o s1.exr $R --spp 12 --sampler stratified --json
expect_rc 0 "render --sampler stratified"
expect_in out '"sampler": "stratified"' "render --json names the stratified sampler"
run render -o s2.exr $R --spp 12 --sampler stratified --threads 1
same_image s1.exr s2.exr || fail "stratified: the same seed gave another image (threads 1 vs default)"
run render -o i12.exr $R --spp 12
same_image s1.exr i12.exr && fail "stratified gives the independent image"
run render -o scrop.exr $R --spp 12 --sampler stratified --crop 5,7,12,9
expect_rc 0 "stratified crop"
oiiotool s1.exr --cut 12x9+5+7 --origin +0+0 --fullpixels -o scut.exr >/dev/null 2>&1 || fail "oiiotool --cut"
same_image scrop.exr scut.exr || fail "a stratified crop is not the same rectangle of the full stratified render"
for est in prb tape; do
    for smp in detached attached; do
        # 12 spp: a padded 4x3 grid for 2D draws, 12 strata for 1D ones
        run fdcheck --param "$albedo" --param "$rough" --estimator "$est" --sampling "$smp" --sampler stratified \
            --res 16x16 --spp 12 --batches 6
        expect_rc 0 "fdcheck --sampler stratified ($est, $smp)"
        expect_in out "entries agree" "fdcheck stratified $est $smp verdict"
    done
done
run grad --param "$albedo" -o sprb.exr $R --spp 7 --sampler stratified --estimator prb
expect_rc 0 "grad prb stratified"
run grad --param "$albedo" -o stape.exr $R --spp 7 --sampler stratified --estimator tape
expect_rc 0 "grad tape stratified"
d=$(rms sprb.exr stape.exr)
awk -v d="$d" 'BEGIN { exit !(d < 1e-6) }' || fail "prb and tape differ with stratified (RMS $d)"

# A smooth primal case: the sphere made diffuse (no glossy fireflies), direct
# light only (max depth 2). Errors of two seeds are pooled; the reference has
# 4096 spp (its own RMS error is ~1/8 of sobol's at 64 spp).
python3 - "$DR_SCENES/cornell-box.gltf" diffuse.gltf <<'PY' || fail "diffuse scene"
import json, sys
d = json.load(open(sys.argv[1]))
for m in d["materials"]:
    if m["name"] == "rough-gold":
        m["pbrMetallicRoughness"].update(metallicFactor=0.0, roughnessFactor=1.0)
json.dump(d, open(sys.argv[2], "w"))
PY
cp "$DR_SCENES/cornell-box.bin" "$DR_SCENES/cornell-box-checker.png" .
D="diffuse.gltf --res 32x32 --max-depth 2"
run render $D -o dref.exr --spp 4096 --sampler sobol --seed 1000
expect_rc 0 "diffuse reference"
declare -A err
for smp in independent stratified sobol; do
    sq=0
    for seed in 1 2; do
        run render $D -o d.exr --spp 64 --sampler "$smp" --seed "$seed"
        expect_rc 0 "diffuse $smp seed $seed"
        sq=$(awk -v s="$sq" -v e="$(rms dref.exr d.exr)" 'BEGIN { print s + e * e }')
    done
    err[$smp]=$(awk -v s="$sq" 'BEGIN { printf "%.4g", sqrt(s / 2) }')
done
echo "diffuse Cornell box, direct light, 64 spp: RMS error independent ${err[independent]}, stratified ${err[stratified]}, sobol ${err[sobol]}"
for smp in stratified sobol; do
    awk -v a="${err[$smp]}" -v b="${err[independent]}" 'BEGIN { exit !(a > 0 && a < 0.5 * b) }' ||
        fail "$smp's RMS error at 64 spp (${err[$smp]}) is not below half of independent's (${err[independent]})"
done

echo "cli_sampler: all passed"
