#!/usr/bin/env bash
# Every model in ../shared/gltf-samples, rendered as a new user would
# (`drender render MODEL`, no options but a small size): real glTF files that
# were not written for drender (issue 13). For each: the exit status, a finite
# image (no NaN/Inf), not black, the default-light note exactly where the file
# has no light, and the effects --json reports for what the file uses.
# The feature-by-feature checks (what each effect does to the image) are in
# cli_gltf_features.sh, cli_gltf_surfaces.sh and cli_units.sh.
# Run by tests/run.sh (env: DRENDER, DR_TESTDIR); also runs alone.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
cli_setup gltf-samples
require_drender
find_samples

# model | exit | default-light note (yes/no) | effects that must be listed (comma-separated)
table="
Box/glTF/Box.gltf                                        |0|yes|environment,specular
Box/glTF-Draco/Box.gltf                                  |0|yes|environment,specular
BoxTextured/glTF/BoxTextured.gltf                        |0|yes|textures
BoxVertexColors/glTF/BoxVertexColors.gltf                |0|yes|vertex_colors
VertexColorTest/glTF/VertexColorTest.gltf                |0|yes|vertex_colors,textures
MultiUVTest/glTF/MultiUVTest.gltf                        |0|no|area_lights,textures
TextureTransformTest/glTF/TextureTransformTest.gltf      |0|yes|textures
TextureSettingsTest/glTF/TextureSettingsTest.gltf        |0|yes|textures,single_sided
SimpleSparseAccessor/glTF/SimpleSparseAccessor.gltf      |0|yes|environment
Cameras/glTF/Cameras.gltf                                |0|yes|environment
NormalTangentTest/glTF/NormalTangentTest.gltf            |0|yes|normal_maps,textures
CornellBox-bevy/glTF-Binary/CornellBox.glb               |0|no|area_lights
DepthOfFieldExample-bevy/glTF-Binary/DepthOfFieldExample.glb|0|no|punctual_lights,area_lights,textures
AnisotropyBarnLamp-KTX2/glTF/AnisotropyBarnLamp.gltf     |0|no|area_lights,textures,normal_maps,thin_transmission
"
count=0
while IFS='|' read -r model want note effects; do
    model=$(echo "$model" | tr -d ' ')
    [ -n "$model" ] || continue
    file=$samples/$model
    [ -f "$file" ] || fail "sample $model is missing"
    out=$(echo "$model" | tr '/' '_').exr
    run render "$file" --res 32x32 --spp 4 -o "$out" --json
    expect_rc "$want" "$model"
    count=$((count + 1))
    if [ "$want" -ne 0 ]; then
        [ ! -e "$out" ] || fail "$model: an image was written although it was refused"
        grep -q "$(basename "$model")" "$tmp/err" || fail "$model: the refusal does not name the file"
        continue
    fi
    n=$(grep -c "has no light" "$tmp/err")
    case $note in
    yes) [ "$n" -eq 1 ] || fail "$model: expected one default-light note, got $n" ;;
    no) [ "$n" -eq 0 ] || fail "$model has a light but got the default-light note" ;;
    esac
    python3 - "$tmp/out" "$effects" "$model" <<'PY' || fail "$model: --json effects"
import json, sys
j = json.load(open(sys.argv[1]))
want = [e for e in sys.argv[2].split(",") if e]
missing = [e for e in want if e not in j["effects"]]
if missing:
    sys.exit("%s: effects %s lack %s" % (sys.argv[3], j["effects"], missing))
PY
    python3 - "$out" "$model" <<'PY' || fail "$model: image not finite or black"
import subprocess, sys
s = subprocess.run(["oiiotool", "--stats", sys.argv[1]], capture_output=True, text=True).stdout
avg, bad = None, 0
for line in s.splitlines():
    w = line.split()
    if "Avg:" in w:
        avg = [float(x) for x in w[w.index("Avg:") + 1:w.index("Avg:") + 4]]
    if "NanCount:" in w or "InfCount:" in w:
        bad += sum(int(x) for x in w[2:])
if bad:
    sys.exit("%s: %d NaN/Inf pixel values" % (sys.argv[2], bad))
if avg is None or not max(avg) > 1e-3:
    sys.exit("%s: black image (avg %s)" % (sys.argv[2], avg))
PY
done <<< "$table"
[ "$count" -eq 14 ] || fail "ran $count of the 14 samples"
echo "cli_gltf_samples: all passed ($count models)"
