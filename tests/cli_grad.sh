#!/usr/bin/env bash
# drender params, grad and fdcheck on the bundled Cornell box: listings,
# forward mode (float derivative images, --vis pictures), reverse mode
# (loss, gradients with standard errors, texture gradient images, --json),
# fdcheck's verdict, and the errors of each.
# Run by tests/run.sh (env: DRENDER = the binary); also runs alone.
# Uses oiiotool (openimageio-tools) and python3 if present.
#
# Expected exit codes (cli/cli.h, man/drender.1):
#   0 = success
#   2 = usage error: unknown --param (message lists the nearest names), the same
#       parameter twice, unknown --sampling, --regularize outside [0, 1],
#       unknown --estimator, a target of
#       the wrong size, -o in a non-float format, ...
#   3 = input error: target or scene missing, unreadable or with NaN pixels
#   4 = fdcheck: some gradient disagrees with finite differences
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
cli_setup grad
cli_cmd_label="last command" cli_out_bytes=3000
# expect_fail CODE "NEEDLE1|NEEDLE2" ARGS...: exit CODE, every needle on stderr,
# nothing on stdout, no file left in the (empty) working directory.
expect_fail() {
    local want=$1 needles=$2
    shift 2
    local before
    before=$(ls -A)
    run "$@"
    expect_rc "$want" "$*"
    [ -s "$tmp/err" ] || fail "$*: expected an error message on stderr"
    expect_mentions "$needles" "$*"
    expect_empty out "$*"
    [ "$(ls -A)" = "$before" ] || fail "$*: left files behind: $(ls -A)"
}

require_drender
red=/materials/red/pbrMetallicRoughness/baseColorFactor
red_idx=/materials/1/pbrMetallicRoughness/baseColorFactor
fast="--res 16x16 --spp 4"

# ---- help ----
run --help
for cmd in params grad fdcheck; do
    grep -Eq "^ +$cmd +[^ ]" "$tmp/out" || fail "drender --help: expected command '$cmd' listed"
done
for cmd in params grad fdcheck; do
    run help "$cmd"
    expect_rc 0 "help $cmd"
    expect_in out "usage: drender $cmd" "help $cmd"
    cp "$tmp/out" "$tmp/help.$cmd"
    run "$cmd" --help
    expect_rc 0 "$cmd --help"
    cmp -s "$tmp/out" "$tmp/help.$cmd" || fail "'drender help $cmd' and 'drender $cmd --help' differ"
done
run grad --help
for opt in --param -o --vis --target --loss --batches --grad-dir --estimator --sampling --spp --max-depth \
    --res --camera --seed --threads --batch --json; do
    grep -qE -- "(^|[ ,])$opt([ ,=]|\$)" "$tmp/out" || fail "grad --help: expected option $opt"
done
run fdcheck --help
for opt in --param --eps --spp --batches --z-max --estimator --sampling --res --max-depth --seed --threads --json; do
    grep -qE -- "(^|[ ,])$opt([ ,=]|\$)" "$tmp/out" || fail "fdcheck --help: expected option $opt"
done

# ---- params ----
run params
expect_rc 0 "params"
expect_empty err "params"
expect_in out "/materials/0/pbrMetallicRoughness/baseColorFactor" "params"
expect_in out "/images/0" "params"
expect_in out "64x64x3 image, mean (" "params (images summarised)"
expect_in out "'red'" "params (material names)"
run params --json
expect_rc 0 "params --json"
[ "$(wc -l <"$tmp/out")" -eq 1 ] || fail "params --json: expected one line"
json_check "$tmp/out" '
any(p["name"] == "/materials/0/pbrMetallicRoughness/baseColorFactor" and p["type"] == "color"
    and len(p["value"]) == 3 and p["material"] == "white" for p in d["parameters"])
and any(p["name"] == "/images/0" and p["type"] == "image" and p["width"] == 64 and p["channels"] == 3
        and len(p["mean"]) == 3 and "value" not in p for p in d["parameters"])
and d["scene"].endswith("cornell-box.gltf")'
expect_fail 2 "--bogus" params --bogus
expect_fail 3 "nope.gltf" params nope.gltf

