#!/usr/bin/env bash
# --sampling derivative (issue 12) and derivative-roughness on the command line: the help of grad,
# fdcheck and optimize names it; grad runs it in reverse and forward mode
# and --json reports what ran; fdcheck agrees with finite differences;
# optimize takes it; tape gives prb's gradient, also in a scene with
# participating media (which attached sampling still refuses); unknown
# names list it.
# Run by tests/run.sh (env: DRENDER, DR_TESTDIR); also runs alone.
#
# Expected exit codes: 0 success; 2 usage error (unknown name; attached sampling on a scene with media: refused
# before any work).
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
cli_setup deriv
cli_cmd_label="last command" cli_out_bytes=3000
require_drender
red=/materials/red/pbrMetallicRoughness/baseColorFactor
rough=/materials/rough-gold/pbrMetallicRoughness/roughnessFactor
metal=/materials/rough-gold/pbrMetallicRoughness/metallicFactor
light=/materials/light/emissiveFactor
fast="--res 16x16 --spp 4 --threads 2"

# ---- help: every command that differentiates names the mode ----
for cmd in grad fdcheck optimize; do
    run help "$cmd"
    expect_rc 0 "help $cmd"
    grep -A3 -e "--sampling" "$tmp/out" | grep -q "derivative" || fail "help $cmd: --sampling does not name derivative"
    grep -A3 -e "--sampling" "$tmp/out" | grep -q "derivative-roughness" ||
        fail "help $cmd: --sampling does not name derivative-roughness"
done

# ---- grad, reverse mode: what ran ----
run render -o t.exr $fast
expect_rc 0 "render target"
run grad --target t.exr --param "$rough" --param "$metal" --sampling derivative --batches 2 $fast --json
expect_rc 0 "grad --sampling derivative"
json_check "$tmp/out" 'd["sampling"] == "derivative" and d["sampling_effective"] == "derivative"
and all(math.isfinite(g) for p in d["parameters"] for g in p["gradient"])'
# no BSDF parameter: nothing to sample for, runs (and reports) detached
run grad --target t.exr --param "$light" --sampling derivative --batches 2 $fast --json
expect_rc 0 "grad --sampling derivative (emission only)"
json_check "$tmp/out" 'd["sampling"] == "derivative" and d["sampling_effective"] == "detached"'
# the derivative directions' extra radiance paths cost rays
run grad --target t.exr --param "$rough" --sampling detached --batches 2 $fast --json
cp "$tmp/out" det.json
run grad --target t.exr --param "$rough" --sampling derivative --batches 2 $fast --json
json_check "$tmp/out" 'd["rays"]["extension"] > json.load(open("det.json"))["rays"]["extension"]'

# ---- forward mode writes a finite derivative image ----
run grad --param "$rough" --sampling derivative -o d.exr $fast
expect_rc 0 "grad forward --sampling derivative"
[ -s d.exr ] || fail "grad forward --sampling derivative: no d.exr"

# ---- fdcheck: agrees ----
run fdcheck --param "$red" --param "$metal" --sampling derivative --res 12x12 --spp 8 --batches 4 --threads 2 --json
expect_rc 0 "fdcheck --sampling derivative"
json_check "$tmp/out" 'd["agree"] is True and d["sampling"] == "derivative" and len(d["entries"]) == 4'

# ---- optimize takes it ----
run optimize --target t.exr --param "$red" --set "$red=0.4,0.4,0.4" --sampling derivative --iters 2 \
    $fast -o o.gltf --json
expect_rc 0 "optimize --sampling derivative"
tail -n 1 "$tmp/out" > summary.json
json_check summary.json 'd["sampling"] == "derivative"'

# ---- refusals ----
# ---- tape: the same gradient as prb, to rounding ----
run grad --target t.exr --param "$rough" --param "$red" --estimator prb --sampling derivative --batches 2 $fast --json
cp "$tmp/out" prb.json
run grad --target t.exr --param "$rough" --param "$red" --estimator tape --sampling derivative --batches 2 $fast --json
expect_rc 0 "grad --estimator tape --sampling derivative"
json_check "$tmp/out" 'all(abs(a - b) <= 1e-9 * (abs(a) + 1e-12) for p, q in zip(d["parameters"], json.load(open("prb.json"))["parameters"]) for a, b in zip(p["gradient"], q["gradient"]))'

