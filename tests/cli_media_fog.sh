#!/usr/bin/env bash
# A global fog around a grid medium: d/d extinction of the unbounded medium.
#   a. Its scattering gain from gain paths, whose position is drawn
#      exponentially (rays never leave a global medium): here because one
#      channel does not scatter (DRT then always takes gain paths). Without
#      the gain term the estimate had the wrong sign (-0.25 against FD +0.22,
#      z = -14); fdcheck must agree.
#   b. As the file is, the pilot (medium_grad.h) finds most of the fog's
#      stretches collide and takes the gain at the path's collisions:
#      grad --json says so, fdcheck agrees, and the baseline reports no
#      choice. A thin fog seen once (fog-khr) keeps gain paths, a thick one
#      (fog-dense) takes the collisions without a pilot, and so does a grid
#      (smoke), whose voxels keep gain paths.
# Run by tests/run.sh (env: DRENDER, DR_TESTDIR); also runs alone.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
cli_setup media-fog
require_drender
data=$DR_TESTDIR/data/media
params=(--param /extensions/DR_medium/extinction --param /extensions/DR_medium/g
        --param /materials/smoke/extensions/DR_medium/density_scale)

# a. gain paths in the unbounded medium
absorbing=(--set /extensions/DR_medium/albedo=0.9,0.9,0)
run grad "$data/fog-global.gltf" --param /extensions/DR_medium/extinction "${absorbing[@]}" --res 16x16 --spp 2 \
    -o "$tmp/d.exr" --json
expect_rc 0 "grad on the global fog with a channel that does not scatter"
json_check "$tmp/out" 'd["medium_gain"] == [{"medium": "/extensions/DR_medium", "source": "gain_paths", "reason": "nonscattering_channel"}]'
run fdcheck "$data/fog-global.gltf" "${params[@]}" "${absorbing[@]}" --spp 16 --res 16x16 --batches 16 --eps 0.03
expect_rc 0 "fdcheck on a global fog's gain paths around a grid medium"
expect_in out "all 5 entries agree" "every entry agrees (gain paths)"

# b. the pilot's choice
run grad "$data/fog-global.gltf" --param /extensions/DR_medium/extinction --res 16x16 --spp 2 -o "$tmp/d.exr" --json
expect_rc 0 "grad on the global fog"
json_check "$tmp/out" 'len(d["medium_gain"]) == 1 and d["medium_gain"][0]["source"] == "collisions" and d["medium_gain"][0]["reason"] == "pilot" and d["medium_gain"][0]["pilot_collided"] >= 0.4 * d["medium_gain"][0]["pilot_stretches"] >= 0.4 * 64'
run fdcheck "$data/fog-global.gltf" "${params[@]}" --spp 16 --res 16x16 --batches 16 --eps 0.03
expect_rc 0 "fdcheck on a global fog's collisions around a grid medium"
expect_in out "all 5 entries agree" "every entry agrees (collisions)"
run fdcheck "$data/fog-global.gltf" --param /extensions/DR_medium/extinction --res 8x8 --spp 2 --batches 2 --json
json_check "$tmp/out" 'd["medium_gain"][0]["source"] == "collisions" and d["medium_gain"][0]["reason"] == "pilot"'
run grad "$data/fog-global.gltf" --param /extensions/DR_medium/extinction --res 16x16 --spp 2 -o "$tmp/d.exr" --json \
    --medium-grad baseline
expect_rc 0 "grad on the global fog, baseline"
json_check "$tmp/out" '"medium_gain" not in d'
run grad "$data/fog-khr.gltf" --param /materials/0/extensions/DR_medium/extinction --res 16x16 --spp 2 \
    -o "$tmp/d.exr" --json
expect_rc 0 "grad on a thin fog"
json_check "$tmp/out" 'd["medium_gain"][0]["source"] == "gain_paths" and d["medium_gain"][0]["reason"] == "pilot" and 64 <= d["medium_gain"][0]["pilot_stretches"] and d["medium_gain"][0]["pilot_collided"] < 0.4 * d["medium_gain"][0]["pilot_stretches"]'
run grad "$data/fog-dense.gltf" --param /materials/0/extensions/DR_medium/extinction --res 8x8 --spp 1 \
    -o "$tmp/d.exr" --json
expect_rc 0 "grad on a dense fog"
json_check "$tmp/out" 'd["medium_gain"] == [{"medium": "/materials/0/extensions/DR_medium", "source": "collisions", "reason": "thick"}]'
run grad "$data/smoke.gltf" --param /materials/0/extensions/DR_medium/density_scale \
    --param /materials/0/extensions/DR_medium/density --res 8x8 --spp 1 -o "$tmp/d.exr" --json
expect_rc 0 "grad on a smoke grid"
json_check "$tmp/out" 'd["medium_gain"] == [{"medium": "/materials/0/extensions/DR_medium", "source": "collisions", "reason": "grid", "voxels_source": "gain_paths"}]'
echo "cli_media_fog: all passed"
