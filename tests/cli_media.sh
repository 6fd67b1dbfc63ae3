#!/usr/bin/env bash
# Participating media from the command line (scenes in tests/data/media/,
# written by make_scenes.py there):
#   a. render --json lists the effects media / heterogeneous_media and the
#      stage participating_media; the Cornell box lists none of them
#   b. params lists the DR_medium parameters (KHR_materials_volume media too)
#   c. grad / fdcheck on media parameters (a homogeneous KHR medium; a global
#      fog around a grid medium) with --medium-grad drt and baseline;
#      a bad --medium-grad value is a usage error (exit 2)
#      and extinction 1e4 with albedo 0.999 at depth 1000 stays finite
#   d. bad media input (missing grid) is an input error naming file and JSON path
#   e. optimize grows density in an all-empty grid (4^3, one majorant cell):
#      DRT lowers the loss and moves towards the true grid, the baseline's
#      gradient is 0 there and the grid stays empty; -o writes the grid back
#   f. OpenVDB grids (smoke.vdb, written by make_vdb.py: smoke.raw's voxels):
#      the render and the density gradient are bit-identical to the raw
#      grid's with the same seed; fdcheck of the VDB-loaded voxels (all at
#      once and a +-1 pattern) agrees, prb and tape; optimize -o writes the
#      grid back as raw float32 with its resolution; bad VDB input (not a VDB,
#      no float grid, only a vec3 grid, an empty grid, an unknown grid name, a
#      resolution that disagrees) is an input error naming file and JSON path
#   g. dielectric boundaries (glass-fog.gltf: fog-khr.gltf with ior 1.5):
#      --json lists the effect and the stage dielectric_boundaries (the
#      index-matched scenes do not); fdcheck of the medium's albedo and
#      extinction and of the floor's base colour seen through the glass, prb
#      and tape (DRT); prb and tape give the same gradient to 1e-12; an ior
#      out of [1, 10] and a non-transmissive KHR_materials_volume boundary
#      are input errors naming file and JSON path
# Run by tests/run.sh (env: DRENDER, DR_TESTDIR); also runs alone.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
data=$DR_TESTDIR/data/media
cli_setup media
cli_cmd_label="last command"
require_drender

# a. effects
run render "$data/smoke.gltf" --spp 4 --res 24x24 -o smoke.png --json
expect_rc 0 "render smoke"
expect_in out '"media", "heterogeneous_media"' "render --json effects of a grid medium"
expect_in out '"participating_media"' "render --json stages of a grid medium"
run render "$data/fog-khr.gltf" --spp 4 --res 24x24 -o fog.png --json
expect_rc 0 "render KHR_materials_volume fog"
expect_in out '"media"' "render --json effects of a homogeneous medium"
expect_in out '"stage_seconds": {"camera": ' "render --json stage times (media inside a mesh: the array tracer)"
grep -q heterogeneous_media "$tmp/out" && fail "a homogeneous medium listed as heterogeneous_media"
# a global medium: every path one at a time, so no stage times
run render "$data/fog-global.gltf" --spp 2 --res 16x16 -o fog-global.png --json
expect_rc 0 "render a global medium"
expect_in out '"stage_seconds": null' "render --json stage times of a global medium"
run render --spp 1 --res 16x16 -o box.png --json
expect_rc 0 "render the Cornell box"
grep -q '"media"\|heterogeneous_media\|participating_media' "$tmp/out" && fail "the Cornell box must not list media effects or stages"

# b. params
run params "$data/smoke.gltf"
expect_rc 0 "params smoke"
for p in extinction albedo g density_scale density; do
    expect_in out "/materials/0/extensions/DR_medium/$p" "params lists $p"
done
run params "$data/fog-khr.gltf"
expect_in out "/materials/0/extensions/DR_medium/extinction" "params of a KHR_materials_volume medium"

# c. grad and fdcheck
for mg in drt baseline; do
    run grad "$data/smoke.gltf" --param /materials/smoke/extensions/DR_medium/density_scale \
        --param /materials/smoke/extensions/DR_medium/g --spp 4 --res 16x16 --medium-grad $mg -o "dimg-$mg.exr" --json
    expect_rc 0 "grad --medium-grad $mg"
    expect_in out "\"medium_grad\": \"$mg\"" "grad --json names the method"
done
run grad "$data/smoke.gltf" --param /materials/smoke/extensions/DR_medium/g --medium-grad exact
check_failed 2 "--medium-grad|exact|drt|baseline"
run fdcheck "$data/fog-khr.gltf" --param /materials/0/extensions/DR_medium/albedo \
    --param /materials/0/extensions/DR_medium/extinction --spp 16 --res 12x12 --batches 8 --json
