#!/usr/bin/env bash
# Punctual light units (issue 13): glTF's KHR_lights_punctual intensities are
# photometric (candela, lux) and read as such by default (divided by 683 lm/W);
# DR_units {"lights": "radiometric"} or --light-units radiometric reads them
# as W/sr, W/m^2.
#   a. a white Lambertian floor under a directional light of 683 lux straight
#      down: radiance albedo/pi * 1 W/m^2 by default, 683x that radiometric
#      (option or DR_units), photometric again with --light-units photometric
#   b. a point light: the same factor, and d/d intensity scales with it
#      (fdcheck agrees in both units)
#   c. optimize -o under --light-units radiometric writes DR_units, so the
#      output reads back in the units it was fitted in; a photometric file
#      gets no DR_units
#   d. the Blender export DepthOfFieldExample (a 6830 lux sun) renders ~683x
#      darker by default than read as watts
#   e. a bad DR_units value (exit 3, file and JSON path) or option value (exit 2)
# Run by tests/run.sh (env: DRENDER, DR_TESTDIR); also runs alone.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
cli_setup units
require_drender
avg() { oiiotool --stats "$1" 2>/dev/null | awk '/Stats Avg/ { print $3, $4, $5; exit }'; }
# near A B REL: |A - B| <= REL * |B|
near() { awk -v a="$1" -v b="$2" -v r="$3" 'BEGIN { d = a - b; if (d < 0) d = -d; if (b < 0) b = -b; exit !(d <= r * b) }'; }

