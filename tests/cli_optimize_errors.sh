#!/usr/bin/env bash
# drender optimize, the failing paths: every bad input must be rejected before
# any work, with a message on stderr naming the option or the file, nothing
# on stdout, the exit code below, and nothing left behind: no --out-dir (nor
# its parents) created, no -o file. A rejected --resume leaves an existing
# --out-dir as it was.
# Run by tests/run.sh (env: DRENDER, DR_TESTDIR); also runs alone.
#
# Expected exit codes (cli/cli.h, man/drender.1):
#   2 = usage error: target of the wrong size for --res, camera index out of
#       range, a parameter that is not differentiable (nearest names listed),
#       bad --set, -o not .gltf/.glb, --iters 0, --sampling bogus, --regularize -1,
#       --resume with a checkpoint for other parameters or beyond --iters
#   3 = input error: target missing, unreadable or with NaN pixels, scene or
#       --reference missing, --resume without a checkpoint
#   1 = other failures: -o into a directory that does not exist
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
data=$DR_TESTDIR/data/optimize
cli_setup optimize-errors
ncases=0
# expect_fail CODE "NEEDLE1|NEEDLE2|..." ARGS...
#   runs `drender optimize ARGS... --out-dir out/progress` in the work
#   directory and checks the exit code, that stderr contains every NEEDLE
#   (fixed strings), that stdout is empty and that the work directory holds
#   the same files as before (so out/ was not created).
expect_fail() {
    local want=$1 needles=$2 before
    shift 2
    ncases=$((ncases + 1))
    before=$(ls -AR "$work")
    run optimize "$@" --out-dir out/progress
    check_failed "$want" "$needles"
    [ "$(ls -AR "$work")" = "$before" ] || fail "files left behind in $work: $(ls -AR "$work")"
}

require_drender
[ -f "$data/diffuse.gltf" ] || fail "test scene $data/diffuse.gltf not found"

# inputs live in $tmp (outside the watched work directory)
scene=$data/diffuse.gltf
P=/materials/wall/pbrMetallicRoughness/baseColorFactor
R=/materials/wall/pbrMetallicRoughness/roughnessFactor
run render "$scene" -o "$tmp/target.exr" --res 16x16 --spp 4 --max-depth 2
[ "$rc" -eq 0 ] || fail "render the target"
T=$tmp/target.exr
echo "this is not an image" >"$tmp/not-an-image.exr"
# a 2x2 float PFM (read through OpenImageIO) with one NaN pixel
{ printf 'PF\n2 2\n-1.0\n'; printf '\000\000\300\177'; head -c 44 /dev/zero; } >"$tmp/nan.pfm"
fast=(--spp 1 --max-depth 2 --iters 2)

# ---- targets ----
expect_fail 2 "--target|16x16|--res|32x32" "$scene" --target "$T" --param "$P" --res 32x32 "${fast[@]}"
expect_fail 3 "--target|missing.exr" "$scene" --target "$tmp/missing.exr" --param "$P" "${fast[@]}"
expect_fail 3 "--target|not-an-image.exr" "$scene" --target "$tmp/not-an-image.exr" --param "$P" "${fast[@]}"
expect_fail 3 "--target|nan.pfm|not a finite number" "$scene" --target "$tmp/nan.pfm" --param "$P" "${fast[@]}"
expect_fail 3 "--target|missing.exr" "$scene" --target "$T" --target "1=$tmp/missing.exr" --param "$P" "${fast[@]}"
expect_fail 2 "--target 3=|camera 3|has 2 cameras" "$scene" --target "3=$T" --param "$P" "${fast[@]}"
expect_fail 2 "--target|camera 2" "$scene" --target "$T" --target "2=$T" --param "$P" "${fast[@]}"
expect_fail 2 "at least one --target" "$scene" --param "$P" "${fast[@]}"

# ---- parameters ----
expect_fail 2 "--param|baseColorFactr|nearest valid names|/materials/0/pbrMetallicRoughness/baseColorFactor" \
    "$scene" --target "$T" --param /materials/wall/pbrMetallicRoughness/baseColorFactr "${fast[@]}"
expect_fail 2 "--param|/materials/wall/doubleSided|nearest valid names" \
    "$scene" --target "$T" --param /materials/wall/doubleSided "${fast[@]}"
expect_fail 2 "--param is required" "$scene" --target "$T" "${fast[@]}"
expect_fail 2 "--set|2 values given|has 3" "$scene" --target "$T" --param "$P" --set "$P=0.5,0.5" "${fast[@]}"
expect_fail 2 "--set|4 values given|has 3" "$scene" --target "$T" --param "$P" --set "$P=0.5,0.5,0.5,0.5" "${fast[@]}"
expect_fail 2 "--set|6 values given|has 3" "$scene" --target "$T" --param "$P" --set "$P=0.5,0.5,0.5,0.5,0.5,0.5" "${fast[@]}"
expect_fail 2 "--set|1.5|outside|[0, 1]" "$scene" --target "$T" --param "$P" --set "$P=0.5,0.5,1.5" "${fast[@]}"
expect_fail 2 "--set|-0.1|outside" "$scene" --target "$T" --param "$R" --set "$R=-0.1" "${fast[@]}"
expect_fail 2 "--set|not a list of numbers" "$scene" --target "$T" --param "$P" --set "$P=0.5,0.5,nan" "${fast[@]}"
expect_fail 2 "--set|not a list of numbers" "$scene" --target "$T" --param "$P" --set "$P=red" "${fast[@]}"
expect_fail 2 "--set|POINTER=VALUE" "$scene" --target "$T" --param "$P" --set "$P" "${fast[@]}"
expect_fail 2 "--set|/materials/nope" "$scene" --target "$T" --param "$P" --set "/materials/nope/emissiveFactor=1,1,1" \
    "${fast[@]}"