# ---- grad: option errors (before any work, nothing written) ----
expect_fail 2 "/materials/red/pbrMetallicRoughnes/baseColorFactor|nearest valid names|$red_idx" \
    grad --param /materials/red/pbrMetallicRoughnes/baseColorFactor -o d.exr $fast
expect_fail 2 "requested twice" grad --param "$red" --param "$red_idx" -o d.exr $fast
expect_fail 2 "--sampling|bogus|detached|attached" grad --param "$red" --sampling bogus -o d.exr $fast
expect_fail 2 "--regularize|2" grad --param "$red" --sampling attached --regularize 2 -o d.exr $fast
expect_fail 2 "--regularize|x" grad --param "$red" --sampling attached --regularize x -o d.exr $fast
expect_fail 2 "--estimator|bogus|prb|tape" grad --param "$red" --estimator bogus -o d.exr $fast
expect_fail 2 "--param" grad -o d.exr $fast
expect_fail 2 "-o d.png|float" grad --param "$red" -o d.png $fast
expect_fail 2 "-o d.hdr|negative" grad --param "$red" -o d.hdr $fast
expect_fail 2 "-o" grad --param "$red" $fast
expect_fail 2 "--loss" grad --param "$red" -o d.exr --loss l1 $fast
expect_fail 2 "--batches" grad --param "$red" --target t.exr --batches 1
expect_fail 2 "--loss|l3" grad --param "$red" --target t.exr --loss l3
expect_fail 2 "--spp" grad --param "$red" -o d.exr --spp 0
expect_fail 2 "'--bogus'" grad --bogus
expect_fail 2 "--json" grad --json=1
expect_fail 1 "sub/d.exr" grad --param "$red" -o sub/d.exr $fast

# ---- grad, forward mode ----
run grad --param "$red" -o d.exr --vis d.png $fast
expect_rc 0 "grad forward"
expect_empty err "grad forward"
[ -s d.exr ] && [ -s d.png ] || fail "grad forward: expected d.exr and d.png"
run grad --param "$red" --param /images/0 -o m.exr --vis m.png $fast --json
expect_rc 0 "grad forward, two parameters"
for f in m.0.exr m.1.exr m.0.png m.1.png; do [ -s "$f" ] || fail "grad forward: expected $f (index before the extension)"; done
[ ! -e m.exr ] || fail "grad forward with two parameters: m.exr should not exist (indexed names)"
json_check "$tmp/out" 'd["mode"] == "forward" and [p["file"] for p in d["parameters"]] == ["m.0.exr", "m.1.exr"]
and d["parameters"][0]["max"] > 0 and "textures" in d["effects_differentiated"] and "bsdf" in d["effects_differentiated"]'
# several parameters share a pass (up to four: estimator.h's
# dr_estimator_forward_groups): each image is, to the bit, its parameter's
# run alone, in the first pass and in the second
five=(--param "$red" --param /images/0 --param /materials/white/pbrMetallicRoughness/baseColorFactor
    --param /materials/rough-gold/pbrMetallicRoughness/roughnessFactor --param /materials/light/emissiveFactor)
run grad "${five[@]}" -o p.exr $fast
expect_rc 0 "grad forward, five parameters"
run grad --param /materials/light/emissiveFactor -o l.exr $fast
expect_rc 0 "grad forward, the light alone"
if $have_oiio; then
    for pair in "m.0.exr d.exr" "p.0.exr d.exr" "p.4.exr l.exr"; do
        set -- $pair
        idiff -fail 0 -warn 0 "$1" "$2" >/dev/null 2>&1 || fail "grad forward: $1 (a shared pass) differs from $2 (alone)"
    done
fi
if $have_oiio; then
    info=$(oiiotool --info d.exr d.png 2>&1) || fail "oiiotool --info: $info"
    echo "$info" | grep -F "d.exr " | grep -Eq ' 16 x +16, 3 channel, float openexr' || fail "d.exr: not float EXR: $info"
    echo "$info" | grep -F "d.png " | grep -Eq ' 16 x +16, 3 channel, uint8 png' || fail "d.png: not an 8-bit PNG: $info"
    # the red wall's colour: derivative is positive somewhere, never meaningfully negative, and finite
    stats=$(oiiotool --stats d.exr 2>&1)
    echo "$stats" | grep -q 'NanCount: 0 0 0' || fail "d.exr has NaNs: $stats"
    max=$(echo "$stats" | sed -n 's/.*Max: *\([0-9.e+-]*\).*/\1/p' | head -n 1)
    awk -v m="${max:-0}" 'BEGIN { exit !(m > 0) }' || fail "d.exr: expected a positive derivative: $stats"
