#!/usr/bin/env bash
# KHR_materials_sheen (core/bsdf_sheen.c) as a user meets it, on the bundled
# Cornell box whose floor is made a dark cloth:
#   a. loading: --json effects name "sheen"; glTF's default sheen colour
#      (black) renders the same pixels as no extension (nothing of it is
#      computed); a colour or roughness outside [0, 1] is refused naming its
#      JSON path, no image left
#   b. the sheen shows: the floor with a white sheen differs from the bare
#      floor, and a smooth sheen from a rough one, by far more than two seeds
#      of one scene do
#   c. params lists sheenColorFactor and sheenRoughnessFactor of sheened
#      materials only; fdcheck, prb and tape, detached, attached and
#      derivative, of the sheen's colour and roughness and the base colour
#      agree with finite differences, the sheen's colour resolved (more than
#      4 standard errors from 0)
#   d. optimize moves sheenColorFactor towards a target's and writes it into
#      the extension; the output passes the glTF validator and renders
# Run by tests/run.sh (env: DRENDER, DR_TESTDIR); also runs alone.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
cli_setup sheen
require_drender
box=$DR_TESTDIR/../scenes/cornell-box.gltf
ln -sf "$DR_TESTDIR/../scenes/cornell-box.bin" "$DR_TESTDIR/../scenes/cornell-box-checker.png" "$tmp/"

# floor SCENE.gltf 'KHR_materials_sheen object': the box, its floor a dark
# red Lambertian cloth with that extension (none: '')
floor() {
    python3 -c "
import json, sys
d = json.load(open(sys.argv[1]))
m = d['materials'][5]
m['pbrMetallicRoughness'] = {'baseColorFactor': [0.25, 0.05, 0.08, 1], 'metallicFactor': 0, 'roughnessFactor': 1}
if sys.argv[3]:
    m['extensions'] = {'KHR_materials_sheen': json.loads(sys.argv[3])}
    d.setdefault('extensionsUsed', []).append('KHR_materials_sheen')
json.dump(d, open(sys.argv[2], 'w'))" "$box" "$tmp/$1" "$2" || fail "could not write $1"
}
R="--res 32x32 --spp 8"

# ---- a. loading ----
floor sheen.gltf '{"sheenColorFactor": [1, 1, 1], "sheenRoughnessFactor": 0.4}'
run render "$tmp/sheen.gltf" $R -o sheen.exr --json
expect_rc 0 "render of the sheened floor"
expect_in out '"sheen"' "--json names the sheen"
grep -q "sheen" "$tmp/err" && fail "a warning about the sheen: $(cat "$tmp/err")"
floor black.gltf '{"sheenColorFactor": [0, 0, 0], "sheenRoughnessFactor": 0.4}'
floor bare.gltf ''
run render "$tmp/black.gltf" $R -o black.exr --json
expect_rc 0 "render with a black sheen"
grep -qF '"sheen"' "$tmp/out" && fail "a black sheen counts as a sheen"
run render "$tmp/bare.gltf" $R -o bare.exr
# (pixels: the files carry the time they were written)
oiiotool --diff --fail 0 --warn 0 black.exr bare.exr >/dev/null || fail "a black sheen changed the image"
floor bad.gltf '{"sheenColorFactor": [1, 1.5, 1]}'
run render "$tmp/bad.gltf" $R -o bad.exr
check_failed 3 "bad.gltf|/materials/5/extensions/KHR_materials_sheen/sheenColorFactor/1|[0, 1]"
[ -e bad.exr ] && fail "a refused scene left an image"
floor bad2.gltf '{"sheenColorFactor": [1, 1, 1], "sheenRoughnessFactor": 2}'
run render "$tmp/bad2.gltf" $R -o bad2.exr
check_failed 3 "bad2.gltf|/materials/5/extensions/KHR_materials_sheen/sheenRoughnessFactor|[0, 1]"
[ -e bad2.exr ] && fail "a refused scene left an image"

