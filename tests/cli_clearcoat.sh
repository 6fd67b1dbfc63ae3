#!/usr/bin/env bash
# KHR_materials_clearcoat (core/bsdf_coat.c) as a user meets it, on the bundled
# Cornell box with coats added:
#   a. loading: --json effects name "clearcoat"; a clearcoatFactor of 0 renders
#      the same pixels as no extension (nothing of the coat is computed); a factor
#      outside [0, 1] is refused naming its JSON path; the lamp sample, whose
#      clearcoatNormalTexture is its normalTexture, loads without a clearcoat
#      warning
#   b. the coat shows: a black floor under a smooth coat reflects the light
#      (black without it); a white clearcoatTexture gives the same pixels as
#      none, a black one the bare floor's light; params lists its image
#   c. params lists the coat's factors of coated materials only; fdcheck, prb
#      and tape, detached, attached and derivative, of both factors, a base
#      colour and a base roughness under the coat, on a scene where the
#      coat's derivatives are resolved (more than 4 standard errors from 0)
#   d. the default (auto) runs derivative-roughness sampling for a small
#      base roughness under a coat and for a coat's roughness below 0.3 (not
#      above), and says so
#   e. optimize moves clearcoatFactor towards a target's, writes it into the
#      extension; the output passes the glTF validator and renders
# Run by tests/run.sh (env: DRENDER, DR_TESTDIR); also runs alone.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
cli_setup clearcoat
require_drender
box=$DR_TESTDIR/../scenes/cornell-box.gltf
ln -sf "$DR_TESTDIR/../scenes/cornell-box.bin" "$DR_TESTDIR/../scenes/cornell-box-checker.png" "$tmp/"

# coat SCENE.gltf 'python edits of d': a copy of the bundled box
coat() {
    python3 -c "import json, sys; d = json.load(open(sys.argv[1])); $2; json.dump(d, open(sys.argv[2], 'w'))" \
        "$box" "$tmp/$1" || fail "could not write $1"
}
cc='d["materials"][M].setdefault("extensions", {})["KHR_materials_clearcoat"]'
coat coated.gltf "${cc/M/1} = {'clearcoatFactor': 0.8, 'clearcoatRoughnessFactor': 0.1}; \
${cc/M/5} = {'clearcoatFactor': 0.6, 'clearcoatRoughnessFactor': 0.25}"
R="--res 32x32 --spp 8"

# ---- a. loading ----
run render "$tmp/coated.gltf" $R -o coated.exr --json
expect_rc 0 "render of the coated box"
expect_in out '"clearcoat"' "--json names the clear coat"
coat zero.gltf "${cc/M/1} = {'clearcoatFactor': 0, 'clearcoatRoughnessFactor': 0.1}"
run render "$tmp/zero.gltf" $R -o zero.exr --json
expect_rc 0 "render with clearcoatFactor 0"
grep -qF '"clearcoat"' "$tmp/out" && fail "a clearcoatFactor of 0 counts as a clear coat"
run render "$box" $R -o plain.exr
# (pixels: the files carry the time they were written)
oiiotool --diff --fail 0 --warn 0 zero.exr plain.exr >/dev/null || fail "clearcoatFactor 0 changed the image"
coat bad.gltf "${cc/M/1} = {'clearcoatFactor': 1.5}"
run render "$tmp/bad.gltf" $R -o bad.exr
check_failed 3 "bad.gltf|/materials/1/extensions/KHR_materials_clearcoat/clearcoatFactor|[0, 1]"
[ -e bad.exr ] && fail "a refused scene left an image"
find_samples
if [ -d "$samples/AnisotropyBarnLamp-KTX2" ]; then
    run params "$samples/AnisotropyBarnLamp-KTX2/glTF/AnisotropyBarnLamp.gltf"
    expect_rc 0 "params of the lamp"
    grep -q "clear" "$tmp/err" && fail "the lamp's coat (its normal map is the base's) was warned about: $(cat "$tmp/err")"
    expect_in out "/materials/0/extensions/KHR_materials_clearcoat/clearcoatFactor" "the lamp's coat is a parameter"
else
    fail "the shared sample models were not found beside the checkout"
fi