fi
# Forward mode: every thread writes one shared derivative image (a pixel's
# samples are one thread's, estimators/common.c): the same values, to the
# bit, for any thread count, with both estimators
if command -v idiff >/dev/null; then
    for est in prb tape; do
        for threads in 1 3 7; do
            run grad --param "$red" --param /images/0 -o "f$threads.exr" --res 40x24 --spp 3 --max-depth 5 \
                --estimator $est --threads $threads
            expect_rc 0 "grad forward --estimator $est --threads $threads"
        done
        for threads in 3 7; do
            for k in 0 1; do
                idiff -fail 0 -warn 0 "f1.$k.exr" "f$threads.$k.exr" >/dev/null ||
                    fail "grad forward ($est): parameter $k's derivative image on $threads threads differs from 1 thread"
            done
        done
    done
    rm -f f1.*.exr f3.*.exr f7.*.exr
fi

# ---- grad, reverse mode ----
run render --res 16x16 --spp 16 -o t.exr
expect_rc 0 "render the target"
run render --res 16x16 --spp 16 -o t.png
expect_rc 0 "render the target (png)"
run grad --target t.exr --param "$red" --param /images/0 --spp 8
expect_rc 0 "grad reverse"
expect_in out "loss (l2):" "grad reverse"
expect_in out "$red_idx:" "grad reverse"
expect_in out " +- " "grad reverse (standard errors)"
expect_in out "grad-images-0.exr" "grad reverse (texture gradient file)"
[ -s grad-images-0.exr ] || fail "grad reverse: expected grad-images-0.exr"
if $have_oiio; then
    oiiotool --info grad-images-0.exr 2>&1 | grep -Eq ' 64 x +64, 3 channel, float openexr' \
        || fail "grad-images-0.exr: expected a 64x64 float EXR: $(oiiotool --info grad-images-0.exr 2>&1)"
fi
mkdir gdir
for est in prb tape; do
    run grad --target t.exr --param "$red" --param /images/0 --estimator "$est" --spp 8 --batches 2 \
        --grad-dir gdir --json
    expect_rc 0 "grad reverse --json ($est)"
    expect_empty err "grad reverse --json ($est)"
    [ "$(wc -l <"$tmp/out")" -eq 1 ] || fail "grad --json: expected one line"
    json_check "$tmp/out" '
all(k in d for k in ["loss", "loss_kind", "estimator", "sampling", "spp", "batches", "time", "peak_memory_bytes",
                     "rays", "parameters", "effects_differentiated"])
and all(k in d["time"] for k in ["primal", "gradient", "total"])
and 0 <= d["loss"] < 0.5 and d["loss_kind"] == "l2" and d["sampling"] == "detached"
and d["batches"] == 2 and d["spp"] == 8
and d["estimator_memory_bytes"] > 0 and d["rr_depth"] == 5
and ((d["record_bytes"] > 0) if d["estimator"] == "tape" else d["record_bytes"] == 0)
and set(d["stages"]) == {"surface_emission", "next_event_estimation"}
and len(d["parameters"][0]["gradient"]) == 3 and len(d["parameters"][0]["stderr"]) == 3
and all(math.isfinite(x) for x in d["parameters"][0]["gradient"] + d["parameters"][0]["stderr"])
and d["parameters"][1]["file"] == "gdir/grad-images-0.exr" and math.isfinite(d["parameters"][1]["norm"])
and "gradient" not in d["parameters"][1]
and "bsdf" in d["effects_differentiated"] and "textures" in d["effects_differentiated"]
and d["vertices_shaded_8_wide"] > 0'
    # the texture's norm is that of the gradient image written (its floats:
    # the JSON's sum runs over the blocks the result's mask marks, cmd_grad.c);
    # scaled to about 1 first, as --dumpdata prints nine decimals
    if $have_oiio; then
        python3 - "$tmp/out" gdir/grad-images-0.exr "$tmp" <<'PY' || fail "grad --json ($est): the texture's norm is not its image's"
