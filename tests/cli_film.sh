#!/usr/bin/env bash
# The film from the command line (issue 14): --filter and --crop for render,
# grad, fdcheck and optimize, and the standard error's parts.
#   a. render --crop equals the same rectangle of the full render, bit for
#      bit (oiiotool --diff), for box and gaussian; --filter changes the image
#   b. grad --crop: forward images are the crop's size; reverse mode with a
#      full-frame target and with a crop-sized one (--res = the frame) gives
#      the same gradient, bit for bit; --json names filter and crop
#   c. fdcheck --crop --filter gaussian agrees with finite differences
#   d. optimize --crop recovers an albedo to 0.01 from a cropped target (crop-sized
#      and full-frame targets: the same run, to the last digit), and its
#      per-iteration --json carries gradient and gradient_stderr
#   e. errors: bad --filter, bad --crop, a crop outside the frame, a
#      crop-sized target without --res, a target of neither size (exit 2,
#      nothing written)
# Run by tests/run.sh (env: DRENDER, DR_TESTDIR); also runs alone.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
data=$DR_TESTDIR/data/optimize
cli_setup film
require_drender
red=/materials/red/pbrMetallicRoughness/baseColorFactor
albedo=/materials/wall/pbrMetallicRoughness/baseColorFactor
albedo_idx=/materials/0/pbrMetallicRoughness/baseColorFactor
json_check() {
    python3 - "$1" "$2" <<'EOF' || fail "JSON check failed: $2"
import json, math, sys
d = json.loads(open(sys.argv[1]).read().strip().splitlines()[-1])
sys.exit(0 if eval("(" + sys.argv[2] + ")") else 1)
EOF
}
# same_image A B: oiiotool finds no difference at all
same_image() { oiiotool "$1" "$2" --diff --fail 0 --failpercent 0 --warn 0 >/dev/null 2>&1; }

# ---- a. render ----
for f in box gaussian:0.6; do
    run render -o full.exr --res 40x30 --spp 8 --seed 3 --filter "$f"
    expect_rc 0 "render full ($f)"
    run render -o crop.exr --res 40x30 --spp 8 --seed 3 --filter "$f" --crop 7,5,20,13 --threads 1 --json
    expect_rc 0 "render --crop ($f)"
    json_check "$tmp/out" 'd["crop"] == [7, 5, 20, 13] and d["width"] == 40 and d["filter"] == "'"$f"'"'
    oiiotool --info crop.exr | grep -q '20 x  *13' || fail "render --crop: crop.exr should be 20x13: $(oiiotool --info crop.exr)"
    oiiotool full.exr --cut 20x13+7+5 --origin +0+0 --fullsize 20x13+0+0 -o cut.exr
    same_image cut.exr crop.exr || fail "render --crop ($f): not the full render's rectangle: $(oiiotool cut.exr crop.exr --diff 2>&1)"
    cp full.exr "full-$f.exr"
done
same_image full-box.exr full-gaussian:0.6.exr && fail "--filter gaussian:0.6 should change the image"

# ---- b. grad ----
run render -o t.exr --res 24x20 --spp 64 --seed 5
expect_rc 0 "render the target"
oiiotool t.exr --cut 12x10+2+3 --origin +0+0 --fullsize 12x10+0+0 -o tc.exr
run grad --param "$red" --res 24x20 --crop 2,3,12,10 --spp 4 -o d.exr --filter tent
expect_rc 0 "grad forward --crop"
oiiotool --info d.exr | grep -q '12 x  *10' || fail "grad forward --crop: d.exr should be 12x10"
set_red="--set $red=0.3,0.3,0.3"
run grad --target t.exr --param "$red" --crop 2,3,12,10 --spp 8 $set_red --json
expect_rc 0 "grad reverse --crop, full-frame target"
cp "$tmp/out" "$tmp/full.json"
run grad --target tc.exr --res 24x20 --param "$red" --crop 2,3,12,10 --spp 8 $set_red --json
expect_rc 0 "grad reverse --crop, crop-sized target"
cp "$tmp/out" "$tmp/crop.json"
python3 - "$tmp/full.json" "$tmp/crop.json" <<'EOF' || fail "grad --crop: full-frame and crop-sized targets should give the same gradient"
import json, sys
a, b = (json.load(open(p)) for p in sys.argv[1:3])
pa, pb = a["parameters"][0], b["parameters"][0]
assert pa["gradient"] == pb["gradient"] and pa["stderr"] == pb["stderr"] and a["loss"] == b["loss"]
assert a["crop"] == [2, 3, 12, 10] and a["filter"] == "box" and a["width"] == 24
assert all(x != 0 for x in pa["gradient"])
EOF
# the crop's loss is the loss over its pixels: a crop elsewhere differs
run grad --target t.exr --param "$red" --crop 10,3,12,10 --spp 8 $set_red --json
expect_rc 0 "grad reverse, another crop"
json_check "$tmp/out" 'd["loss"] != '"$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["loss"])' "$tmp/full.json")"

