#!/usr/bin/env bash
# Normal maps, alpha modes and single-sided materials (issue 13) on real sample
# models (../shared/gltf-samples) and on the scenes of tests/data/surfaces:
#   a. NormalTangentTest under an environment with a colour gradient: each
#      normal-mapped cell (right of a pair) looks like the real geometry on its
#      left (pixel correlation of the two cells, 15 pairs), clearly more so
#      than with the normal map's green channel flipped or with no normal map
#      (what drender did before); --json effects name normal_maps
#   b. TextureSettingsTest: the single-sided test shows the green check behind
#      the culled polygon (not black, as when back faces absorbed; not a red
#      X); the double-sided test shows its check
#   c. fdcheck, prb and tape, detached: base colour and roughness of a
#      normal-mapped floor; base colours of a floor, a MASK cut-out and a BLEND
#      pane, and the floor's roughness seen through them
#   d. BLEND decisions are pure functions of the path: the same image for
#      --threads 1 and 2; params does not list the normal map's image;
#      attached sampling with a roughness parameter is refused naming the material
#   e. the closed Box's backs are proved unreachable from outside, and not
#      with a camera inside, which sees through its culled walls
#   f. thin-walled glass (the bundled box's sphere made transmissive): fdcheck,
#      prb and tape, detached and derivative, of the glass's roughness and the
#      wall seen through it; the same image for --threads 1 and 2
# Run by tests/run.sh (env: DRENDER, DR_TESTDIR); also runs alone.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
cli_setup surfaces
require_drender
find_samples
[ -d "$samples/NormalTangentTest" ] || fail "the shared sample models were not found beside the checkout"
data=$DR_TESTDIR/data/surfaces