# floor.gltf [UNITS] [LIGHT]: a 20x20 white Lambertian floor (y = 0), a camera
# 1 m above looking down, one light: "sun" (683 lux straight down) or "bulb"
# (683 cd point light 1 m above the floor's centre). UNITS: "" or the DR_units
# lights value.
make_floor() {
    python3 - "$@" <<'PY'
import base64, json, struct, sys
out, units, light = sys.argv[1], sys.argv[2], sys.argv[3]
pos = [(-10, 0, -10), (10, 0, -10), (10, 0, 10), (-10, 0, 10)]
buf = b"".join(struct.pack("<3f", *p) for p in pos) + struct.pack("<6H", 0, 2, 1, 0, 3, 2)
lights = {"sun": {"type": "directional", "intensity": 683},
          "bulb": {"type": "point", "intensity": 683}}[light]
doc = {
    "asset": {"version": "2.0"},
    "extensionsUsed": ["KHR_lights_punctual", "KHR_materials_specular"] + (["DR_units"] if units else []),
    "scene": 0, "scenes": [{"nodes": [0, 1, 2]}],
    "nodes": [{"mesh": 0},
              {"camera": 0, "translation": [0, 1, 0], "rotation": [-0.70710678, 0, 0, 0.70710678]},
              {"extensions": {"KHR_lights_punctual": {"light": 0}},
               "translation": [0, 1, 0], "rotation": [-0.70710678, 0, 0, 0.70710678]}],
    "cameras": [{"type": "perspective", "perspective": {"yfov": 0.2, "znear": 0.01, "aspectRatio": 1}}],
    "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
    "materials": [{"name": "white", "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0},
                   "extensions": {"KHR_materials_specular": {"specularFactor": 0}}}],
    "buffers": [{"byteLength": len(buf), "uri": "data:application/octet-stream;base64," + base64.b64encode(buf).decode()}],
    "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48}, {"buffer": 0, "byteOffset": 48, "byteLength": 12}],
    "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                   "min": [-10, 0, -10], "max": [10, 0, 10]},
                  {"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}],
    "extensions": {"KHR_lights_punctual": {"lights": [lights]}},
}
if units:
    doc["extensions"]["DR_units"] = {"lights": units}
json.dump(doc, open(out, "w"))
PY
}
R="--res 8x8 --spp 4 --max-depth 2"
pi_inv=0.3183098862

# ---- a. directional light ----
make_floor sun.gltf "" sun
make_floor sun-w.gltf radiometric sun
make_floor sun-p.gltf photometric sun
run render sun.gltf $R -o a.exr;                              expect_rc 0 "render (photometric default)"
grep -q "has no light" "$tmp/err" && fail "a lit scene got the default-light note"
set -- $(avg a.exr); near "$1" $pi_inv 1e-3 || fail "683 lux on a white floor: radiance $1, expected 1/pi"
run render sun.gltf $R -o b.exr --light-units radiometric;    expect_rc 0 "render --light-units radiometric"
set -- $(avg b.exr); near "$1" "$(awk -v p=$pi_inv 'BEGIN { print 683 * p }')" 1e-3 || fail "683 W/m^2: radiance $1, expected 683/pi"
run render sun-w.gltf $R -o c.exr;                            expect_rc 0 "render DR_units radiometric"
set -- $(avg c.exr); near "$1" "$(awk -v p=$pi_inv 'BEGIN { print 683 * p }')" 1e-3 || fail "DR_units radiometric not read: radiance $1"
run render sun-w.gltf $R -o d.exr --light-units photometric;  expect_rc 0 "render --light-units photometric"
set -- $(avg d.exr); near "$1" $pi_inv 1e-3 || fail "--light-units photometric does not override DR_units: radiance $1"
run render sun-p.gltf $R -o e.exr;                            expect_rc 0 "render DR_units photometric"
set -- $(avg e.exr); near "$1" $pi_inv 1e-3 || fail "DR_units photometric: radiance $1"

# ---- b. point light: the image and d/d intensity follow the units ----
make_floor bulb.gltf "" bulb
I=/extensions/KHR_lights_punctual/lights/0/intensity
run render bulb.gltf $R -o p.exr;                             expect_rc 0 "render bulb"
run render bulb.gltf $R -o w.exr --light-units radiometric;   expect_rc 0 "render bulb radiometric"
set -- $(avg p.exr); p=$1; set -- $(avg w.exr)
near "$1" "$(awk -v p="$p" 'BEGIN { print 683 * p }')" 1e-3 || fail "point light: radiometric $1 vs 683 x photometric $p"
for u in photometric radiometric; do
    run fdcheck bulb.gltf --param $I --res 8x8 --spp 4 --max-depth 2 --batches 4 --light-units $u --json
    expect_rc 0 "fdcheck of the intensity ($u)"
done

# ---- c. optimize writes the units it fitted in ----
python3 -c 'import json; d = json.load(open("bulb.gltf")); d["extensions"]["KHR_lights_punctual"]["lights"][0]["intensity"] = 800; json.dump(d, open("bulb800.gltf", "w"))'
run render bulb800.gltf $R -o target.exr --light-units radiometric
expect_rc 0 "target render"
run optimize bulb.gltf --target target.exr --param $I --iters 3 $R --light-units radiometric --out-dir o1 -o o1/out.gltf
expect_rc 0 "optimize --light-units radiometric"
python3 -c 'import json, sys; d = json.load(open(sys.argv[1])); sys.exit(d["extensions"].get("DR_units", {}).get("lights") != "radiometric" or "DR_units" not in d["extensionsUsed"])' \
    o1/out.gltf || fail "optimize -o under --light-units radiometric did not write DR_units radiometric"
run render o1/out.gltf $R -o back.exr
set -- $(avg back.exr)
awk -v a="$1" -v p="$p" 'BEGIN { exit !(a > 100 * p) }' || fail "the written file does not read back as radiometric ($1 vs $p)"
run optimize bulb.gltf --target p.exr --param $I --iters 2 $R --out-dir o2 -o o2/out.gltf
expect_rc 0 "optimize (photometric)"
python3 -c 'import json, sys; sys.exit("DR_units" in json.load(open(sys.argv[1]))["extensions"])' o2/out.gltf \
    || fail "a photometric file got DR_units"

# ---- d. a Blender export ----
dof=$DR_TESTDIR/../../shared/gltf-samples/DepthOfFieldExample-bevy/glTF-Binary/DepthOfFieldExample.glb
[ -f "$dof" ] || dof=$DR_TESTDIR/../../../shared/gltf-samples/DepthOfFieldExample-bevy/glTF-Binary/DepthOfFieldExample.glb
[ -f "$dof" ] || fail "the shared sample DepthOfFieldExample.glb was not found beside the checkout"
run render "$dof" --res 32x18 --spp 4 -o dof.exr;                          expect_rc 0 "render the Blender export"
run render "$dof" --res 32x18 --spp 4 -o dof-w.exr --light-units radiometric; expect_rc 0 "render it in watts"
set -- $(avg dof.exr); a=$1; set -- $(avg dof-w.exr)
awk -v a="$a" -v w="$1" 'BEGIN { exit !(a > 0.005 && a < 1 && w > 30 * a) }' \
    || fail "Blender export: photometric avg $a should be moderate and far below the radiometric $1"

# ---- e. errors ----
python3 -c 'import json; d = json.load(open("sun-w.gltf")); d["extensions"]["DR_units"]["lights"] = "lumens"; json.dump(d, open("bad.gltf", "w"))'
run render bad.gltf $R -o bad.png
check_failed 3 "bad.gltf|/extensions/DR_units/lights"
[ ! -e bad.png ] || fail "an image was written for a bad DR_units"
run render sun.gltf $R -o bad.png --light-units watts
check_failed 2 "--light-units watts"
echo "cli_units: all passed"