expect_fail 2 "--set|/images/0|images cannot be set" "$data/texture-flat.gltf" --target "$T" --param /images/0 \
    --set "/images/0=0.5" "${fast[@]}"

# ---- options ----
expect_fail 2 "-o|result.png|.gltf or .glb" "$scene" --target "$T" --param "$P" -o out/result.png "${fast[@]}"
expect_fail 2 "-o|result|.gltf or .glb" "$scene" --target "$T" --param "$P" -o result "${fast[@]}"
expect_fail 1 "nodir" "$scene" --target "$T" --param "$P" -o nodir/result.gltf "${fast[@]}"
expect_fail 2 "--iters|0" "$scene" --target "$T" --param "$P" --spp 1 --iters 0
expect_fail 2 "--iters|-5" "$scene" --target "$T" --param "$P" --spp 1 --iters -5
expect_fail 2 "--lr|0" "$scene" --target "$T" --param "$P" "${fast[@]}" --lr 0
expect_fail 2 "--loss|l3" "$scene" --target "$T" --param "$P" "${fast[@]}" --loss l3
expect_fail 2 "--sampling|bogus|detached" "$scene" --target "$T" --param "$P" "${fast[@]}" --sampling bogus
expect_fail 2 "--regularize|-1" "$scene" --target "$T" --param "$P" "${fast[@]}" --regularize -1
expect_fail 2 "--estimator|magic" "$scene" --target "$T" --param "$P" "${fast[@]}" --estimator magic
expect_fail 2 "--checkpoint-every|0" "$scene" --target "$T" --param "$P" "${fast[@]}" --checkpoint-every 0
expect_fail 2 "--render-every|0" "$scene" --target "$T" --param "$P" "${fast[@]}" --render-every 0
expect_fail 2 "unknown option" "$scene" --target "$T" --param "$P" "${fast[@]}" --frobnicate
expect_fail 3 "missing.gltf" "$tmp/missing.gltf" --target "$T" --param "$P" "${fast[@]}"
expect_fail 3 "--reference|missing.gltf" "$scene" --target "$T" --param "$P" --reference "$tmp/missing.gltf" "${fast[@]}"
expect_fail 2 "--reference|does not have the same parameters" "$scene" --target "$T" --param "$P" \
    --reference "$data/glossy.gltf" "${fast[@]}"

# ---- --resume ----
expect_fail 3 "--resume|checkpoint.txt|cannot read checkpoint" "$scene" --target "$T" --param "$P" "${fast[@]}" --resume
# a checkpoint for other parameters (in an existing directory: nothing in it changes)
ck=$tmp/ck
run optimize "$scene" --target "$T" --param "$R" --param "$P" --spp 1 --max-depth 2 --iters 2 --out-dir "$ck"
[ "$rc" -eq 0 ] && [ -s "$ck/checkpoint.txt" ] || fail "set-up run for the --resume cases"
snapshot() { (cd "$ck" && ls -l --time-style=+%s.%N && cat checkpoint.txt loss.csv); }
before=$(snapshot)
resume_fail() {   # resume_fail CODE "NEEDLES" ARGS...: like expect_fail with --out-dir $ck --resume
    local want=$1 needles=$2
    shift 2
    ncases=$((ncases + 1))
    run optimize "$scene" --target "$T" --spp 1 --max-depth 2 "$@" --out-dir "$ck" --resume
    check_failed "$want" "$needles"
    [ "$(snapshot)" = "$before" ] || fail "a rejected --resume changed $ck"
}
resume_fail 2 "--resume|checkpoint holds|roughnessFactor|baseColorFactor|same --param list" --param "$P" --iters 4
resume_fail 2 "--resume|checkpoint holds" --param "$P" --param "$R" --iters 4
resume_fail 2 "--resume|more parameters|same --param list" --param "$R" --iters 4 --json
resume_fail 2 "--resume|iteration 2|beyond --iters 1" --param "$R" --param "$P" --iters 1
resume_fail 2 "--resume|fewer parameters|same --param list" --param "$R" --param "$P" --param /materials/wall/emissiveFactor --iters 4
head -c 60 "$ck/checkpoint.txt" >"$tmp/trunc.txt"
cp "$ck/checkpoint.txt" "$tmp/saved.txt" && cp "$tmp/trunc.txt" "$ck/checkpoint.txt"
before=$(snapshot)
resume_fail 3 "--resume|not a valid drender checkpoint" --param "$R" --param "$P" --iters 4
echo "$ncases rejected inputs: right exit codes and messages, nothing left behind"