import json, math, subprocess, sys
d = json.load(open(sys.argv[1]))
want = d["parameters"][1]["norm"]
scaled = sys.argv[3] + "/scaled.exr"
subprocess.run(["oiiotool", sys.argv[2], "--mulc", repr(1.0 / want), "-o", scaled], check=True)
dump = subprocess.run(["oiiotool", "--dumpdata", scaled], check=True, capture_output=True, text=True).stdout
vals = [float(x) for line in dump.splitlines() if line.lstrip().startswith("Pixel") for x in line.split(":", 1)[1].split()]
norm = math.sqrt(sum(v * v for v in vals)) * want
print("texture norm", want, "from the image", norm, len(vals), "values")
sys.exit(0 if len(vals) == 64 * 64 * 3 and abs(norm - want) <= 1e-5 * want else 1)
PY
    fi
done
# (prb's walks and the tape's steps shade the hits on the undifferentiated
# materials eight lanes at a time; with the light'"'"'s emission a parameter,
# prb's primal walks and replays still do, the stages marking the vertices
# with a term and filling their light terms: path_simd.h)
run grad --target t.exr --param "$red" --param /materials/light/emissiveFactor --spp 4 --batches 2 --json
expect_rc 0 "grad reverse --json (an emission parameter)"
json_check "$tmp/out" 'd["primal"] == "cross" and d["vertices_shaded_8_wide"] > d["replayed_vertices_shaded_8_wide"] > 0'
# ... their time by stage (walks and replays together): ray queries and
# shading among them, within the time the gradient's threads had
json_check "$tmp/out" 'sorted(d["stage_seconds"]) == ["camera", "continuation", "escaped", "ray_queries", "shading"]
and d["stage_seconds"]["ray_queries"] > 0 and d["stage_seconds"]["shading"] > 0
and sum(d["stage_seconds"].values()) <= d["threads"] * d["time"]["total"] + 1e-3'
# the standard error's parts (issue 14), with a primal render per batch:
# total^2 = gradient part^2 + primal part^2
run grad --target t.exr --param "$red" --param /images/0 --spp 16 --batches 4 --primal separate --json
expect_rc 0 "grad reverse --json (stderr parts)"
json_check "$tmp/out" 'd["primal"] == "separate" and d["time"]["primal"] > 0'
json_check "$tmp/out" '
all(abs(t * t - g * g - q * q) <= 1e-9 * t * t + 1e-30 or (q == 0 and g >= t)
    for t, g, q in zip(*(d["parameters"][0][k] for k in ["stderr", "stderr_gradient", "stderr_primal"])))
and all(x > 0 for x in d["parameters"][0]["stderr_gradient"] + d["parameters"][0]["stderr"])
and d["spp_per_batch"] == 4
and all(math.isfinite(d["parameters"][1][k]) for k in ["stderr_norm", "stderr_gradient_norm", "stderr_primal_norm"])'
# one sample per batch: no halves, so no parts (null), the total is still there;
# and no other sample of the pixel to be its primal: the cross primal (the
# default) renders one, and says so
run grad --target t.exr --param "$red" --spp 2 --batches 2 --json
expect_rc 0 "grad reverse --json (spp 1 per batch)"
json_check "$tmp/out" '
d["parameters"][0]["stderr_gradient"] == [None] * 3 and d["parameters"][0]["stderr_primal"] == [None] * 3
and all(x > 0 for x in d["parameters"][0]["stderr"]) and d["primal"] == "separate" and d["time"]["primal"] > 0'
# the cross primal (default), with independent numbers (leave one out): the
# gradient's own samples are the loss's primal, no render, no parts; both
# estimators give the same numbers
for est in prb tape; do
    run grad --target t.exr --param "$red" --spp 16 --batches 4 --estimator $est --sampler independent --json
    expect_rc 0 "grad reverse --json (cross primal, $est)"
    cp "$tmp/out" "$tmp/cross-$est.json"
    json_check "$tmp/out" 'd["primal"] == "cross" and d["time"]["primal"] == 0 and 0 < d["loss"] < 0.5
