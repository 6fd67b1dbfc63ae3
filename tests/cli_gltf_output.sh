#!/usr/bin/env bash
# What optimize writes and what params lists, on real sample models (issue 13):
#   a. optimize -o OUT.glb is self-contained: a fitted texture and the source's
#      untouched textures are embedded (images with bufferViews, no uri), the
#      output directory holds no image file beside it, the .glb copied alone
#      elsewhere renders the fitted texture, and the Khronos validator finds no
#      error in it
#   b. params lists only images that can change the image: NormalTangentTest's
#      normal map is not a parameter, and asking for it says why (exit 2)
#   c. load warnings are printed once per run, also by optimize
#   d. optimize writes a Draco-compressed model back (.gltf and .glb): the
#      Draco primitives keep their extension and indices, the output renders
#      like the fitted scene and the validator finds no error
# Run by tests/run.sh (env: DRENDER, DR_TESTDIR); also runs alone.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
cli_setup gltf-output
require_drender
find_samples
avg() { oiiotool --stats "$1" 2>/dev/null | awk '/Stats Avg/ { print $3, $4, $5; exit }'; }
# glb_images FILE: one line per image: "bufferView=N uri=U"
glb_images() {
    python3 - "$1" <<'PY'
import json, struct, sys
b = open(sys.argv[1], "rb").read()
assert b[:4] == b"glTF", "not a GLB"
n = struct.unpack("<I", b[12:16])[0]
for im in json.loads(b[20:20 + n]).get("images", []):
    print("bufferView=%s uri=%s" % (im.get("bufferView", -1), im.get("uri", "")))
PY
}
R="--res 24x24 --spp 4"

# ---- a. a self-contained .glb ----
box=$samples/BoxTextured/glTF/BoxTextured.gltf
[ -f "$box" ] || fail "BoxTextured.gltf not found"
run render "$box" $R -o target.exr --env 0.3,0.6,0.9
expect_rc 0 "target render"
run optimize "$box" --target target.exr --param /images/0 --iters 3 --spp 2 --res 24x24 --out-dir o1 -o o1/fit.glb
expect_rc 0 "optimize a texture into a .glb"
[ -z "$(ls o1 | grep -iE '^fit.*\.(png|jpg|jpeg)$')" ] || fail "image files beside the .glb: $(ls o1)"
glb_images o1/fit.glb > images.txt || fail "o1/fit.glb is not a readable GLB"
grep -q "bufferView=-1" images.txt && fail "an image of the .glb is not embedded: $(cat images.txt)"
grep -q "uri=[^ ]" images.txt && fail "an embedded image still has a uri: $(cat images.txt)"
mkdir alone && cp o1/fit.glb alone/ || fail "copy"
run render alone/fit.glb $R -o alone.exr
expect_rc 0 "render the .glb copied alone"
run render o1/fit.glb $R -o beside.exr
[ "$(avg alone.exr)" = "$(avg beside.exr)" ] || fail "the copied .glb renders differently ($(avg alone.exr) vs $(avg beside.exr))"
run optimize "$box" --target target.exr --param /materials/0/pbrMetallicRoughness/baseColorFactor --iters 1 \
    --spp 2 --res 24x24 --out-dir o2 -o o2/mat.glb
expect_rc 0 "optimize a material into a .glb"
glb_images o2/mat.glb | grep -q "bufferView=-1" && fail "the source's texture was not embedded into the .glb"
[ -z "$(ls o2 | grep -iE '\.(png|jpg|jpeg)$' | grep -v -E '^(before|after|target|loss|render-[0-9]+)\.png$')" ] \
    || fail "files beside the .glb: $(ls o2)"
ensure_gltf_validator
validate_gltf o1/fit.glb o2/mat.glb > validate.txt 2>&1 || { cat validate.txt >&2; fail "the validator found errors in the written .glb"; }

# ---- b. params: only images that change the image ----
ntt=$samples/NormalTangentTest/glTF/NormalTangentTest.gltf
[ -f "$ntt" ] || fail "NormalTangentTest.gltf not found"
run params "$ntt"
expect_rc 0 "params NormalTangentTest"
expect_in out "/images/0 " "the base colour image is listed"
expect_in out "/images/1 " "the occlusion-roughness-metallic image is listed (roughness and metallic read it)"
grep -q "^/images/2 " "$tmp/out" && fail "the normal map /images/2 is listed as a parameter"
run grad "$ntt" --param /images/2 -o d.exr $R
check_failed 2 "/images/2|normal"

# ---- c. warnings once ----
dof=$samples/DepthOfFieldExample-bevy/glTF-Binary/DepthOfFieldExample.glb
run render "$dof" --res 16x9 --spp 1 -o dof.exr
expect_rc 0 "render DepthOfFieldExample"
dups=$(grep "warning" "$tmp/err" | sort | uniq -d)
[ -z "$dups" ] || fail "a load warning was printed more than once: $dups"
run optimize "$dof" --target dof.exr --param /materials/0/pbrMetallicRoughness/baseColorFactor --iters 2 --spp 1 \
    --res 16x9 --out-dir o3 -o o3/out.glb
expect_rc 0 "optimize DepthOfFieldExample"
dups=$(grep "warning" "$tmp/err" | sort | uniq -d)
[ -z "$dups" ] || fail "optimize printed a load warning more than once: $dups"
# ---- d. Draco written back ----
draco=$samples/Box/glTF-Draco/Box.gltf
[ -f "$draco" ] || fail "Box/glTF-Draco/Box.gltf not found"
run render "$draco" $R -o dtarget.exr --env 0.5
expect_rc 0 "render the Draco box"
for o in dbox.gltf dbox.glb; do
    run optimize "$draco" --target dtarget.exr --param /materials/0/pbrMetallicRoughness/baseColorFactor --iters 2 \
        --spp 2 --res 24x24 --env 0.5 --out-dir o4 -o "o4/$o"
    expect_rc 0 "optimize the Draco box into $o"
    run render "o4/$o" $R -o "back-$o.exr" --env 0.5
    expect_rc 0 "render the written $o"
    set -- $(avg "back-$o.exr")
    awk -v r="$1" 'BEGIN { exit !(r > 0.01) }' || fail "the written $o renders black ($*)"
done
python3 - o4/dbox.gltf <<'PY' || fail "the written Draco primitive lost its extension or indices"
import json, sys
p = json.load(open(sys.argv[1]))["meshes"][0]["primitives"][0]
sys.exit(0 if "KHR_draco_mesh_compression" in p.get("extensions", {}) and "indices" in p else 1)
PY
validate_gltf o4/dbox.gltf o4/dbox.glb > validate-draco.txt 2>&1 || { cat validate-draco.txt >&2; fail "the validator found errors in the written Draco model"; }
echo "cli_gltf_output: all passed"
