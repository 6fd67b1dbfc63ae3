#!/usr/bin/env bash
# A global fog around a grid medium: d/d extinction of the unbounded medium
# needs the DRT gain term with an exponentially drawn position (rays never
# leave a global medium). Without it the estimate had the wrong sign
# (-0.25 against FD +0.22, z = -14); fdcheck must agree.
# Run by tests/run.sh (env: DRENDER, DR_TESTDIR); also runs alone.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
cli_setup media-fog
require_drender
run fdcheck "$DR_TESTDIR/data/media/fog-global.gltf" --param /extensions/DR_medium/extinction \
    --param /extensions/DR_medium/g --param /materials/smoke/extensions/DR_medium/density_scale \
    --spp 16 --res 16x16 --batches 16 --eps 0.03
expect_rc 0 "fdcheck on a global fog around a grid medium"
expect_in out "all 5 entries agree" "every entry agrees"
echo "cli_media_fog: all passed"