and d["parameters"][0]["stderr_primal"] == [None] * 3
and all(math.isfinite(x) and x != 0 for x in d["parameters"][0]["gradient"] + d["parameters"][0]["stderr"])'
done
python3 - "$tmp/cross-prb.json" "$tmp/cross-tape.json" <<'PY' || fail "grad --primal cross: prb and tape differ"
import json, sys
a, b = (json.load(open(f)) for f in sys.argv[1:])
ga, gb = a["parameters"][0]["gradient"], b["parameters"][0]["gradient"]
sys.exit(not (all(abs(x - y) <= 1e-9 * max(abs(x), abs(y)) for x, y in zip(ga, gb)) and a["loss"] == b["loss"]))
PY
# sobol (the default there): the cross primal too, each sample weighted by
# the other half of its pixel's samples (two sequences scrambled apart); prb
# and tape agree (tape pairs a path with its half by its place in the pixel)
for est in prb tape; do
    run grad --target t.exr --param "$red" --spp 16 --batches 4 --estimator $est --sampler sobol --json
    expect_rc 0 "grad reverse --sampler sobol --json (cross primal, $est)"
    cp "$tmp/out" "$tmp/sobol-$est.json"
    json_check "$tmp/out" 'd["primal"] == "cross" and d["time"]["primal"] == 0 and d["sampler"] == "sobol"
and all(math.isfinite(x) and x != 0 for x in d["parameters"][0]["gradient"] + d["parameters"][0]["stderr"])'
done
python3 - "$tmp/sobol-prb.json" "$tmp/sobol-tape.json" "$tmp/cross-prb.json" <<'PY' || fail "grad --sampler sobol: prb and tape differ, or equal independent's"
import json, sys
a, b, ind = (json.load(open(f)) for f in sys.argv[1:])
ga, gb = a["parameters"][0]["gradient"], b["parameters"][0]["gradient"]
sys.exit(not (all(abs(x - y) <= 1e-9 * max(abs(x), abs(y)) for x, y in zip(ga, gb)) and a["loss"] == b["loss"]
              and ga != ind["parameters"][0]["gradient"]))
