#!/usr/bin/env bash
# --sampler independent|sobol from the command line.
#   a. render: the default is the independent sampler, bit for bit; sobol
#      gives a different image of the same mean, with a smaller error against
#      a high-sample reference at equal spp; --json names the sampler; a
#      sobol crop equals the same rectangle of the full sobol render
#   b. fdcheck --sampler sobol agrees for prb and tape, detached and attached
#   c. grad forward mode: prb and tape give the same derivative image with sobol
#   d. errors: an unknown sampler is a usage error naming the option
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
run render -o default.exr $R --spp 8
expect_rc 0 "render, default sampler"
run render -o indep.exr $R --spp 8 --sampler independent
expect_rc 0 "render --sampler independent"
same_image default.exr indep.exr || fail "the default sampler is not the independent one"
run render -o ref.exr --res 32x32 --seed 77 --spp 1024 --sampler sobol
expect_rc 0 "reference render"
run render -o sobol.exr $R --spp 16 --sampler sobol --json
expect_rc 0 "render --sampler sobol"
expect_in out '"sampler": "sobol"' "render --json names the sampler"
run render -o indep16.exr $R --spp 16
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

echo "cli_sampler: all passed"