# ---- c. fdcheck ----
run fdcheck --param "$red" --res 16x16 --crop 4,4,8,8 --filter gaussian:0.8 --spp 8 --batches 6 --json
expect_rc 0 "fdcheck --crop --filter gaussian"
json_check "$tmp/out" 'd["agree"] and d["crop"] == [4, 4, 8, 8] and d["filter"] == "gaussian:0.8"'

# ---- d. optimize on a crop ----
run render "$data/diffuse.gltf" -o dt.exr --res 24x24 --spp 256 --max-depth 3 --seed 11
expect_rc 0 "render the diffuse target"
oiiotool dt.exr --cut 12x14+6+4 --origin +0+0 --fullsize 12x14+0+0 -o dtc.exr
opt="--param $albedo --set $albedo=0.3,0.3,0.3 --iters 80 --spp 16 --max-depth 3 --crop 6,4,12,14"
run optimize "$data/diffuse.gltf" --target dt.exr $opt --reference "$data/diffuse.gltf" --out-dir oa --json
expect_rc 0 "optimize --crop (full-frame target)"
json_check "$tmp/out" '(lambda e: e < 0.01)(d["reference_error"]["'"$albedo_idx"'"])'
head -n 1 "$tmp/out" >"$tmp/it1.json"
json_check "$tmp/it1.json" 'all(len(d[k]["'"$albedo_idx"'"]) == 3 for k in ["gradient", "gradient_stderr"])
and all(x > 0 for x in d["gradient_stderr"]["'"$albedo_idx"'"])'
oiiotool --info oa/after.png | grep -q '12 x  *14' || fail "optimize --crop: after.png should show the crop (12x14)"
run optimize "$data/diffuse.gltf" --target dtc.exr --res 24x24 $opt --out-dir ob --json
expect_rc 0 "optimize --crop (crop-sized target)"
cut -d, -f1,2 oa/loss.csv >"$tmp/la"
cut -d, -f1,2 ob/loss.csv >"$tmp/lb"
[ "$(wc -l <"$tmp/la")" -eq 81 ] || fail "optimize --crop: loss.csv should have 80 rows"
cmp -s "$tmp/la" "$tmp/lb" || fail "optimize --crop: crop-sized and full-frame targets should give the same run"

# ---- e. errors ----
expect_fail() {   # expect_fail CODE "N1|N2" ARGS...: exit CODE, the needles on stderr, no new files
    local want=$1 needles=$2 before
    shift 2
    before=$(ls -A)
    run "$@"
    check_failed "$want" "$needles"
    [ "$(ls -A)" = "$before" ] || fail "$*: left files behind"
}
expect_fail 2 "--filter|gauss|box, tent, gaussian" render --filter gauss -o x.png
expect_fail 2 "--filter|standard deviation" render --filter gaussian:0 -o x.png
expect_fail 2 "--crop|X,Y,W,H" render --crop 1,2,3 -o x.png
expect_fail 2 "--crop|X,Y,W,H" render --crop 1,2,0,4 -o x.png
expect_fail 2 "--crop 30,5,20,13|40x30" render --res 40x30 --crop 30,5,20,13 -o x.png
expect_fail 2 "tc.exr|crop's size|--res" grad --target tc.exr --param "$red" --crop 2,3,12,10
expect_fail 2 "t.exr|24x20|12x10" grad --target t.exr --res 30x30 --param "$red" --crop 2,3,12,10
expect_fail 2 "--crop|24x20" grad --target t.exr --param "$red" --crop 20,3,12,10
expect_fail 2 "--crop|16x16" fdcheck --param "$red" --res 16x16 --crop 10,10,8,8
expect_fail 2 "dtc.exr|--res" optimize "$data/diffuse.gltf" --target dtc.exr $opt --out-dir oc

echo "cli_film: all passed"