PY
# stratified samples of a pixel depend on each other (shared strata): their
# leave-one-out means would be correlated with the sample, so separate runs
run grad --target t.exr --param "$red" --spp 16 --batches 4 --sampler stratified --json
expect_rc 0 "grad --sampler stratified (cross requested)"
json_check "$tmp/out" 'd["primal"] == "separate" and d["time"]["primal"] > 0'
run grad --target t.exr --param "$red" --primal sideways
expect_rc 2 "grad --primal sideways"
expect_in err "unknown mode 'sideways' (available: cross, separate)" "grad --primal sideways"
run grad -o d.exr --param "$red" --primal separate
expect_rc 2 "grad --primal in forward mode"
expect_in err "--primal is for reverse mode" "grad --primal in forward mode"
[ -s gdir/grad-images-0.exr ] || fail "grad --grad-dir gdir: expected gdir/grad-images-0.exr"
# attached sampling (tape): roughness enters a sampling map, a colour does not
rough=/materials/4/pbrMetallicRoughness/roughnessFactor
run grad --target t.exr --param "$rough" --estimator tape --sampling attached --spp 4 --batches 2 --json
expect_rc 0 "grad --sampling attached (roughness)"
json_check "$tmp/out" 'd["sampling"] == "attached" and d["sampling_effective"] == "attached"
and all(math.isfinite(x) for x in d["parameters"][0]["gradient"] + d["parameters"][0]["stderr"])'
run grad --target t.exr --param "$rough" --estimator prb --sampling attached --regularize 0 --spp 4 --batches 2 --json
expect_rc 0 "grad --sampling attached (prb)"
json_check "$tmp/out" 'd["sampling_effective"] == "attached" and d["regularize"] == 0
and all(math.isfinite(x) for x in d["parameters"][0]["gradient"] + d["parameters"][0]["stderr"])'
run grad --target t.exr --param "$red" --estimator tape --sampling attached --spp 4 --batches 2 --json
expect_rc 0 "grad --sampling attached (colour)"
json_check "$tmp/out" 'd["sampling"] == "attached" and d["sampling_effective"] == "detached"'
run grad --target t.exr --param "$red" --estimator tape --spp 4 --batches 2 --json
json_check "$tmp/out" 'd["sampling_effective"] == "detached"'
# --sampling auto (the default): derivative-roughness sampling where a
# differentiated roughness is below 0.2, said in a note naming the parameter; detached, and
# no note, when a mode is given, the lobe is rough, or only a colour is
# differentiated; in a scene with media too (the medium walker walks its
# radiance paths)
run grad --target t.exr --param "$rough" --set "$rough=0.05" --spp 2 --json
expect_rc 0 "grad of roughness 0.05"
expect_in err "note: --sampling auto chose derivative-roughness sampling (directions sampled for the roughness derivative; base colours and metallic as detached): /materials/rough-gold/pbrMetallicRoughness/roughnessFactor is 0.05, below 0.2," "grad of roughness 0.05"
json_check "$tmp/out" 'd["sampling"] == "derivative-roughness" and d["sampling_requested"] == "auto" and d["sampling_effective"] == "derivative-roughness"'
run grad --target t.exr --param "$rough" --param "$red" --set "$rough=0.05" --spp 2 --sampling auto --json
expect_rc 0 "grad of roughness 0.05 with --sampling auto given"
expect_in err "is 0.05, below 0.12 (with a base colour or metallic differentiated)" "grad of roughness 0.05 with a colour"
json_check "$tmp/out" 'd["sampling"] == "derivative-roughness" and d["sampling_requested"] == "auto"'
# between the two thresholds: derivative-roughness for a roughness alone, detached beside a colour
run grad --target t.exr --param "$rough" --set "$rough=0.15" --spp 2 --json
expect_in err "is 0.15, below 0.2," "grad of roughness 0.15"
json_check "$tmp/out" 'd["sampling"] == "derivative-roughness"'
run grad --target t.exr --param "$rough" --param "$red" --set "$rough=0.15" --spp 2 --json
expect_empty err "grad of roughness 0.15 beside a colour"
json_check "$tmp/out" 'd["sampling"] == "detached" and d["sampling_requested"] == "auto"'
run grad --target t.exr --param "$rough" --param "$red" --set "$rough=0.05" --spp 2 --sampling detached --json
expect_empty err "grad of roughness 0.05 with --sampling detached given"
json_check "$tmp/out" 'd["sampling"] == "detached" and d["sampling_requested"] == "detached"'
run grad --target t.exr --param "$rough" --spp 2 --json
expect_empty err "grad of roughness 0.35 (the file's)"
json_check "$tmp/out" 'd["sampling"] == "detached" and d["sampling_requested"] == "auto"'
run grad --target t.exr --param "$red" --set "$rough=0.05" --spp 2 --json
expect_empty err "grad of a colour beside a roughness of 0.05"
json_check "$tmp/out" 'd["sampling"] == "detached"'
# a differentiated metallic-roughness texture counts with its texels' median
# roughness (basic.gltf's mr.png: G median 150/255, times the factor)
mr_rough=/materials/0/pbrMetallicRoughness/roughnessFactor
run grad "$DR_TESTDIR/data/gltf/basic.gltf" --param /images/1 --set "$mr_rough=0.1" --res 8x8 --spp 2 \
    -o "$tmp/mr-d.exr" --json
expect_rc 0 "grad of a metallic-roughness texture of median roughness 0.059"
expect_in err "--sampling auto chose derivative-roughness sampling (directions sampled for the roughness derivative; base colours and metallic as detached): the roughness in /images/1 has median 0.0588235, below 0.12" \
    "grad of a metallic-roughness texture of median roughness 0.059"
json_check "$tmp/out" 'd["sampling"] == "derivative-roughness"'
run grad "$DR_TESTDIR/data/gltf/basic.gltf" --param /images/1 --set "$mr_rough=0.5" --res 8x8 --spp 2 \
    -o "$tmp/mr-d.exr" --json
expect_rc 0 "grad of a metallic-roughness texture of median roughness 0.29"
json_check "$tmp/out" 'd["sampling"] == "detached"'
# a differentiated factor on that material: the roughness it makes with the texture (0.3 x 0.588)
run grad "$DR_TESTDIR/data/gltf/basic.gltf" --param "$mr_rough" --set "$mr_rough=0.3" --res 8x8 --spp 2 \
    -o "$tmp/mr-d.exr" --json
