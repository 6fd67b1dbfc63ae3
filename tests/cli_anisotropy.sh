#!/usr/bin/env bash
# KHR_materials_anisotropy (core/anisotropy.c, the anisotropic GGX of
# core/bsdf.c) as a user meets it, on the bundled Cornell box whose floor is
# made a rough anisotropic metal:
#   a. loading: --json effects name "anisotropy"; an anisotropyStrength of 0
#      renders the same pixels as no extension (nothing of it is computed); a
#      strength outside [0, 1] is refused naming its JSON path, no image left;
#      the lamp sample (strength 1, an 8-bit KTX2 anisotropy texture) loads
#      without an anisotropy warning and lists its strength as a parameter
#   b. the lobe shows and turns: the floor's reflection of the lamp with the
#      anisotropy along the tangent and turned a quarter differ from each
#      other and from the isotropic floor by far more than two seeds of one
#      scene do; turned half a turn, the same lobe: within the noise
#   c. params lists anisotropyStrength of anisotropic materials only; fdcheck,
#      prb and tape, of the strength, the roughness and the base colour of the
#      anisotropic floor agree with finite differences, the strength and the
#      colour resolved (more than 4 standard errors from 0);
#      attached and mis sampling agree too (the frame turns with the moving
#      hit point: d_anisotropy_frame); KHR_materials_specular textures, which
#      have no uv adjoint, are refused under attached sampling; derivative
#      sampling runs (this floor's strength, 0.5, leaves its roughness to the
#      forward strategies: path_deriv.h); on the gold sphere mildly
#      anisotropic (strength 0.1, roughness 0.15) the roughness gets the
#      stretched lobe's antithetic pair: its derivative agrees with finite
#      differences in prb and tape with a standard error well below detached
#      sampling's
#   d. optimize moves anisotropyStrength towards a target's and writes it
#      into the extension; the output passes the glTF validator and renders
# Run by tests/run.sh (env: DRENDER, DR_TESTDIR); also runs alone.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
cli_setup anisotropy
require_drender
box=$DR_TESTDIR/../scenes/cornell-box.gltf
ln -sf "$DR_TESTDIR/../scenes/cornell-box.bin" "$DR_TESTDIR/../scenes/cornell-box-checker.png" "$tmp/"

# floor SCENE.gltf 'KHR_materials_anisotropy object' [roughness]: the box, its
# floor a white-ish metal of that roughness (0.3) with that extension (none: '')
floor() {
    python3 -c "
import json, sys
d = json.load(open(sys.argv[1]))
m = d['materials'][5]
m['pbrMetallicRoughness'] = {'baseColorFactor': [0.9, 0.85, 0.8, 1], 'metallicFactor': 1, 'roughnessFactor': float(sys.argv[4])}
if sys.argv[3]:
    m['extensions'] = {'KHR_materials_anisotropy': json.loads(sys.argv[3])}
    d.setdefault('extensionsUsed', []).append('KHR_materials_anisotropy')
json.dump(d, open(sys.argv[2], 'w'))" "$box" "$tmp/$1" "$2" "${3:-0.3}" || fail "could not write $1"
}
R="--res 32x32 --spp 8"