# ---- a. NormalTangentTest ----
nt=$samples/NormalTangentTest/glTF
mkdir nt && for f in "$nt"/*; do ln -s "$f" nt/; done
oiiotool "$nt/NormalTangentTest_Normal.png" --mulc 1,-1,1 --addc 0,1,0 -d uint8 -o nt/flipped.png ||
    fail "oiiotool could not flip the normal map's green channel"
python3 - "$nt/NormalTangentTest.gltf" <<'PY' || fail "could not write the NormalTangentTest variants"
import json, sys
d = json.load(open(sys.argv[1]))
f = json.loads(json.dumps(d)); f["images"][2]["uri"] = "flipped.png"; json.dump(f, open("nt/flipped.gltf", "w"))
p = json.loads(json.dumps(d)); del p["materials"][0]["normalTexture"]; json.dump(p, open("nt/plain.gltf", "w"))
PY
# a horizon-less gradient sky: every normal direction sees its own colour
oiiotool --pattern fill:topleft=1,0.1,0.1:topright=0.1,1,0.1:bottomleft=0.1,0.1,1:bottomright=1,1,0.1 64x32 3 \
    -o sky.exr || fail "oiiotool could not write the sky"
for v in NormalTangentTest flipped plain; do
    run render "nt/$v.gltf" --env sky.exr,1 -o "$v.exr" --res 192x192 --spp 48 --seed 1 --json
    expect_rc 0 "render $v"
    oiiotool --dumpdata "$v.exr" >"$v.txt" || fail "oiiotool --dumpdata $v.exr"
done
run render nt/NormalTangentTest.gltf --res 8x8 --spp 1 -o x.exr --json
expect_in out '"normal_maps"' "--json effects of a normal-mapped scene"
# corr FILE: correlation of the left and right cell of each of the 15 pairs
# (3 columns x 5 rows; at 192x192 the left cells' centres are 45.5 px apart
# horizontally, 22.5 vertically, and each right cell is 18 px to the right)
cat >corr.py <<'PY'
import math, re, sys
px = {}
for line in open(sys.argv[1]):
    m = re.match(r"\s*Pixel \((\d+), (\d+)\):\s*(.*)", line)
    if m:
        px[(int(m.group(1)), int(m.group(2)))] = [float(v) for v in m.group(3).split()]
out = []
for c in range(3):
    for r in range(5):
        lx, ly = 41 + c * 45.5, 43 + r * 22.5
        a, b = [], []
        for dy in range(-5, 6):
            for dx in range(-5, 6):
                a += px[(int(lx + dx), int(ly + dy))]
                b += px[(int(lx + 18 + dx), int(ly + dy))]
        ma, mb = sum(a) / len(a), sum(b) / len(b)
        cov = sum((x - ma) * (y - mb) for x, y in zip(a, b))
        va, vb = sum((x - ma) ** 2 for x in a), sum((y - mb) ** 2 for y in b)
        out.append(cov / math.sqrt(va * vb) if va > 0 and vb > 0 else 0.0)
print("%.4f %.4f" % (min(out), sum(out) / len(out)))
PY
read -r ok_min ok_mean < <(python3 corr.py NormalTangentTest.txt)
read -r fl_min fl_mean < <(python3 corr.py flipped.txt)
read -r pl_min pl_mean < <(python3 corr.py plain.txt)
echo "cell correlation min/mean: normal map $ok_min/$ok_mean, green flipped $fl_min/$fl_mean, no normal map $pl_min/$pl_mean"
awk -v m="$ok_min" -v a="$ok_mean" 'BEGIN { exit !(m > 0.7 && a > 0.85) }' ||
    fail "normal-mapped cells do not look like the geometry beside them (min $ok_min, mean $ok_mean)"
awk -v a="$ok_mean" -v f="$fl_mean" -v p="$pl_mean" 'BEGIN { exit !(a > f + 0.15 && a > p + 0.1) }' ||
    fail "the normal map is no closer to the geometry than a flipped one ($fl_mean) or none ($pl_mean): $ok_mean"

# ---- b. TextureSettingsTest ----
run render "$samples/TextureSettingsTest/glTF/TextureSettingsTest.gltf" -o ts.exr --res 320x320 --spp 32 --seed 1 --json
expect_rc 0 "render TextureSettingsTest"
expect_in out '"single_sided"' "--json effects name single_sided"
# avg X Y: the mean colour of the 14x14 pixels at (X, Y)
avg() { oiiotool ts.exr --cut "14x14+$1+$2" --printstats 2>/dev/null | awk '/Stats Avg/ { print $3, $4, $5; exit }'; }
read -r r g b < <(avg 163 88)
echo "single-sided test cell: $r $g $b"
awk -v r="$r" -v g="$g" 'BEGIN { exit !(g > 0.05 && g >= r) }' ||
    fail "single-sided cell: expected the green check behind the culled polygon, got $r $g $b (black: the back absorbs)"
read -r r g b < <(avg 163 112)
awk -v r="$r" -v g="$g" 'BEGIN { exit !(g > 0.3 && g > r + 0.1) }' || fail "double-sided cell: expected a green check, got $r $g $b"

# ---- c. fdcheck ----
F="--res 32x32 --spp 16 --batches 8 --seed 3"
nm_params="--param /materials/bumpy/pbrMetallicRoughness/baseColorFactor --param /materials/bumpy/pbrMetallicRoughness/roughnessFactor"
al_params="--param /materials/floor/pbrMetallicRoughness/baseColorFactor --param /materials/leaf/pbrMetallicRoughness/baseColorFactor
           --param /materials/pane/pbrMetallicRoughness/baseColorFactor --param /materials/floor/pbrMetallicRoughness/roughnessFactor"
for e in prb tape; do
    # shellcheck disable=SC2086
    run fdcheck "$data/normal_mapped.gltf" $nm_params $F --estimator $e
    expect_rc 0 "fdcheck ($e) on the normal-mapped floor"
    expect_in out "all 4 entries agree" "fdcheck ($e), normal map"
    # shellcheck disable=SC2086
    run fdcheck "$data/alpha.gltf" $al_params $F --estimator $e
    expect_rc 0 "fdcheck ($e) through MASK and BLEND surfaces"
    expect_in out "all 10 entries agree" "fdcheck ($e), alpha"
done

# ---- d. determinism, params, attached ----
run render "$data/alpha.gltf" -o t1.exr --res 32x32 --spp 8 --threads 1 --json
expect_in out '"alpha_mask"' "effects name alpha_mask"
expect_in out '"alpha_blend"' "effects name alpha_blend"
run render "$data/alpha.gltf" -o t2.exr --res 32x32 --spp 8 --threads 2
oiiotool t1.exr t2.exr --diff --fail 0 --failpercent 0 --warn 0 >/dev/null 2>&1 ||
    fail "BLEND: --threads 1 and 2 give different images"
run params "$data/normal_mapped.gltf"
expect_rc 0 "params"
grep -q "/images/" "$tmp/out" && fail "params lists the normal map's image"
run fdcheck "$data/normal_mapped.gltf" --param /materials/bumpy/pbrMetallicRoughness/roughnessFactor \
    --sampling attached --res 8x8 --spp 1 --batches 2
[ "$rc" -ne 0 ] || fail "attached sampling on a normal-mapped scene should be refused"
expect_mentions "attached sampling|normal map|bumpy|--sampling detached"

# ---- e. backs no ray can reach (core/backface.c) ----
# Box (a closed single-sided cube) seen by the default view from outside:
# all 12 backs proved unreachable. The same cube with its only camera inside:
# nothing proved, and the camera sees through the culled walls to the
# default white sky (an image of 1; black if the backs were taken as walls).
box=$samples/Box/glTF
run render "$box/Box.gltf" -o out_box.exr --res 16x16 --spp 2 --json
expect_in out '"backs_unreachable": 12' "the closed Box seen from outside: 12 backs unreachable"
mkdir inside && for f in "$box"/*; do ln -s "$f" inside/; done
python3 - "$box/Box.gltf" <<'PY' || fail "could not write the camera-inside variant of Box"
import json, sys
d = json.load(open(sys.argv[1]))
d["cameras"] = [{"type": "perspective", "perspective": {"yfov": 1.0, "znear": 0.01}}]
d["nodes"].append({"camera": 0, "translation": [0, 0, 0]})
d["scenes"][d.get("scene", 0)]["nodes"].append(len(d["nodes"]) - 1)
json.dump(d, open("inside/inside.gltf", "w"))
PY
run render inside/inside.gltf -o inside.exr --res 16x16 --spp 2 --json
expect_in out '"backs_unreachable": 0' "a camera inside the closed Box: no back proved unreachable"
read -r r g b < <(oiiotool inside.exr --printstats 2>/dev/null | awk '/Stats Avg/ { print $3, $4, $5; exit }')
awk -v r="$r" -v g="$g" -v b="$b" 'BEGIN { exit !(r > 0.999 && g > 0.999 && b > 0.999) }' ||
    fail "inside the single-sided Box the walls must be culled (sky of 1), got $r $g $b"

# ---- f. thin-walled glass ----
python3 - "$DR_TESTDIR/../scenes/cornell-box.gltf" "$tmp/glass.gltf" <<'PY'
import json, sys
g = json.load(open(sys.argv[1]))
g["materials"][4].setdefault("extensions", {})["KHR_materials_transmission"] = {"transmissionFactor": 1}
json.dump(g, open(sys.argv[2], "w"))
PY
ln -sf "$DR_TESTDIR/../scenes/cornell-box.bin" "$DR_TESTDIR/../scenes/cornell-box-checker.png" "$tmp/"
for est in prb tape; do
    for smp in detached derivative; do
        run fdcheck "$tmp/glass.gltf" --param /materials/4/pbrMetallicRoughness/roughnessFactor \
            --param /materials/0/pbrMetallicRoughness/baseColorFactor --res 24x24 --spp 16 --batches 8 \
            --estimator $est --sampling $smp
        expect_rc 0 "fdcheck through thin glass ($est, $smp)"
    done
done
run render "$tmp/glass.gltf" --res 32x32 --spp 4 --threads 1 -o glass1.exr
run render "$tmp/glass.gltf" --res 32x32 --spp 4 --threads 2 -o glass2.exr --json
expect_in out '"thin_transmission"' "--json names the thin glass"
[ "$(oiiotool --diff glass1.exr glass2.exr 2>&1 | grep -c PASS)" -ge 1 ] ||
    fail "thin glass: the image depends on the thread count"
echo "PASS"