expect_rc 0 "grad of a roughness factor of 0.3 on a metallic-roughness texture of median 0.588"
expect_in err "roughnessFactor is 0.3 (0.176471 with its metallic-roughness texture: the texels' median G times it), below 0.2" \
    "grad of a roughness factor of 0.3 on a metallic-roughness texture"
json_check "$tmp/out" 'd["sampling"] == "derivative-roughness"'
fog_rough=/materials/floor/pbrMetallicRoughness/roughnessFactor
run grad "$DR_TESTDIR/data/media/fog-khr.gltf" --param "$fog_rough" --set "$fog_rough=0.1" --res 8x8 --spp 2 \
    -o "$tmp/fog-d.exr" --json
expect_rc 0 "grad of roughness 0.1 in a scene with media"
expect_in err "--sampling auto chose derivative-roughness sampling" "grad of roughness 0.1 in a scene with media"
json_check "$tmp/out" 'd["sampling"] == "derivative-roughness" and d["sampling_effective"] == "derivative-roughness"'
run grad --target t.exr --param "$red" --loss l1 --json
expect_rc 0 "grad --loss l1"
json_check "$tmp/out" 'd["loss_kind"] == "l1" and d["width"] == 16 and d["height"] == 16'
# an 8-bit sRGB target is decoded to linear (its clipped light makes the loss larger, not absurd)
run grad --target t.png --param "$red" --json
expect_rc 0 "grad --target t.png"
json_check "$tmp/out" '0 < d["loss"] < 1 and all(math.isfinite(x) for x in d["parameters"][0]["gradient"])'

# reverse-mode errors
expect_fail 2 "t.exr|16x16|--res" grad --target t.exr --param "$red" --res 8x8
expect_fail 3 "missing.exr" grad --target missing.exr --param "$red"
{ printf 'PF\n4 4\n-1.0\n'; for i in $(seq 48); do printf '\x00\x00\xc0\x7f'; done; } >nan.pfm   # all NaN
expect_fail 3 "nan.pfm|not a finite number" grad --target nan.pfm --param "$red"
expect_fail 2 "-o" grad --target t.exr --param "$red" -o x.exr
expect_fail 2 "--grad-dir|nodir" grad --target t.exr --param "$red" --grad-dir nodir
rm -f nan.pfm

# ---- grad: a texture parameter's memory ----
# NormalTangentTest's base colour, 2048x2048x3 = 12.6 M scalars, 96 MiB per
# vector of doubles. A reverse run holds the mean, the standard error and one
# batch's gradient (drivers/reverse.c), the estimator's thread 0 sums
# straight into the last and every other thread has one of its own
# (estimators/common.c): with the float texture and the gradient image's
# float copy, about 3.3 vectors over a run with a scalar parameter at one
# thread, one more per thread. (Before: 9.3 and 10.3 — scratch for the
# standard error's parts no run asked for, a copy per thread for thread 0.)
find_samples
ntt=$samples/NormalTangentTest/glTF/NormalTangentTest.gltf
[ -f "$ntt" ] || fail "NormalTangentTest.gltf not found beside the checkout"
run render "$ntt" --res 8x8 --spp 2 -o ntt.exr
expect_rc 0 "render NormalTangentTest (target)"
peak() {   # peak PARAM THREADS: sets PEAK, the grad run's peak memory in MiB (here, not in a subshell: fail exits)
    run grad "$ntt" --target ntt.exr --param "$1" --spp 4 --threads "$2" --grad-dir gdir --json
    expect_rc 0 "grad NormalTangentTest $1 --threads $2"
    PEAK=$(python3 -c 'import json, sys; print(json.load(open(sys.argv[1]))["peak_memory_bytes"] / 2**20)' "$tmp/out")
    [ -n "$PEAK" ] || fail "grad NormalTangentTest $1: no peak_memory_bytes"
}
# (AddressSanitizer's shadow memory and quarantine of freed blocks count in
# the peak: under it the runs are made, the bound is not checked)
asan=false
ldd "$DRENDER" 2>/dev/null | grep -q libasan && asan=true
peak /materials/0/pbrMetallicRoughness/roughnessFactor 1
base=$PEAK
for threads in 1 2; do
    peak /images/0 "$threads"
    tex=$PEAK
    echo "texture gradient, $threads thread(s): peak $tex MiB, a scalar's run $base MiB"
    $asan && continue
    awk -v b="$base" -v t="$tex" -v n="$threads" 'BEGIN { exit !(t - b < (3.5 + n) * 96) }' ||
        fail "grad of a 2048x2048x3 texture with $threads thread(s): $tex MiB peak against $base MiB for a scalar (over $((3 + threads)).5 vectors of 96 MiB)"