# ---- a. loading ----
floor aniso.gltf '{"anisotropyStrength": 0.8}'
run render "$tmp/aniso.gltf" $R -o aniso.exr --json
expect_rc 0 "render of the anisotropic floor"
expect_in out '"anisotropy"' "--json names the anisotropy"
grep -q "anisotropy" "$tmp/err" && fail "a warning about the anisotropy: $(cat "$tmp/err")"
floor zero.gltf '{"anisotropyStrength": 0, "anisotropyRotation": 1}'
floor iso.gltf ''
run render "$tmp/zero.gltf" $R -o zero.exr --json
expect_rc 0 "render with anisotropyStrength 0"
grep -qF '"anisotropy"' "$tmp/out" && fail "an anisotropyStrength of 0 counts as anisotropy"
run render "$tmp/iso.gltf" $R -o iso.exr
# (pixels: the files carry the time they were written)
oiiotool --diff --fail 0 --warn 0 zero.exr iso.exr >/dev/null || fail "anisotropyStrength 0 changed the image"
floor bad.gltf '{"anisotropyStrength": 1.5}'
run render "$tmp/bad.gltf" $R -o bad.exr
check_failed 3 "bad.gltf|/materials/5/extensions/KHR_materials_anisotropy/anisotropyStrength|[0, 1]"
[ -e bad.exr ] && fail "a refused scene left an image"
find_samples
lamp=$samples/AnisotropyBarnLamp-KTX2/glTF/AnisotropyBarnLamp.gltf
run params "$lamp"
expect_rc 0 "params of the lamp"
grep -q "anisotropy" "$tmp/err" && fail "the lamp's anisotropy was warned about: $(cat "$tmp/err")"
expect_in out "/materials/0/extensions/KHR_materials_anisotropy/anisotropyStrength" "the lamp's anisotropy is a parameter"
run render "$lamp" --res 24x24 --spp 4 --env 1 -o lamp.exr --json
expect_rc 0 "render of the lamp"
expect_in out '"anisotropy"' "the lamp renders with its anisotropy"

# ---- b. the lobe shows and turns ----
# mean absolute difference of two images over the floor's lower half
mad() { oiiotool "$1" "$2" --sub --abs --cut 32x16+0+16 --printstats | awk '/Stats Avg/ { print ($3 + $4 + $5) / 3; exit }'; }
floor along.gltf '{"anisotropyStrength": 1}'
floor across.gltf '{"anisotropyStrength": 1, "anisotropyRotation": 1.5707963267948966}'
floor back.gltf '{"anisotropyStrength": 1, "anisotropyRotation": 3.141592653589793}'
for s in iso along across back; do
    run render "$tmp/$s.gltf" --res 32x32 --spp 256 -o "$s.exr"
    expect_rc 0 "render of $s"
done
run render "$tmp/iso.gltf" --res 32x32 --spp 256 --seed 7 -o iso7.exr
noise=$(mad iso.exr iso7.exr)
turned=$(mad along.exr across.exr)
vs_iso=$(mad across.exr iso.exr)
half=$(mad along.exr back.exr)
echo "mean |difference| on the floor: two seeds $noise, along/across $turned, across/isotropic $vs_iso, along/half a turn $half"
awk -v n="$noise" -v t="$turned" -v i="$vs_iso" -v h="$half" 'BEGIN { exit !(t > 4 * n && i > 4 * n && h < 2 * n) }' ||
    fail "the anisotropic lobe does not show or turn as it should"

# ---- c. params and fdcheck ----
run params "$tmp/aniso.gltf"
expect_rc 0 "params of the anisotropic floor"
[ "$(grep -c "KHR_materials_anisotropy" "$tmp/out")" -eq 1 ] || fail "expected the floor's anisotropyStrength alone"
floor fd.gltf '{"anisotropyStrength": 0.5, "anisotropyRotation": 1.5707963267948966}' 0.25
P="--param /materials/5/extensions/KHR_materials_anisotropy/anisotropyStrength \
--param /materials/5/pbrMetallicRoughness/roughnessFactor --param /materials/5/pbrMetallicRoughness/baseColorFactor"
for est in prb tape; do
    for smp in detached attached mis derivative; do
        run fdcheck "$tmp/fd.gltf" $P --res 24x24 --spp 16 --batches 8 --estimator $est --sampling $smp
        expect_rc 0 "fdcheck of the anisotropic floor ($est, $smp)"
        # (the strength and the colour stand out of their noise; the roughness's
        # effect on this projection is within it, and agreeing is all it shows)
        # (attached sampling's strength is 10 times as noisy here, rough lobes
        # being its weak case: agreeing, and the colour resolved, is what it shows)
        awk -v need_a="$([ $smp = attached ] || [ $smp = mis ] && echo 0 || echo 1)" \
            '$1 ~ /anisotropyStrength$/ { a = ($2 > 0 ? $2 : -$2) > 4 * $4 } $1 ~ /baseColorFactor\[0\]$/ \
            { c = $2 > 4 * $4 } END { exit !((a || !need_a) && c) }' "$tmp/out" ||
            fail "the anisotropy's derivatives are not resolved ($est, $smp): $(cat "$tmp/out")"
    done