# ---- derivative-roughness: derivative sampling's directions for the roughness alone ----
same_as() {   # same_as FILE INDEX TOL: parameter INDEX's gradient equals FILE's to TOL relative
    json_check "$tmp/out" "all(abs(a - b) <= $3 * (abs(b) + 1e-300) for a, b in zip(d['parameters'][$2]['gradient'],
        json.load(open('$1'))['parameters'][$2]['gradient']))"
}
run grad --target t.exr --param "$rough" --sampling derivative --batches 2 $fast --json
cp "$tmp/out" rough-der.json
run grad --target t.exr --param "$rough" --sampling derivative-roughness --batches 2 $fast --json
expect_rc 0 "grad --sampling derivative-roughness (roughness alone)"
json_check "$tmp/out" 'd["sampling"] == "derivative-roughness" and d["sampling_effective"] == "derivative-roughness"'
# a roughness alone: the same directions and weights as derivative sampling, to the digit
same_as rough-der.json 0 0
# beside a base colour: the colour keeps detached sampling's estimate (to
# rounding), and no third direction is sampled for it (fewer rays than derivative)
run grad --target t.exr --param "$rough" --param "$red" --sampling detached --batches 2 $fast --json
cp "$tmp/out" both-det.json
run grad --target t.exr --param "$rough" --param "$red" --sampling derivative --batches 2 $fast --json
cp "$tmp/out" both-der.json
run grad --target t.exr --param "$rough" --param "$red" --sampling derivative-roughness --batches 2 $fast --json
expect_rc 0 "grad --sampling derivative-roughness (roughness and a colour)"
cp "$tmp/out" both-dr.json
same_as both-det.json 1 1e-9
json_check "$tmp/out" 'd["parameters"][0]["gradient"][0] != json.load(open("both-det.json"))["parameters"][0]["gradient"][0]'
json_check "$tmp/out" 'd["rays"]["extension"] < json.load(open("both-der.json"))["rays"]["extension"]'
run grad --target t.exr --param "$rough" --param "$red" --estimator tape --sampling derivative-roughness --batches 2 \
    $fast --json
expect_rc 0 "grad --estimator tape --sampling derivative-roughness"
same_as both-dr.json 0 1e-9
same_as both-dr.json 1 1e-9
# no roughness requested: nothing to sample for, runs (and reports) detached,
# on detached's walk: its numbers to the last digit
run grad --target t.exr --param "$red" --param "$metal" --sampling detached --batches 2 $fast --json
cp "$tmp/out" cm-det.json
run grad --target t.exr --param "$red" --param "$metal" --sampling derivative-roughness --batches 2 $fast --json
json_check "$tmp/out" 'd["sampling"] == "derivative-roughness" and d["sampling_effective"] == "detached"'
same_as cm-det.json 0 0
same_as cm-det.json 1 0
run fdcheck --param "$rough" --param "$metal" --set "$rough=0.5" --sampling derivative-roughness --res 12x12 --spp 8 \
    --batches 4 --threads 2 --json
expect_rc 0 "fdcheck --sampling derivative-roughness"
json_check "$tmp/out" 'd["agree"] is True and d["sampling"] == "derivative-roughness" and len(d["entries"]) == 2'

# ---- media: the radiance walks are the medium walker's; prb and tape agree there too ----
fog="$DR_TESTDIR/data/media/fog-khr.gltf"
floor=/materials/floor/pbrMetallicRoughness
for smp in derivative derivative-roughness; do
    run render "$fog" -o fog-t.exr --res 12x12 --spp 16
    run grad "$fog" --target fog-t.exr --param "$floor/roughnessFactor" --param "$floor/baseColorFactor" \
        --set "$floor/roughnessFactor=0.2" --set "$floor/metallicFactor=1" --sampling $smp --res 12x12 --spp 4 \
        --batches 2 --threads 2 --json
    expect_rc 0 "grad --sampling $smp on a scene with media"
    json_check "$tmp/out" "d['sampling_effective'] == '$smp' and all(math.isfinite(g) for p in d['parameters'] for g in p['gradient'])"
    cp "$tmp/out" fog-prb.json
    run grad "$fog" --target fog-t.exr --param "$floor/roughnessFactor" --param "$floor/baseColorFactor" \
        --set "$floor/roughnessFactor=0.2" --set "$floor/metallicFactor=1" --sampling $smp --res 12x12 --spp 4 \
        --batches 2 --threads 2 --json --estimator tape
    expect_rc 0 "grad --estimator tape --sampling $smp on a scene with media"
    same_as fog-prb.json 0 1e-9
    same_as fog-prb.json 1 1e-9
done
# attached sampling still cannot take media
run grad "$fog" --param "$floor/roughnessFactor" --sampling attached -o d.exr $fast
expect_rc 2 "attached sampling on a scene with media (bad usage, refused before any work)"
expect_mentions "attached sampling|participating media|--sampling detached"
run grad --target t.exr --param "$red" --sampling derivativ $fast
check_failed 2 "--sampling|derivativ|derivative"

echo "cli_sampling_derivative: all passed"