done
$asan && echo "note: $DRENDER is an AddressSanitizer build: the peak-memory bound is not checked"
# From 4 threads on, the threads add into one shared vector of exact sums
# (core/exact_sum.h: 17 bytes an entry instead of 8 for each thread but the
# first): the gradient is then the same to the bit for any thread count,
# and equal to the 2-thread (per-thread vectors) one but for rounding.
both=(--param /images/0 --param /materials/0/pbrMetallicRoughness/roughnessFactor)
for threads in 2 4 5; do
    mkdir -p "g$threads"
    run grad "$ntt" --target ntt.exr "${both[@]}" --spp 4 --threads "$threads" --grad-dir "g$threads" --json
    expect_rc 0 "grad NormalTangentTest texture + roughness --threads $threads"
    cp "$tmp/out" "g$threads.json"
done
python3 - g2.json g4.json g5.json <<'PY' || fail "grad of a texture on 4 and 5 threads: see above"
import json, sys
d2, d4, d5 = (json.load(open(f)) for f in sys.argv[1:])
T = d4["parameters"][0]["size"] + 1
g = [d["parameters"][1]["gradient"][0] for d in (d2, d4, d5)]
n = [d["parameters"][0]["norm"] for d in (d2, d4, d5)]
ok = g[1] == g[2] and n[1] == n[2]
ok = ok and abs(g[0] - g[1]) <= 1e-9 * abs(g[0]) and abs(n[0] - n[1]) <= 1e-9 * n[0]
ok = ok and d4["estimator_memory_bytes"] < 20 * T < 3 * 8 * T   # shared sums, not a vector per thread
print("roughness", g, "texture norm", n, "estimator memory", d2["estimator_memory_bytes"], d4["estimator_memory_bytes"])
sys.exit(not ok)
PY
command -v idiff >/dev/null && { idiff -a g4/grad-images-0.exr g5/grad-images-0.exr >/dev/null ||
    fail "texture gradient images on 4 and 5 threads differ"; }
rm -rf ntt.exr gdir/grad-images-0.exr g2 g4 g5 g2.json g4.json g5.json

# ---- fdcheck ----
run fdcheck --param "$red" --res 16x16 --spp 4 --batches 4
expect_rc 0 "fdcheck on the red wall's colour"
expect_in out "agree" "fdcheck"
expect_in out "$red_idx[0]" "fdcheck (entry labels)"
run fdcheck --param "$red" --res 16x16 --spp 4 --batches 4 --estimator tape --json
expect_rc 0 "fdcheck --json (tape)"
json_check "$tmp/out" 'd["agree"] is True and len(d["entries"]) == 3 and d["estimator"] == "tape"
and all(e["agree"] and math.isfinite(e["fd"]) and math.isfinite(e["reverse"]) for e in d["entries"])'
# an impossible threshold: every entry disagrees -> exit 4
run fdcheck --param "$red" --res 8x8 --spp 2 --batches 2 --z-max 1e-9
expect_rc 4 "fdcheck --z-max 1e-9"
expect_in out "DISAGREE" "fdcheck --z-max 1e-9"
expect_fail 2 "--eps" fdcheck --param "$red" --eps 0
expect_fail 2 "--batches" fdcheck --param "$red" --batches 1
expect_fail 2 "--batch" fdcheck --param "$red" --batch 3
expect_fail 2 "--sampling|bogus" fdcheck --param "$red" --sampling bogus
expect_fail 2 "nearest valid names" fdcheck --param /images/7
expect_fail 3 "nope.gltf" fdcheck nope.gltf --param "$red"

echo "cli_grad: all passed"