# ---- b. a black floor under a smooth coat reflects the light ----
coat black.gltf "d['materials'][5]['pbrMetallicRoughness'] = {'baseColorFactor': [0, 0, 0, 1], 'roughnessFactor': 1}; \
d['materials'][5]['extensions'] = {'KHR_materials_specular': {'specularFactor': 0}}"
coat black_coat.gltf "d['materials'][5]['pbrMetallicRoughness'] = {'baseColorFactor': [0, 0, 0, 1], 'roughnessFactor': 1}; \
d['materials'][5]['extensions'] = {'KHR_materials_specular': {'specularFactor': 0}, \
'KHR_materials_clearcoat': {'clearcoatFactor': 1, 'clearcoatRoughnessFactor': 0.05}}"
# (floor pixels left of the sphere, right of the red wall; the bare floor's
# stray light there comes from pixel footprints that reach the box)
for s in black black_coat; do
    run render "$tmp/$s.gltf" --res 32x32 --spp 64 --crop 7,28,5,4 -o "$s.exr"
    expect_rc 0 "render of $s"
done
floor=$(oiiotool --stats black.exr | awk '/Stats Avg/ { print $3; exit }')
floor_coat=$(oiiotool --stats black_coat.exr | awk '/Stats Avg/ { print $3; exit }')
echo "black floor: mean red $floor bare, $floor_coat under a smooth coat"
awk -v a="$floor" -v b="$floor_coat" 'BEGIN { exit !(b > 5 * a && b > 0.003) }' ||
    fail "the coat does not reflect on a black floor ($floor bare, $floor_coat coated)"
# clearcoatTexture's R scales the coat: all white is the factor alone (the
# same pixels), all black no coat at all (the bare floor's light)
oiiotool --pattern constant:color=1,1,1 2x2 3 -d uint8 -o "$tmp/white.png" &&
    oiiotool --pattern constant:color=0,0,0 2x2 3 -d uint8 -o "$tmp/black.png" || fail "oiiotool could not write the masks"
for mask in white black; do
    coat "mask_$mask.gltf" "d['materials'][5]['pbrMetallicRoughness'] = {'baseColorFactor': [0, 0, 0, 1], 'roughnessFactor': 1}; \
d['images'].append({'uri': '$mask.png'}); d['textures'].append({'source': len(d['images']) - 1}); \
d['materials'][5]['extensions'] = {'KHR_materials_specular': {'specularFactor': 0}, \
'KHR_materials_clearcoat': {'clearcoatFactor': 1, 'clearcoatRoughnessFactor': 0.05, \
'clearcoatTexture': {'index': len(d['textures']) - 1}}}"
    run render "$tmp/mask_$mask.gltf" --res 32x32 --spp 64 --crop 7,28,5,4 -o "mask_$mask.exr"
    expect_rc 0 "render with a $mask clearcoatTexture"
    grep -q "clearcoat" "$tmp/err" && fail "a warning about the clearcoatTexture: $(cat "$tmp/err")"
done
# (pixels, not bytes: the headers differ)
oiiotool --diff --fail 0 --warn 0 mask_white.exr black_coat.exr >/dev/null || fail "a white clearcoatTexture changed the coat"
masked=$(oiiotool --stats mask_black.exr | awk '/Stats Avg/ { print $3; exit }')
[ "$masked" = "$floor" ] || fail "a black clearcoatTexture leaves a coat ($masked, bare $floor)"
run params "$tmp/mask_black.gltf"
expect_in out "/images/1 " "params lists the clearcoatTexture's image"