# ---- b. the sheen shows ----
# mean absolute difference of two images over the floor's lower half
mad() { oiiotool "$1" "$2" --sub --abs --cut 32x16+0+16 --printstats | awk '/Stats Avg/ { print ($3 + $4 + $5) / 3; exit }'; }
floor smooth.gltf '{"sheenColorFactor": [1, 1, 1], "sheenRoughnessFactor": 0.1}'
floor rough.gltf '{"sheenColorFactor": [1, 1, 1], "sheenRoughnessFactor": 1}'
for s in bare smooth rough; do
    run render "$tmp/$s.gltf" --res 32x32 --spp 1024 -o "$s.exr"
    expect_rc 0 "render of $s"
done
run render "$tmp/bare.gltf" --res 32x32 --spp 1024 --seed 7 -o bare7.exr
noise=$(mad bare.exr bare7.exr)
vs_bare=$(mad rough.exr bare.exr)
smooth_rough=$(mad smooth.exr rough.exr)
echo "mean |difference| on the floor: two seeds $noise, rough sheen/bare $vs_bare, smooth/rough sheen $smooth_rough"
awk -v n="$noise" -v b="$vs_bare" -v r="$smooth_rough" 'BEGIN { exit !(b > 4 * n && r > 4 * n) }' ||
    fail "the sheen does not show, or its roughness does not change it"

# ---- c. params and fdcheck ----
run params "$tmp/sheen.gltf"
expect_rc 0 "params of the sheened floor"
[ "$(grep -c "KHR_materials_sheen" "$tmp/out")" -eq 2 ] || fail "expected the floor's two sheen factors alone"
floor fd.gltf '{"sheenColorFactor": [0.6, 0.7, 0.8], "sheenRoughnessFactor": 0.5}'
P="--param /materials/5/extensions/KHR_materials_sheen/sheenColorFactor \
--param /materials/5/extensions/KHR_materials_sheen/sheenRoughnessFactor \
--param /materials/5/pbrMetallicRoughness/baseColorFactor"
for est in prb tape; do
    for smp in detached attached mis derivative; do
        run fdcheck "$tmp/fd.gltf" $P --res 24x24 --spp 16 --batches 8 --estimator $est --sampling $smp
        expect_rc 0 "fdcheck of the sheened floor ($est, $smp)"
        awk '$1 ~ /sheenColorFactor\[0\]$/ { c = $2 > 4 * $4 } END { exit !c }' "$tmp/out" ||
            fail "the sheen colour's derivative is not resolved ($est, $smp): $(cat "$tmp/out")"
    done
done
cat "$tmp/out"

# ---- d. optimize ----
floor target.gltf '{"sheenColorFactor": [0.9, 0.9, 0.9], "sheenRoughnessFactor": 0.5}'
floor start.gltf '{"sheenColorFactor": [0.2, 0.2, 0.2], "sheenRoughnessFactor": 0.5}'
run render "$tmp/target.gltf" --res 32x32 --spp 64 -o target.exr
expect_rc 0 "the target's render"
mkdir -p "$tmp/fit"
run optimize "$tmp/start.gltf" --target target.exr \
    --param /materials/checker-floor/extensions/KHR_materials_sheen/sheenColorFactor \
    --iters 30 --spp 8 --lr 0.05 -o "$tmp/fit/fit.gltf" --out-dir "$tmp/fit"
expect_rc 0 "optimize of sheenColorFactor"
json_check "$tmp/fit/fit.gltf" '
min(d["materials"][5]["extensions"]["KHR_materials_sheen"]["sheenColorFactor"]) > 0.5 and
d["materials"][5]["extensions"]["KHR_materials_sheen"]["sheenRoughnessFactor"] == 0.5'
ensure_gltf_validator
validate_gltf "$tmp/fit/fit.gltf" || fail "the fitted scene does not validate"
run render "$tmp/fit/fit.gltf" --res 16x16 --spp 2 -o fit.exr
expect_rc 0 "render of the fitted scene"
echo "PASS"