expect_rc 0 "fdcheck on homogeneous medium coefficients"
# an unbounded global fog around the grid cube: rays never leave it
run fdcheck "$data/fog-global.gltf" --param /extensions/DR_medium/extinction --param /extensions/DR_medium/g \
    --param /materials/smoke/extensions/DR_medium/density_scale --spp 16 --res 16x16 --batches 16 --eps 0.03 --json
expect_rc 0 "fdcheck on a global medium and a grid medium inside it"

# hard case: extinction up to 1e4 with albedo 0.999 at depth 1000: finite gradients, nothing dropped
run grad "$data/fog-dense.gltf" --param /materials/0/extensions/DR_medium/extinction \
    --param /materials/0/extensions/DR_medium/albedo --max-depth 1000 --spp 2 --res 12x12 -o dense.exr --json
expect_rc 0 "grad on a dense, almost white medium at depth 1000"
expect_in out '"invalid_samples": 0' "no non-finite samples in the dense medium"

# d. bad input
sed 's/"smoke.raw"/"missing.raw"/' "$data/smoke.gltf" >bad.gltf
run render bad.gltf -o bad.png
check_failed 3 "bad.gltf|/materials/0/extensions/DR_medium/density/uri|missing.raw"
[ ! -e bad.png ] || fail "nothing may be written for a bad scene"

# e. optimize from an empty grid
run render "$data/coarse.gltf" --spp 256 --res 32x32 -o target.exr
expect_rc 0 "target render"
for mg in drt baseline; do
    run optimize "$data/coarse-empty.gltf" --target target.exr \
        --param /materials/smoke/extensions/DR_medium/density --iters 40 --spp 16 --medium-grad $mg \
        --reference "$data/coarse.gltf" --out-dir "opt-$mg" -o "opt-$mg.gltf" --json
    expect_rc 0 "optimize --medium-grad $mg"
    tail -n 1 "$tmp/out" | grep -o '"reference_error": {[^}]*}' | grep -o '[-+0-9.eE]*}$' | tr -d '}' >"err-$mg"
    awk -F, 'NR == 2 { print $2, $4 }' "opt-$mg/loss.csv" >"first-$mg"
    awk -F, 'END { print $2, $4 }' "opt-$mg/loss.csv" >"last-$mg"
done
read -r loss0 perr0 <first-drt
read -r loss1 perr1 <last-drt
read -r bloss0 bperr0 <first-baseline
read -r bloss1 bperr1 <last-baseline
echo "optimize from an empty grid: DRT loss $loss0 -> $loss1, grid error $perr0 -> $perr1 (relative $(cat err-drt));" \
    "baseline grid error $bperr0 -> $bperr1"
awk -v a="$loss0" -v b="$loss1" 'BEGIN { exit !(b < 0.7 * a) }' || fail "DRT: loss $loss0 -> $loss1, expected a 30% drop"
awk -v a="$perr0" -v b="$perr1" 'BEGIN { exit !(b < 0.85 * a) }' || fail "DRT: grid error $perr0 -> $perr1"
[ "$bperr0" = "$bperr1" ] || fail "baseline: the grid must stay empty (error $bperr0 -> $bperr1)"
[ -s opt-drt.medium0.raw ] || fail "optimize -o must write the grid (opt-drt.medium0.raw)"
grep -q '"opt-drt.medium0.raw"' opt-drt.gltf || fail "the written scene must reference its grid"
run params opt-drt.gltf
expect_rc 0 "the optimised scene loads"
# f. OpenVDB
for f in smoke smoke-vdb; do
    run render "$data/$f.gltf" --spp 8 --res 32x32 --seed 5 -o "$f.exr"
    expect_rc 0 "render $f"
    mkdir -p "g-$f"
    run grad "$data/$f.gltf" --target smoke.exr --param /materials/0/extensions/DR_medium/density \
        --spp 4 --res 32x32 --seed 9 --grad-dir "g-$f"
    expect_rc 0 "grad density of $f"
done
# idiff with thresholds 0: every pixel equal (the files differ in their DateTime)
idiff -fail 0 -warn 0 smoke.exr smoke-vdb.exr >/dev/null ||
    fail "a VDB grid must render bit-identically to the same voxels as raw float32"
idiff -fail 0 -warn 0 g-smoke/grad-materials-0-extensions-DR_medium-density.exr \
    g-smoke-vdb/grad-materials-0-extensions-DR_medium-density.exr >/dev/null ||
    fail "the density gradient of a VDB grid must equal the raw grid's"
for est in prb tape; do
    run fdcheck "$data/smoke-vdb.gltf" --param /materials/0/extensions/DR_medium/density --spp 16 --res 16x16 \
        --batches 16 --eps 0.1 --estimator $est
    expect_rc 0 "fdcheck of VDB-loaded voxels ($est)"