# ---- c. params and fdcheck ----
run params "$tmp/coated.gltf"
expect_rc 0 "params of the coated box"
[ "$(grep -c "KHR_materials_clearcoat" "$tmp/out")" -eq 4 ] || fail "expected the 4 coat factors of the 2 coated materials"
grep -q "^/materials/0/extensions/KHR_materials_clearcoat" "$tmp/out" && fail "an uncoated material's coat is listed"
# (a dark floor and the red wall under coats of roughness 0.3: the coat's
# share of the image is large enough that its derivatives are resolved)
coat fd.gltf "d['materials'][5]['pbrMetallicRoughness'] = {'baseColorFactor': [0.05, 0.05, 0.05, 1], 'roughnessFactor': 1}; \
${cc/M/5} = {'clearcoatFactor': 0.7, 'clearcoatRoughnessFactor': 0.3}; \
${cc/M/1} = {'clearcoatFactor': 0.8, 'clearcoatRoughnessFactor': 0.3}"
P="--param /materials/5/extensions/KHR_materials_clearcoat/clearcoatFactor \
--param /materials/1/extensions/KHR_materials_clearcoat/clearcoatRoughnessFactor \
--param /materials/1/extensions/KHR_materials_clearcoat/clearcoatFactor \
--param /materials/1/pbrMetallicRoughness/baseColorFactor --param /materials/1/pbrMetallicRoughness/roughnessFactor"
for est in prb tape; do
    for smp in detached attached derivative; do
        run fdcheck "$tmp/fd.gltf" $P --res 24x24 --spp 16 --batches 8 --estimator $est --sampling $smp
        expect_rc 0 "fdcheck of the coat ($est, $smp)"
        # the check means something only where the derivative stands out of its noise
        awk '$1 ~ /materials\/5\/.*clearcoatFactor$/ { f = $2 > 4 * $4 } $1 ~ /materials\/1\/.*clearcoatRoughnessFactor$/ \
            { r = -$2 > 4 * $4 } END { exit !(f && r) }' "$tmp/out" ||
            fail "the coat's derivatives are not resolved ($est, $smp): $(cat "$tmp/out")"
    done
done
cat "$tmp/out"

# ---- d. derivative sampling, auto ----
coat rough.gltf "${cc/M/1} = {'clearcoatFactor': 0.8}; d['materials'][1]['pbrMetallicRoughness']['roughnessFactor'] = 0.1"
run grad "$tmp/rough.gltf" --param /materials/1/pbrMetallicRoughness/roughnessFactor --res 8x8 -o g.exr --json
expect_rc 0 "grad with auto sampling on a coated material"
expect_in out '"sampling_effective": "derivative-roughness"' "auto samples for a small roughness under a coat"
expect_in err "chose derivative-roughness sampling" "auto says what it chose"
run grad "$tmp/coated.gltf" --param /materials/red/extensions/KHR_materials_clearcoat/clearcoatRoughnessFactor \
    --res 8x8 -o g.exr --json
expect_rc 0 "grad of a smooth coat's roughness"
expect_in out '"sampling_effective": "derivative-roughness"' "auto samples for a smooth coat's roughness"
expect_in err "clearcoatRoughnessFactor is 0.1, below 0.3" "the note names the coat's roughness"
# (a coat's own threshold, 0.3: between its two measured scenes' break-evens)
for r in 0.25 0.35; do
    coat c$r.gltf "${cc/M/1} = {'clearcoatFactor': 0.8, 'clearcoatRoughnessFactor': $r}"
    run grad "$tmp/c$r.gltf" --param /materials/red/extensions/KHR_materials_clearcoat/clearcoatRoughnessFactor \
        --res 8x8 -o g.exr --json
    expect_rc 0 "grad of a coat's roughness at $r"
    want=$([ $r = 0.25 ] && echo derivative-roughness || echo detached)
    expect_in out "\"sampling_effective\": \"$want\"" "auto runs $want at coat roughness $r"
done

# ---- e. optimize ----
coat target.gltf "${cc/M/1} = {'clearcoatFactor': 0.9, 'clearcoatRoughnessFactor': 0.05}"
coat start.gltf "${cc/M/1} = {'clearcoatFactor': 0.2, 'clearcoatRoughnessFactor': 0.05}"
run render "$tmp/target.gltf" --res 32x32 --spp 64 -o target.exr
expect_rc 0 "the target's render"
mkdir -p "$tmp/fit"
run optimize "$tmp/start.gltf" --target target.exr --param /materials/red/extensions/KHR_materials_clearcoat/clearcoatFactor \
    --iters 30 --spp 8 --lr 0.03 -o "$tmp/fit/fit.gltf" --out-dir "$tmp/fit"
expect_rc 0 "optimize of clearcoatFactor"
json_check "$tmp/fit/fit.gltf" '
d["materials"][1]["extensions"]["KHR_materials_clearcoat"]["clearcoatFactor"] > 0.45 and
d["materials"][1]["extensions"]["KHR_materials_clearcoat"]["clearcoatRoughnessFactor"] == 0.05'
ensure_gltf_validator
validate_gltf "$tmp/fit/fit.gltf" || fail "the fitted scene does not validate"
run render "$tmp/fit/fit.gltf" --res 16x16 --spp 2 -o fit.exr
expect_rc 0 "render of the fitted scene"
echo "PASS"
