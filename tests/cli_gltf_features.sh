#!/usr/bin/env bash
# glTF features of real users' files (issue 13), on the Khronos samples in
# ../shared/gltf-samples: each render is checked for the effect the feature
# has on the image, and where it helps against a copy of the file with the
# feature taken out (so the check is known to tell them apart).
#   a. COLOR_0: BoxVertexColors is not grey; VertexColorTest shows no
#      complementary-colour "X" marks (it does with COLOR_0 removed); fdcheck
#      of baseColorFactor agrees on the vertex-coloured box
#   b. TEXCOORD_1: MultiUVTest's emissive texture reads set 1 (differs from
#      the same file reading set 0), no texCoord warning
#   c. KHR_texture_transform: TextureTransformTest's top row is green, blue,
#      cyan from left to right, not the yellow "not supported" image
#   d. sparse accessors: SimpleSparseAccessor's peaks (height/width of the
#      shape ~ 4/6, ~ 1/6 without the substitution)
#   e. cameras: both of Cameras render; the orthographic one draws the tilted
#      square with parallel edges, the perspective one as a trapezoid;
#      --camera 2 names the count
#   f. Draco: Box/glTF-Draco renders the same image as Box/glTF
#   g. KTX2 and thin-walled glass: AnisotropyBarnLamp-KTX2 (8-bit KTX2
#      textures with Zstandard; glass whose glTF volume is an open mesh)
#      renders, its glass thin-walled with a warning, the filament lighting
#      the image through it (dark with the glass opaque); fdcheck through the
#      glass agrees; the glass's base colour is no parameter and attached
#      sampling is refused. A copy whose normal map is Basis Universal is
#      refused without --ignore-unsupported and renders with it (one warning);
#      a Basis base colour is refused. A fitted KTX2 texture reached through
#      KHR_texture_basisu is written as PNG and becomes the texture's source,
#      the extension dropped there (and from extensionsUsed/Required once no
#      texture uses it); the output renders
#   h. every command that loads a scene takes --ignore-unsupported
#   i. gltfpack's outputs (tests/data/gltf/meshopt): quantized and
#      meshopt-compressed files render without a warning; optimize writes one
#      back decoded (no EXT_meshopt_compression), which the validator accepts.
#      EXT_texture_webp: BoxTextured with its texture as WebP renders the same
#      pixels as with that WebP decoded to PNG; a fitted WebP texture is written
#      as PNG, its texture's source, the extension dropped
#   j. EXT_mesh_gpu_instancing: Box drawn four times by one node's instance
#      attributes renders the same pixels as four child nodes at the same
#      TRS (and not the single box's); optimize keeps the extension and the
#      validator accepts its output
# Run by tests/run.sh (env: DRENDER, DR_TESTDIR); also runs alone.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
cli_setup gltf-features
require_drender
find_samples
R="--res 48x48 --spp 8"