done
run optimize "$data/smoke-vdb.gltf" --target smoke.exr --param /materials/0/extensions/DR_medium/density \
    --iters 2 --spp 4 -o vdbopt.gltf --out-dir vdbopt
expect_rc 0 "optimize a VDB grid"
[ -s vdbopt.medium0.raw ] || fail "optimize -o writes a VDB-sourced grid as raw float32 (vdbopt.medium0.raw)"
python3 -c 'import json,sys; d=json.load(open(sys.argv[1]))["materials"][0]["extensions"]["DR_medium"]["density"]
assert d == {"uri": "vdbopt.medium0.raw", "resolution": [16, 16, 16]}, d' vdbopt.gltf ||
    fail "the written scene must reference the raw grid with its resolution"
bad_vdb() {   # NAME EDIT WANT: smoke-vdb.gltf edited by sed expression EDIT must fail naming WANT
    sed "$2" "$data/smoke-vdb.gltf" >"$1.gltf"
    run render "$1.gltf" -o "$1.png"
    check_failed 3 "$1.gltf|/materials/0/extensions/DR_medium/density/uri|$3"
}
for f in not-a-vdb nofloat vec3 empty; do
    cp "$data/$f.vdb" .
done
bad_vdb notvdb 's/"smoke.vdb"/"not-a-vdb.vdb"/' "not-a-vdb.vdb: cannot read volume: not an OpenVDB file"
bad_vdb nofloat 's/"smoke.vdb"/"nofloat.vdb"/' "nofloat.vdb: cannot read volume: no float grid"
bad_vdb vec3 's/"smoke.vdb"/"vec3.vdb"/' "vec3.vdb: cannot read volume: no float grid (the file has: velocity (vec3))"
bad_vdb emptyvdb 's/"smoke.vdb"/"empty.vdb"/' "empty.vdb: cannot read volume: grid 'density' has no active voxels"
cp "$data/smoke.vdb" .
bad_vdb gridname 's/"uri": "smoke.vdb"/"uri": "smoke.vdb", "grid": "velocity"/' "no float grid named 'velocity'"
bad_vdb vdbres 's/"uri": "smoke.vdb"/"uri": "smoke.vdb", "resolution": [16, 16, 8]/' "16x16x16 voxels"

# g. dielectric boundaries
run render "$data/glass-fog.gltf" --spp 4 --res 24x24 -o glass.png --json
expect_rc 0 "render a glass cube of fog"
python3 -c 'import json, sys; j = json.load(open(sys.argv[1]))
sys.exit(not ({"media", "dielectric_boundaries"} <= set(j["effects"]) and
              {"participating_media", "dielectric_boundaries"} <= set(j["stages"])))' "$tmp/out" \
    || fail "render --json effects and stages of a dielectric boundary: media/participating_media and dielectric_boundaries"
run render "$data/fog-khr.gltf" --spp 1 --res 8x8 -o fog.png --json
grep -q dielectric "$tmp/out" && fail "an index-matched boundary must not plan the dielectric stage"
glass_params=(--param /materials/0/extensions/DR_medium/albedo --param /materials/0/extensions/DR_medium/extinction
              --param /materials/1/pbrMetallicRoughness/baseColorFactor)
for est in prb tape; do
    run fdcheck "$data/glass-fog.gltf" "${glass_params[@]}" --spp 32 --res 12x12 --batches 16 --eps 0.05 \
        --estimator $est
    expect_rc 0 "fdcheck through a dielectric boundary ($est)"
    run grad "$data/glass-fog.gltf" --target fog.png "${glass_params[@]}" --res 8x8 --spp 8 --estimator $est --json
    expect_rc 0 "grad through a dielectric boundary ($est)"
    cp "$tmp/out" "glass-$est.json"
done
python3 - glass-prb.json glass-tape.json <<'PY' || fail "prb and tape must agree through a dielectric boundary"
import json, sys
a, b = (json.load(open(f))["parameters"] for f in sys.argv[1:3])
worst = max(abs(x - y) / max(abs(x), abs(y), 1e-300) for p, q in zip(a, b) for x, y in zip(p["gradient"], q["gradient"]))
print("glass-fog: prb vs tape, largest relative difference %.3g" % worst)
sys.exit(worst > 1e-12)
PY
sed 's/"ior": 1.5/"ior": 0.5/' "$data/glass-fog.gltf" >badior.gltf
run render badior.gltf -o badior.png
check_failed 3 "badior.gltf|/materials/0/extensions/KHR_materials_ior/ior|[1, 10]"
sed 's/"transmissionFactor": 1/"transmissionFactor": 0.5/' "$data/glass-fog.gltf" >opaque.gltf
run render opaque.gltf -o opaque.png
check_failed 3 "opaque.gltf|/materials/0/extensions/KHR_materials_volume|transmissionFactor"

echo "cli_media: all passed"
