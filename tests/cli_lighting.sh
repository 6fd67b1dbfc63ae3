#!/usr/bin/env bash
# Default lighting and --env (issue 13, "out of the box"), on a real sample
# model with no light and no camera (../shared/gltf-samples/Box).
#   a. render: a note on stderr, once; a lit (non-black) image; with
#      --no-default-light a black one and no note; --env COLOR,STRENGTH and
#      --env FILE,STRENGTH light it as asked; a lit scene gets no note
#   b. params lists the default environment's parameters, --env's (the map's
#      texels, or the colour as given) in their place, none with
#      --no-default-light
#   c. optimize on the camera-less, light-less file fits the environment's
#      colour to a target; the written glTF carries DR_environment only when
#      the environment was fitted
#   d. fdcheck of the environment strength under --env agrees
#   e. errors: --env neither file nor colour, negative values (exit 2)
# Run by tests/run.sh (env: DRENDER, DR_TESTDIR); also runs alone.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
cli_setup lighting
require_drender
box=$DR_TESTDIR/../../shared/gltf-samples/Box/glTF/Box.gltf
[ -f "$box" ] || box=$DR_TESTDIR/../../../shared/gltf-samples/Box/glTF/Box.gltf
[ -f "$box" ] || fail "the shared sample model Box.gltf was not found beside the checkout"
# avg IMG: the mean of the three channels' averages (oiiotool --stats)
avg() { oiiotool --stats "$1" 2>/dev/null | awk '/Stats Avg/ { print $3, $4, $5; exit }'; }
R="--res 24x24 --spp 4"

# ---- a. render ----
run render "$box" $R -o lit.exr
expect_rc 0 "render of a light-less model"
[ "$(grep -c "has no light" "$tmp/err")" -eq 1 ] || fail "expected one 'has no light' note on stderr"
expect_in err "--no-default-light" "the note says how to turn it off"
set -- $(avg lit.exr)
awk -v r="$1" 'BEGIN { exit !(r > 0.05) }' || fail "the default-lit Box is black (avg $*)"
run render "$box" $R -o dark.exr --no-default-light
expect_rc 0 "render --no-default-light"
grep -q "has no light" "$tmp/err" && fail "--no-default-light still printed the note"
set -- $(avg dark.exr)
awk -v r="$1" -v g="$2" -v b="$3" 'BEGIN { exit !(r == 0 && g == 0 && b == 0) }' || fail "--no-default-light is not black ($*)"
run render "$box" $R -o col.exr --env 0.2,0.4,0.8,2
expect_rc 0 "render --env R,G,B,S"
grep -q "has no light" "$tmp/err" && fail "--env still printed the default-light note"
python3 - "$(avg lit.exr)" "$(avg col.exr)" <<'PY' || fail "--env 0.2,0.4,0.8,2 does not scale the default-lit image by 0.4, 0.8, 1.6"
import sys
a = [float(x) for x in sys.argv[1].split()]; b = [float(x) for x in sys.argv[2].split()]
want = [0.4, 0.8, 1.6]
sys.exit(0 if all(abs(bi / ai - w) < 0.05 * w for ai, bi, w in zip(a, b, want) if ai > 1e-3) else 1)
PY
run render "$box" $R -o sky.exr --env "$DR_TESTDIR/data/gltf/sky.hdr,0.5"
expect_rc 0 "render --env FILE,STRENGTH"
set -- $(avg sky.exr)
awk -v r="$1" 'BEGIN { exit !(r > 0) }' || fail "--env sky.hdr,0.5 gave a black image"
run render $R -o cornell.png
expect_rc 0 "render of the lit bundled scene"
grep -q "has no light" "$tmp/err" && fail "a scene with an area light got the default-light note"

# ---- b. params ----
run params "$box"
expect_rc 0 "params"
expect_in out "/extensions/DR_environment/color" "params lists the default environment"
run params "$box" --no-default-light
expect_rc 0 "params --no-default-light"
grep -q "DR_environment" "$tmp/out" && fail "params --no-default-light still lists an environment"
grep -q "has no light" "$tmp/err" && fail "params --no-default-light printed the default-light note"
run params "$box" --env "$DR_TESTDIR/data/gltf/sky.hdr,0.5" --json
expect_rc 0 "params --env FILE,STRENGTH"
python3 - "$tmp/out" "$DR_TESTDIR/data/gltf/sky.hdr" <<'PY' || fail "params --env sky.hdr,0.5 does not list the map's texels and strength 0.5"
import json, subprocess, sys
p = {q["name"]: q for q in json.load(open(sys.argv[1]))["parameters"]}
uri, st = p.get("/extensions/DR_environment/uri"), p.get("/extensions/DR_environment/strength")
info = subprocess.run(["oiiotool", "--info", sys.argv[2]], capture_output=True, text=True).stdout
w, h = [int(x) for x in info.split(":")[1].split(",")[0].split("x")]
sys.exit(0 if uri and uri["type"] == "image" and (uri["width"], uri["height"]) == (w, h)
         and st and st["value"] == [0.5] else 1)
PY
run params "$box" --env 0.25,0.5,1
expect_rc 0 "params --env R,G,B"
grep -qE '^/extensions/DR_environment/color +color +3 +\(0\.25, 0\.5, 1\)' "$tmp/out" ||
    fail "params --env 0.25,0.5,1 does not list that colour: $(grep DR_environment "$tmp/out")"
run params "$box" --env -1
expect_rc 2 "params --env with a negative value"

# ---- c. optimize: no camera, no light ----
run render "$box" $R -o target.exr --env 0.5
expect_rc 0 "target render"
run optimize "$box" --target target.exr --param /extensions/DR_environment/color --iters 100 --spp 4 \
    --out-dir opt -o opt/out.gltf
expect_rc 0 "optimize of a camera-less, light-less model"
python3 - opt/out.gltf <<'PY' || fail "optimize did not recover the environment colour 0.5"
import json, sys
c = json.load(open(sys.argv[1]))["extensions"]["DR_environment"]["color"]
sys.exit(0 if all(abs(x - 0.5) < 0.05 for x in c) else 1)
PY
run optimize "$box" --target target.exr --param /materials/0/pbrMetallicRoughness/baseColorFactor --iters 2 \
    --spp 2 --out-dir opt2 -o opt2/out.gltf
expect_rc 0 "optimize of the material"
python3 -c 'import json, sys; sys.exit("DR_environment" in json.load(open(sys.argv[1])).get("extensions", {}))' \
    opt2/out.gltf || fail "the default environment was written into a glTF that did not fit it"

# ---- d. fdcheck under --env ----
run fdcheck "$box" --env 0.7 --param /extensions/DR_environment/strength --res 16x16 --spp 8 --batches 6
expect_rc 0 "fdcheck --env"
expect_in out "entries agree" "fdcheck of the environment strength"

# ---- e. errors ----
for bad in "no-such-sky.hdr" "0.5,-1" "1,2,3,4,5"; do
    run render "$box" $R -o bad.png --env "$bad"
    expect_rc 2 "--env $bad"
    expect_in err "--env" "the message names --env ($bad)"
    [ ! -e bad.png ] || fail "an image was written after --env $bad"
done

echo "cli_lighting: all passed"