# pixels IMG: python3 reads "x y r g b" lines of oiiotool --dumpdata (small images)
pixels() { oiiotool --dumpdata "$1" | sed -n 's/^ *Pixel (\([0-9]*\), \([0-9]*\)): \([^ ]*\) \([^ ]*\) \([^ ]*\).*/\1 \2 \3 \4 \5/p'; }
# copy_model DIR NAME.gltf OUT.gltf PYTHON: links DIR's files into a new
# directory and writes OUT.gltf, the model after PYTHON edited its JSON `d`
copy_model() {
    local d=$tmp/copy-$3; mkdir -p "$d"
    for f in "$1"/*; do ln -sf "$f" "$d/"; done
    rm -f "$d/$2"
    python3 -c "import json, sys; d = json.load(open(sys.argv[1])); $4; json.dump(d, open(sys.argv[2], 'w'))" \
        "$1/$2" "$d/$3" || fail "could not edit a copy of $2"
    echo "$d/$3"
}

# ---- a. COLOR_0 ----
run render "$samples/BoxVertexColors/glTF/BoxVertexColors.gltf" $R -o vc.exr
expect_rc 0 "render BoxVertexColors"
pixels vc.exr > vc.txt
python3 - vc.txt <<'PY' || fail "BoxVertexColors is grey: COLOR_0 was not applied"
import sys
px = [list(map(float, l.split()))[2:] for l in open(sys.argv[1])]
obj = [p for p in px if min(p) < 0.95]                      # not the white background
colourful = [p for p in obj if max(p) - min(p) > 0.2]
print("BoxVertexColors: %d object pixels, %d with max-min channel > 0.2" % (len(obj), len(colourful)))
sys.exit(0 if obj and len(colourful) > 0.5 * len(obj) else 1)
PY
vct=$samples/VertexColorTest/glTF
nocol=$(copy_model "$vct" VertexColorTest.gltf nocol.gltf \
    '[p["attributes"].pop("COLOR_0", None) for m in d["meshes"] for p in m["primitives"]]')
run render "$vct/VertexColorTest.gltf" --res 96x96 --spp 8 -o vct.exr
expect_rc 0 "render VertexColorTest"
run render "$nocol" --res 96x96 --spp 8 -o vct_nocol.exr
expect_rc 0 "render VertexColorTest without COLOR_0"
pixels vct.exr > vct.txt
pixels vct_nocol.exr > vct_nocol.txt
python3 - vct.txt vct_nocol.txt <<'PY' || fail "VertexColorTest: the complementary X marks are not gone"
import sys
def xmarks(f):   # cyan, magenta or yellow pixels: two channels lit, the third dark
    n = 0
    for l in open(f):
        r, g, b = sorted(map(float, l.split()[2:]))
        n += r < 0.1 and g > 0.3
    return n
a, b = xmarks(sys.argv[1]), xmarks(sys.argv[2])
print("VertexColorTest: %d two-channel (X mark) pixels with COLOR_0, %d without" % (a, b))
sys.exit(0 if b >= 40 and a * 4 <= b else 1)
PY
run fdcheck "$samples/BoxVertexColors/glTF/BoxVertexColors.gltf" \
    --param /materials/0/pbrMetallicRoughness/baseColorFactor --res 16x16 --spp 4 --batches 6
expect_rc 0 "fdcheck of baseColorFactor on the vertex-coloured box"
expect_in out "entries agree" "fdcheck verdict"

# ---- b. TEXCOORD_1 ----
muv=$samples/MultiUVTest/glTF
uv0=$(copy_model "$muv" MultiUVTest.gltf uv0.gltf 'd["materials"][0]["emissiveTexture"]["texCoord"] = 0')
run render "$muv/MultiUVTest.gltf" $R -o muv1.exr
expect_rc 0 "render MultiUVTest"
grep -q "texCoord" "$tmp/err" && fail "MultiUVTest: a texCoord warning although TEXCOORD_1 is supported"
notex=$(copy_model "$muv" MultiUVTest.gltf notex.gltf 'del d["materials"][0]["emissiveTexture"]')
run render "$uv0" $R -o muv0.exr
expect_rc 0 "render MultiUVTest reading set 0"
run render "$notex" $R -o muvn.exr
expect_rc 0 "render MultiUVTest without the emissive texture"
for f in muv1 muv0 muvn; do pixels $f.exr > $f.txt; done
# the same seed gives the same samples: only the emissive lookup differs
python3 - muv1.txt muv0.txt muvn.txt <<'PY' || fail "MultiUVTest: the emissive texture does not follow TEXCOORD_1"
import sys
img = [[list(map(float, l.split()[2:])) for l in open(f)] for f in sys.argv[1:]]
def diff(a, b): return sum(abs(x - y) for p, q in zip(a, b) for x, y in zip(p, q)) / (3 * len(a))
d0, dn = diff(img[0], img[1]), diff(img[0], img[2])
print("MultiUVTest: mean |set 1 - set 0| = %.4f, |set 1 - no texture| = %.4f" % (d0, dn))
sys.exit(0 if d0 > 0.004 and dn > 0.004 else 1)
PY

# ---- c. KHR_texture_transform ----
ttt=$samples/TextureTransformTest/glTF
nott=$(copy_model "$ttt" TextureTransformTest.gltf nott.gltf \
    '[m.get("pbrMetallicRoughness", {}).get("baseColorTexture", {}).pop("extensions", None) for m in d["materials"]]')
for f in "$ttt/TextureTransformTest.gltf" "$nott"; do
    run render "$f" --res 96x64 --spp 8 -o "tt$(basename "$f" .gltf).exr"
    expect_rc 0 "render $(basename "$f")"
done
pixels ttTextureTransformTest.exr > tt.txt
pixels ttnott.exr > tt_none.txt
python3 - tt.txt tt_none.txt <<'PY' || fail "TextureTransformTest: the top row is not green, blue, cyan (transform not applied?)"
import sys
def classes(f):   # mean x and count of green, blue, cyan, yellow pixels in the top half
    out = {k: [] for k in ("green", "blue", "cyan", "yellow")}
    for l in open(f):
        x, y, r, g, b = map(float, l.split())
        if y >= 32: continue
        if g > 0.3 and g > 2 * r and g > 2 * b: out["green"].append(x)
        elif b > 0.3 and b > 2 * r and b > 2 * g: out["blue"].append(x)
        elif g > 0.3 and b > 0.3 and min(g, b) > 2 * r: out["cyan"].append(x)
        elif r > 0.3 and g > 0.3 and min(r, g) > 2 * b: out["yellow"].append(x)
    return {k: (len(v), sum(v) / len(v) if v else -1) for k, v in out.items()}
a, b = classes(sys.argv[1]), classes(sys.argv[2])
print("with transform:", a)
print("without       :", b)
ok = all(a[k][0] >= 40 for k in ("green", "blue", "cyan")) and a["yellow"][0] * 10 < a["green"][0]
ok = ok and a["green"][1] < a["blue"][1] < a["cyan"][1]          # U, V, UV from left to right
ok = ok and b["yellow"][0] >= 100 and b["green"][0] < 10           # the check tells them apart
sys.exit(0 if ok else 1)
PY

# ---- d. sparse accessors ----
ssa=$samples/SimpleSparseAccessor/glTF
nosparse=$(copy_model "$ssa" SimpleSparseAccessor.gltf nosparse.gltf '[a.pop("sparse", None) for a in d["accessors"]]')
run render "$ssa/SimpleSparseAccessor.gltf" $R -o sparse.exr
expect_rc 0 "render SimpleSparseAccessor"
run render "$nosparse" $R -o nosparse.exr
expect_rc 0 "render SimpleSparseAccessor without the substitution"
pixels sparse.exr > sparse.txt
pixels nosparse.exr > nosparse.txt
python3 - sparse.txt nosparse.txt <<'PY' || fail "SimpleSparseAccessor: the sparse substitution did not raise the peaks"
import sys
def aspect(f):   # height / width of the pixels the shape covers
    pts = [(int(l.split()[0]), int(l.split()[1])) for l in open(f) if min(map(float, l.split()[2:])) < 0.95]
    xs, ys = [p[0] for p in pts], [p[1] for p in pts]
    return (max(ys) - min(ys) + 1) / (max(xs) - min(xs) + 1)
a, b = aspect(sys.argv[1]), aspect(sys.argv[2])
print("SimpleSparseAccessor: height/width %.3f with sparse (model 4/6), %.3f without (1/6)" % (a, b))
sys.exit(0 if 0.5 < a < 0.85 and b < 0.3 else 1)
PY

# ---- e. cameras ----
cams=$samples/Cameras/glTF/Cameras.gltf
for c in 0 1; do
    run render "$cams" --camera $c --res 96x96 --spp 4 -o cam$c.exr
    expect_rc 0 "render Cameras --camera $c"
    pixels cam$c.exr > cam$c.txt
done
python3 - cam0.txt cam1.txt <<'PY' || fail "Cameras: the orthographic camera is not a parallel projection"
import sys
def rows(f):   # covered span width per row, top to bottom
    w = {}
    for l in open(f):
        x, y, r, g, b = l.split()
        if min(float(r), float(g), float(b)) < 0.95: w[int(y)] = w.get(int(y), 0) + 1
    ys = sorted(w)
    return [w[y] for y in ys[1:-1]]   # the edge rows are partly covered
p, o = rows(sys.argv[1]), rows(sys.argv[2])
print("perspective: top %d px, bottom %d px wide, %d rows; orthographic: top %d, bottom %d, %d rows"
      % (p[0], p[-1], len(p), o[0], o[-1], len(o)))
# orthographic, ymag 1 over 96 px: the unit square is 48 px wide, 48 cos(45) = 34 rows high
ok = abs(o[0] - o[-1]) <= 2 and abs(o[0] - 48) <= 2 and abs(len(o) + 2 - 34) <= 3
ok = ok and p[-1] - p[0] >= 4     # perspective: the far (top) edge is shorter
sys.exit(0 if ok else 1)
PY
run render "$cams" --camera 2 $R -o nope.exr
check_failed 2 "--camera 2|has 2 cameras|Cameras.gltf"

# ---- f. Draco ----
run render "$samples/Box/glTF/Box.gltf" $R -o box.exr
expect_rc 0 "render Box"
run render "$samples/Box/glTF-Draco/Box.gltf" $R -o box_draco.exr
expect_rc 0 "render Box/glTF-Draco"
grep -q "KHR_draco_mesh_compression" "$tmp/err" && fail "a warning about the Draco extension"
pixels box.exr > box.txt
pixels box_draco.exr > box_draco.txt
python3 - box.txt box_draco.txt <<'PY' || fail "Box/glTF-Draco renders differently from Box/glTF"
import sys
a = [list(map(float, l.split()[2:])) for l in open(sys.argv[1])]
b = [list(map(float, l.split()[2:])) for l in open(sys.argv[2])]
m = max(abs(x - y) for p, q in zip(a, b) for x, y in zip(p, q))
lit = sum(1 for p in a if min(p) < 0.95)
print("Box vs Box Draco: max |difference| %g over %d pixels (%d show the box)" % (m, len(a), lit))
sys.exit(0 if len(a) == len(b) == 48 * 48 and lit > 100 and m <= 1e-4 else 1)
PY

# ---- g. KTX2 and thin-walled glass ----
lamp=$samples/AnisotropyBarnLamp-KTX2/glTF
run render "$lamp/AnisotropyBarnLamp.gltf" $R -o lamp.exr --json
expect_rc 0 "render of the KTX2 lamp (8-bit texels, Zstandard)"
expect_in err "/materials/2 (Lamp Glass): KHR_materials_volume needs a closed mesh" "the open glass volume's warning"
expect_in err "rendered as thin-walled glass" "the glass becomes thin-walled"
grep -q "KTX2 image" "$tmp/err" && fail "a KTX2 warning for images drender decodes"
python3 - "$tmp/out" <<'PY' || fail "lamp --json effects"
import json, sys
fx = json.load(open(sys.argv[1]))["effects"]
sys.exit(0 if all(e in fx for e in ("textures", "normal_maps", "thin_transmission")) and "media" not in fx else fx)
PY
# the filament lights the image through the glass: with the glass opaque
# (transmission and volume taken out) the lamp is dark
lamp_opaque=$(copy_model "$lamp" AnisotropyBarnLamp.gltf opaque.gltf \
    'e = d["materials"][2]["extensions"]; del e["KHR_materials_transmission"]; del e["KHR_materials_volume"]')
run render "$lamp_opaque" $R -o lamp_opaque.exr
expect_rc 0 "render of the lamp with opaque glass"
glass=$(oiiotool --stats lamp.exr | awk '/Stats Avg/ { print $3; exit }')
opaque=$(oiiotool --stats lamp_opaque.exr | awk '/Stats Avg/ { print $3; exit }')
echo "lamp: mean red $glass through thin glass, $opaque behind opaque glass"
awk -v g="$glass" -v o="$opaque" 'BEGIN { exit !(g > 0.003 && g > 3 * o) }' || fail "the filament does not light the image through the glass ($glass vs $opaque)"
# fdcheck through the glass: the filament's strength, seen through it
run fdcheck "$lamp/AnisotropyBarnLamp.gltf" --param /materials/1/extensions/KHR_materials_emissive_strength/emissiveStrength \
    --res 24x24 --spp 8 --batches 4
expect_rc 0 "fdcheck of the filament's strength through thin glass"
run grad "$lamp/AnisotropyBarnLamp.gltf" --param /materials/2/pbrMetallicRoughness/baseColorFactor --res 8x8 -o g.exr
check_failed 2 "/materials/2/pbrMetallicRoughness/baseColorFactor|thin-walled glass"
run grad "$lamp/AnisotropyBarnLamp.gltf" --param /materials/0/pbrMetallicRoughness/roughnessFactor \
    --sampling attached --res 8x8 -o g.exr
check_failed 2 "attached sampling does not differentiate through thin-walled glass|Lamp Glass"
# a Basis Universal image (ETC1S: vkFormat 0, BasisLZ) as the normal map: refused without
# --ignore-unsupported, skipped with it (one warning); as the base colour: refused
python3 - "$tmp/basis.ktx2" <<'PY'
import struct, sys
h = bytes([0xAB, 0x4B, 0x54, 0x58, 0x20, 0x32, 0x30, 0xBB, 0x0D, 0x0A, 0x1A, 0x0A])
h += struct.pack("<9I", 0, 1, 4, 4, 0, 0, 1, 1, 1) + struct.pack("<4I2Q", 0, 0, 0, 0, 0, 0)
h += struct.pack("<3Q", 104, 16, 16) + bytes(16)
open(sys.argv[1], "wb").write(h)
PY
lamp_b=$(copy_model "$lamp" AnisotropyBarnLamp.gltf basis.gltf \
    'd["images"][0]["uri"] = "basis.ktx2"; del d["materials"][2]["extensions"]["KHR_materials_volume"]')
cp "$tmp/basis.ktx2" "$(dirname "$lamp_b")/"
run render "$lamp_b" $R -o lamp_b.exr --env 1
check_failed 3 "basis.gltf|/images/0|Basis Universal ETC1S|--ignore-unsupported"
run render "$lamp_b" $R -o lamp_b.exr --env 1 --ignore-unsupported
expect_rc 0 "render of the Basis normal-map model with --ignore-unsupported"
[ "$(grep -c "KTX2 image" "$tmp/err")" -eq 1 ] || fail "expected exactly one KTX2 warning"
expect_in err "/images/0: KTX2 images drender cannot decode skipped" "the warning names the skipped image"
set -- $(oiiotool --stats lamp_b.exr | awk '/Stats Avg/ { print $3, $4, $5; exit }')
awk -v r="$1" 'BEGIN { exit !(r > 0.01) }' || fail "the lamp rendered black ($*)"
lamp_bc=$(copy_model "$lamp" AnisotropyBarnLamp.gltf basis_colour.gltf 'd["images"][2]["uri"] = "basis.ktx2"')
cp "$tmp/basis.ktx2" "$(dirname "$lamp_bc")/"
run render "$lamp_bc" $R -o lamp_bc.exr --ignore-unsupported
check_failed 3 "basis_colour.gltf|/materials/0/pbrMetallicRoughness/baseColorTexture|Basis Universal ETC1S"

# optimize fits a KTX2 texture that files reach through KHR_texture_basisu:
# the PNG it writes is the texture's source, not the extension's (which must
# name KTX2); a texture whose KTX2 was not fitted keeps the extension
basisu_edit='
for i in TEXTURES:
    t = d["textures"][i]; t["extensions"] = {"KHR_texture_basisu": {"source": t.pop("source")}}
d["extensionsUsed"].append("KHR_texture_basisu"); d["extensionsRequired"] = ["KHR_texture_basisu"]'
run render "$lamp/AnisotropyBarnLamp.gltf" --res 16x16 --spp 2 -o lamp_t.exr
expect_rc 0 "render of the lamp's target"
for which in both one; do   # both: textures 0 and 1 through the extension; one: texture 1 alone
    textures="(0, 1)" && [ $which = one ] && textures="(1,)"
    lamp_u=$(copy_model "$lamp" AnisotropyBarnLamp.gltf "basisu-$which.gltf" "${basisu_edit/TEXTURES/$textures}")
    mkdir -p "$tmp/fit-$which"
    run optimize "$lamp_u" --target lamp_t.exr --param /images/1 --iters 1 --spp 1 -o "$tmp/fit-$which/fit.gltf"
    expect_rc 0 "optimize of a KTX2 texture through KHR_texture_basisu ($which)"
    json_check "$tmp/fit-$which/fit.gltf" '
d["images"][1]["uri"] == "fit.image1.png" and d["textures"][1]["source"] == 1
and "extensions" not in d["textures"][1] and (
  ("KHR_texture_basisu" in d["textures"][0]["extensions"] and "KHR_texture_basisu" in d["extensionsUsed"]
   and d["extensionsRequired"] == ["KHR_texture_basisu"]) if "'$which'" == "both" else
  ("KHR_texture_basisu" not in d["extensionsUsed"] and not d.get("extensionsRequired")))'
    run render "$tmp/fit-$which/fit.gltf" --res 16x16 --spp 1 -o fit.exr
    expect_rc 0 "render of the fitted lamp ($which)"
done

# ---- h. every command that loads a scene takes the option ----
for c in render params grad fdcheck optimize compare; do
    "$DRENDER" help $c 2>&1 | grep -q -- "--ignore-unsupported" || fail "drender help $c does not list --ignore-unsupported"
done
run params "$lamp_b" --ignore-unsupported
expect_rc 0 "params --ignore-unsupported"
grep -q "^/images/0 " "$tmp/out" && fail "params lists the skipped KTX2 image /images/0"
expect_in out "/images/2" "params lists the JPEG base colour"
expect_in out "/images/1" "params lists the KTX2 metallic-roughness texture"
grep -q "^/materials/2/pbrMetallicRoughness/baseColorFactor" "$tmp/out" && fail "params lists thin glass's base colour"
run fdcheck "$lamp_b" --ignore-unsupported --env 1 --param /extensions/DR_environment/strength --res 8x8 --spp 2 --batches 4
expect_rc 0 "fdcheck --ignore-unsupported"

# ---- i. gltfpack's outputs, WebP ----
mo=$DR_TESTDIR/data/gltf/meshopt
for f in box_q.gltf box_c.gltf box_cc.glb box_vpf.gltf; do
    run render "$mo/$f" --res 24x24 --spp 4 -o "mo_${f%.*}.exr"
    expect_rc 0 "render of gltfpack's $f"
    grep -q "EXT_meshopt_compression\|KHR_mesh_quantization" "$tmp/err" && fail "$f: a warning about its extensions"
done
mkdir -p "$tmp/mofit"
run optimize "$mo/box_cc.glb" --target mo_box_q.exr --param /materials/0/pbrMetallicRoughness/baseColorFactor --iters 2 \
    --spp 2 -o "$tmp/mofit/box.gltf" --out-dir "$tmp/mofit/progress"
expect_rc 0 "optimize of a meshopt-compressed .glb"
json_check "$tmp/mofit/box.gltf" '"EXT_meshopt_compression" not in d.get("extensionsUsed", []) and
not any("extensions" in v for v in d["bufferViews"]) and "KHR_mesh_quantization" in d["extensionsRequired"]'
ensure_gltf_validator
validate_gltf "$tmp/mofit/box.gltf" || fail "the decoded output does not validate"
run render "$tmp/mofit/box.gltf" --res 24x24 --spp 4 -o mofit.exr
expect_rc 0 "render of the decoded output"
# WebP
bt=$samples/BoxTextured/glTF
mkdir -p "$tmp/webp" && cp "$bt"/* "$tmp/webp/"
oiiotool "$bt/CesiumLogoFlat.png" -o "$tmp/webp/logo.webp" && oiiotool "$tmp/webp/logo.webp" -o "$tmp/webp/logo_dec.png" ||
    fail "oiiotool could not write the WebP"
python3 - "$tmp/webp" <<'PY' || fail "could not write the WebP variants"
import json, os, sys
d = json.load(open(os.path.join(sys.argv[1], "BoxTextured.gltf")))
d["images"].append({"uri": "logo.webp"})
d["textures"][0] = {"sampler": d["textures"][0].get("sampler", 0), "extensions": {"EXT_texture_webp": {"source": 1}}}
d["extensionsUsed"] = d.get("extensionsUsed", []) + ["EXT_texture_webp"]
d["extensionsRequired"] = ["EXT_texture_webp"]
json.dump(d, open(os.path.join(sys.argv[1], "webp.gltf"), "w"))
d = json.load(open(os.path.join(sys.argv[1], "BoxTextured.gltf")))
d["images"][0]["uri"] = "logo_dec.png"
json.dump(d, open(os.path.join(sys.argv[1], "dec.gltf"), "w"))
PY
run render "$tmp/webp/webp.gltf" --res 32x32 --spp 4 -o webp.exr
expect_rc 0 "render with a WebP texture"
grep -q "EXT_texture_webp" "$tmp/err" && fail "a warning about EXT_texture_webp"
run render "$tmp/webp/dec.gltf" --res 32x32 --spp 4 -o webp_dec.exr
# (pixels: the files carry the time they were written)
oiiotool --diff --fail 0 --warn 0 webp.exr webp_dec.exr >/dev/null || fail "the WebP texture renders otherwise than its decoded PNG"
mkdir -p "$tmp/webpfit"
run optimize "$tmp/webp/webp.gltf" --target webp.exr --param /images/1 --iters 1 --spp 1 -o "$tmp/webpfit/fit.gltf" \
    --out-dir "$tmp/webpfit/progress"
expect_rc 0 "optimize of a WebP texture"
json_check "$tmp/webpfit/fit.gltf" 'd["textures"][0]["source"] == 1 and "extensions" not in d["textures"][0] and
d["images"][1]["uri"] == "fit.image1.png" and "EXT_texture_webp" not in d.get("extensionsUsed", []) and
not d.get("extensionsRequired")'
validate_gltf "$tmp/webpfit/fit.gltf" || fail "the fitted WebP scene does not validate"

# ---- j. EXT_mesh_gpu_instancing ----
box=$samples/Box/glTF
mkdir -p "$tmp/inst" && cp "$box"/* "$tmp/inst/"
python3 - "$tmp/inst" <<'PY' || fail "could not write the instancing variants"
import base64, json, math, os, struct, sys
src = os.path.join(sys.argv[1], "Box.gltf")
T = [(-1.2, 0, 0), (1.2, 0, 0), (0, 1.1, -0.5), (0, -1.1, 0.3)]
a = math.sqrt(0.5)
R = [(0, 0, 0, 1), (0, a, 0, a), (0.3, 0.1, 0.2, 0.9), (a, 0, 0, a)]
S = [(1, 1, 1), (0.5, 0.5, 0.5), (1, 0.4, 1), (0.7, 0.7, 1.3)]
raw = b"".join(struct.pack("<3f", *t) for t in T) + b"".join(struct.pack("<4f", *r) for r in R) + \
      b"".join(struct.pack("<3f", *x) for x in S)
def f32(v): return struct.unpack("<f", struct.pack("<f", v))[0]   # the values as the file holds them
d = json.load(open(src))
mesh_node = next(i for i, n in enumerate(d["nodes"]) if "mesh" in n)
d["buffers"].append({"byteLength": len(raw), "uri": "data:application/octet-stream;base64," + base64.b64encode(raw).decode()})
bv = len(d["bufferViews"])
d["bufferViews"].append({"buffer": len(d["buffers"]) - 1, "byteLength": len(raw)})
acc = len(d["accessors"])
d["accessors"] += [{"bufferView": bv, "componentType": 5126, "count": 4, "type": "VEC3"},
                   {"bufferView": bv, "byteOffset": 48, "componentType": 5126, "count": 4, "type": "VEC4"},
                   {"bufferView": bv, "byteOffset": 112, "componentType": 5126, "count": 4, "type": "VEC3"}]
d["nodes"][mesh_node].setdefault("extensions", {})["EXT_mesh_gpu_instancing"] = {
    "attributes": {"TRANSLATION": acc, "ROTATION": acc + 1, "SCALE": acc + 2}}
d["extensionsUsed"] = d.get("extensionsUsed", []) + ["EXT_mesh_gpu_instancing"]
json.dump(d, open(os.path.join(sys.argv[1], "instanced.gltf"), "w"))
d = json.load(open(src))
mesh = d["nodes"][mesh_node].pop("mesh")
kids = []
for t, r, x in zip(T, R, S):
    kids.append(len(d["nodes"]))
    d["nodes"].append({"mesh": mesh, "translation": [f32(v) for v in t], "rotation": [f32(v) for v in r],
                       "scale": [f32(v) for v in x]})
d["nodes"][mesh_node]["children"] = d["nodes"][mesh_node].get("children", []) + kids
json.dump(d, open(os.path.join(sys.argv[1], "explicit.gltf"), "w"))
PY
IR="--res 40x40 --spp 4 --sampler independent"
for f in instanced explicit Box; do
    run render "$tmp/inst/$f.gltf" $IR -o "inst_$f.exr"
    expect_rc 0 "render of $f.gltf"
    grep -q "EXT_mesh_gpu_instancing" "$tmp/err" && fail "$f.gltf: a warning about EXT_mesh_gpu_instancing"
done
oiiotool --diff --fail 0 --warn 0 inst_instanced.exr inst_explicit.exr >/dev/null ||
    fail "the instanced Box renders otherwise than four explicit nodes"
oiiotool --diff --fail 0 --warn 0 inst_instanced.exr inst_Box.exr >/dev/null &&
    fail "the instanced Box renders as the single Box: the instances are not drawn"
mkdir -p "$tmp/instfit"
run optimize "$tmp/inst/instanced.gltf" --target inst_explicit.exr --param /materials/0/pbrMetallicRoughness/baseColorFactor \
    --iters 1 --spp 1 -o "$tmp/instfit/fit.gltf" --out-dir "$tmp/instfit/progress"
expect_rc 0 "optimize of an instanced scene"
json_check "$tmp/instfit/fit.gltf" 'any("EXT_mesh_gpu_instancing" in n.get("extensions", {}) for n in d["nodes"]) and
"EXT_mesh_gpu_instancing" in d["extensionsUsed"]'
validate_gltf "$tmp/instfit/fit.gltf" || fail "the instanced output does not validate"

echo "cli_gltf_features: all passed"