done
cat "$tmp/out"
python3 -c "
import json, sys
d = json.load(open(sys.argv[1]))
m = d['materials'][4]
m['pbrMetallicRoughness']['roughnessFactor'] = 0.15
m['extensions'] = {'KHR_materials_anisotropy': {'anisotropyStrength': 0.1, 'anisotropyRotation': 0.5}}
d.setdefault('extensionsUsed', []).append('KHR_materials_anisotropy')
json.dump(d, open(sys.argv[2], 'w'))" "$box" "$tmp/mild.gltf" || fail "could not write mild.gltf"
# (the roughness's effect on fdcheck's projection is small here: agreeing,
# and derivative sampling's standard error well below detached sampling's,
# 0.6x at most (by hand, seeds 1-3: 0.24-0.45x), is what shows the pair at work)
mild_se() { awk '$1 ~ /roughnessFactor$/ { print $4 }' "$tmp/out"; }
run fdcheck "$tmp/mild.gltf" --param /materials/4/pbrMetallicRoughness/roughnessFactor --res 32x32 --spp 64 \
    --batches 8 --estimator prb --sampling detached
expect_rc 0 "fdcheck of the mildly anisotropic sphere's roughness (prb, detached)"
se_detached=$(mild_se)
for est in prb tape; do
    run fdcheck "$tmp/mild.gltf" --param /materials/4/pbrMetallicRoughness/roughnessFactor --res 32x32 --spp 64 \
        --batches 8 --estimator $est --sampling derivative
    expect_rc 0 "fdcheck of the mildly anisotropic sphere's roughness ($est, derivative)"
    awk -v d="$se_detached" -v s="$(mild_se)" 'BEGIN { exit !(s > 0 && s < 0.6 * d) }' ||
        fail "derivative sampling's standard error $(mild_se) is not well below detached's $se_detached ($est)"
done
# KHR_materials_specular's textures have no uv adjoint either: attached refused, detached runs
python3 -c "
import json, sys
d = json.load(open(sys.argv[1]))
d['materials'][1]['extensions'] = {'KHR_materials_specular': {'specularTexture': {'index': 0}}}
json.dump(d, open(sys.argv[2], 'w'))" "$box" "$tmp/spec.gltf" || fail "could not write spec.gltf"
run grad "$tmp/spec.gltf" --param /materials/red/pbrMetallicRoughness/roughnessFactor --sampling attached --res 8x8 -o g.exr
check_failed 2 "attached sampling|specular textures|'red'|--sampling detached"
run grad "$tmp/spec.gltf" --param /materials/red/pbrMetallicRoughness/roughnessFactor --sampling detached --res 8x8 -o g.exr
expect_rc 0 "detached sampling with a specular texture"

# ---- d. optimize ----
floor target.gltf '{"anisotropyStrength": 0.9, "anisotropyRotation": 1.5707963267948966}' 0.2
floor start.gltf '{"anisotropyStrength": 0.3, "anisotropyRotation": 1.5707963267948966}' 0.2
run render "$tmp/target.gltf" --res 32x32 --spp 64 -o target.exr
expect_rc 0 "the target's render"
mkdir -p "$tmp/fit"
run optimize "$tmp/start.gltf" --target target.exr \
    --param /materials/checker-floor/extensions/KHR_materials_anisotropy/anisotropyStrength \
    --iters 30 --spp 8 --lr 0.05 -o "$tmp/fit/fit.gltf" --out-dir "$tmp/fit"
expect_rc 0 "optimize of anisotropyStrength"
json_check "$tmp/fit/fit.gltf" '
d["materials"][5]["extensions"]["KHR_materials_anisotropy"]["anisotropyStrength"] > 0.6 and
d["materials"][5]["pbrMetallicRoughness"]["roughnessFactor"] == 0.2'
ensure_gltf_validator
validate_gltf "$tmp/fit/fit.gltf" || fail "the fitted scene does not validate"
run render "$tmp/fit/fit.gltf" --res 16x16 --spp 2 -o fit.exr
expect_rc 0 "render of the fitted scene"
echo "PASS"
