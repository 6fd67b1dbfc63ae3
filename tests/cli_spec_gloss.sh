#!/usr/bin/env bash
# KHR_materials_pbrSpecularGlossiness (gltf_load.cpp's load_spec_gloss) as a
# user meets it, on the bundled Cornell box whose checker floor is made a
# specular-glossiness material with an RGBA specular-glossiness texture:
#   a. it renders with no warning about the extension, and its pixels are
#      those of the metallic-roughness + KHR_materials_specular file the
#      mapping names (metallic 0, roughness texture G = 1 - A, specular
#      colour texture = the RGB, specularColorFactor = specularFactor / 0.04)
#      to float rounding, and differ from the file with the extension
#      dropped (so the extension is what changed them)
#   b. a mapped factor (base colour, metallic, roughness) of such a material
#      is refused as a parameter with the reason; its emission and the
#      diffuse texture's texels are parameters
#   c. a glossinessFactor outside [0, 1] is refused naming its JSON path, no
#      image left
#   d. optimize of the diffuse texture's texels writes a scene that keeps
#      the extension and the file's images and textures (not the derived
#      roughness texture), passes the glTF validator and renders
# Run by tests/run.sh (env: DRENDER, DR_TESTDIR); also runs alone.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
cli_setup spec_gloss
require_drender
box=$DR_TESTDIR/../scenes/cornell-box.gltf
ln -sf "$DR_TESTDIR/../scenes/cornell-box.bin" "$DR_TESTDIR/../scenes/cornell-box-checker.png" "$tmp/"
# the specular-glossiness texture: a coloured RGB over a ramp of A (PNG,
# 8-bit), and the roughness texture the mapping makes of it (G = 1 - A)
oiiotool --pattern fill:top=0.9,0.5,0.2:bottom=0.3,0.6,0.9 16x16 3 \
    --pattern fill:left=0.05:right=0.95 16x16 1 --chappend -d uint8 -o "$tmp/sg.png" >/dev/null ||
    fail "could not write sg.png"
oiiotool "$tmp/sg.png" --ch A --mulc -1 --addc 1 --ch 0,0,0 -d uint8 -o "$tmp/rough.png" >/dev/null ||
    fail "could not write rough.png"

# floor SCENE.gltf MODE: the box, its floor (material 5) as MODE: sg (the
# extension), mr (the metallic-roughness file it maps to), none (the
# extension dropped: the checker floor as it is), badgloss
floor() {
    python3 -c "
import json, sys
d = json.load(open(sys.argv[1]))
mode = sys.argv[3]
d['images'] += [{'uri': 'sg.png'}, {'uri': 'rough.png'}]
d['textures'] += [{'source': 1, 'sampler': 0}, {'source': 2, 'sampler': 0}]
m = d['materials'][5]
ext = {'diffuseFactor': [0.9, 0.8, 0.7, 1], 'specularFactor': [0.3, 0.2, 0.1], 'glossinessFactor': 1.0,
       'diffuseTexture': {'index': 0}, 'specularGlossinessTexture': {'index': 1}}
if mode == 'badgloss':
    ext['glossinessFactor'] = 1.5
if mode in ('sg', 'badgloss'):
    m['extensions'] = {'KHR_materials_pbrSpecularGlossiness': ext}
    d.setdefault('extensionsUsed', []).append('KHR_materials_pbrSpecularGlossiness')
elif mode == 'mr':
    m['pbrMetallicRoughness'] = {'baseColorFactor': [0.9, 0.8, 0.7, 1], 'baseColorTexture': {'index': 0},
                                 'metallicFactor': 0, 'roughnessFactor': 1, 'metallicRoughnessTexture': {'index': 2}}
    m['extensions'] = {'KHR_materials_specular': {'specularFactor': 1,
                       'specularColorFactor': [0.3 / 0.04, 0.2 / 0.04, 0.1 / 0.04],
                       'specularColorTexture': {'index': 1}}}
    d.setdefault('extensionsUsed', []).append('KHR_materials_specular')
json.dump(d, open(sys.argv[2], 'w'))" "$box" "$tmp/$1" "$2" || fail "could not write $1"
}
R="--res 48x48 --spp 16 --seed 3"

# ---- a. rendering ----
floor sg.gltf sg
floor mr.gltf mr
floor none.gltf none
run render "$tmp/sg.gltf" $R -o sg.exr
expect_rc 0 "render of the specular-glossiness floor"
grep -qi "glossiness\|not supported" "$tmp/err" && fail "a warning about the extension: $(cat "$tmp/err")"
run render "$tmp/mr.gltf" $R -o mr.exr
expect_rc 0 "render of the metallic-roughness equivalent"
run render "$tmp/none.gltf" $R -o none.exr
expect_rc 0 "render without the extension"
oiiotool --diff --fail 1e-5 --warn 1e-5 sg.exr mr.exr >"$tmp/diff" ||
    fail "the extension does not render as the file it maps to: $(cat "$tmp/diff")"
oiiotool --diff --fail 0.01 --warn 0.01 sg.exr none.exr >/dev/null &&
    fail "the extension did not change the image (its floor as the checker without it)"

# ---- b. parameters ----
run params "$tmp/sg.gltf"
expect_rc 0 "params"
grep -q "^/materials/5/pbrMetallicRoughness/" "$tmp/out" && fail "a mapped factor of the material is listed: $(cat "$tmp/out")"
expect_in out "/materials/5/emissiveFactor" "the material's emission is a parameter"
expect_in out "/images/0" "the diffuse texture's texels are a parameter"
grep -q "^/images/3" "$tmp/out" && fail "the derived roughness image is listed"
run grad "$tmp/sg.gltf" --target sg.exr --param /materials/5/pbrMetallicRoughness/roughnessFactor $R
check_failed 2 "pbrSpecularGlossiness|not parameters"

# ---- c. malformed ----
floor bad.gltf badgloss
run render "$tmp/bad.gltf" $R -o bad.exr
check_failed 3 "bad.gltf|/materials/5/extensions/KHR_materials_pbrSpecularGlossiness/glossinessFactor|[0, 1]"
[ -e bad.exr ] && fail "a refused scene left an image"
# ---- d. fitting the diffuse texture's texels ----
mkdir -p "$tmp/fit"
run optimize "$tmp/sg.gltf" --target sg.exr --param /images/0 --iters 2 --res 48x48 --spp 2 -o "$tmp/fit/fit.gltf"
expect_rc 0 "optimize of the diffuse texture"
json_check "$tmp/fit/fit.gltf" "'KHR_materials_pbrSpecularGlossiness' in d['materials'][5]['extensions'] and len(d['images']) == 3 and len(d['textures']) == 3" ||
    fail "the written scene keeps the extension and the file's images and textures only"
ensure_gltf_validator
validate_gltf "$tmp/fit/fit.gltf" || fail "the fitted scene does not validate"
run render "$tmp/fit/fit.gltf" --res 16x16 --spp 2 -o fit.exr
expect_rc 0 "render of the fitted scene"
echo "PASS"
