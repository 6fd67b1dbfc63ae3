#!/usr/bin/env bash
# drender optimize: parameter recovery on small synthetic scenes
# (tests/data/optimize/, written by make_scenes.py there). Each target is the
# scene rendered at its true values (drender render --spp 256); the optimiser
# starts from wrong values (--set, or a scene with a flat texture) and the
# final --json summary's "reference_error" (--reference = the true scene) must
# show the truth recovered:
#   a. a diffuse albedo, to 0.01 in 120 iterations (one view, then two views)
#   b. a 4x4 sRGB base-colour texture (/images/0): relative error down >= 10x
#   c. an emission strength (5% relative) and a metal's roughness (0.05),
#      optimised together (a glossy floor reflecting an area light)
#   d. interrupt and resume: K iterations then --resume to N equals N
#      uninterrupted (the same numbers, to the last digit); SIGINT/SIGTERM
#      during a run: exit 128+signal, a valid checkpoint, --resume works
#   e. -o result.gltf / result.glb: no errors from the Khronos glTF validator
#      (installed into build/node like tests/cli_gltf_validate.sh), `drender
#      params` reads back the optimiser's final values, the result renders
#      close to the target
# Run by tests/run.sh (env: DRENDER, DR_TESTDIR); also runs alone.
# Needs node + npm for part e (as cli_gltf_validate.sh); uses oiiotool and
# gnuplot if present.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
data=$DR_TESTDIR/data/optimize
cli_setup optimize
# fail shows the last lines of the command's output (optimize's output is long)
cli_cmd_label="last command"
cli_show_output() {
    echo "  --- stdout (last lines) ---" >&2; tail -n 3 "$tmp/out" | head -c 3000 >&2
    echo "  --- stderr (last lines) ---" >&2; tail -n 15 "$tmp/err" | head -c 3000 >&2
}
# The last line of stdout must be optimize's --json summary.
summary() { tail -n 1 "$tmp/out" | grep -q '^{"done": true' || fail "$1: no --json summary line on stdout"; tail -n 1 "$tmp/out" >"$tmp/$2"; }
# ref_error FILE NAME: the summary's reference_error of parameter NAME
ref_error() {
    grep -o '"reference_error": {[^}]*}' "$tmp/$1" | grep -o "\"$2\": [-+0-9.eE]*" | awk '{print $NF}'
}
# param_values FILE NAME: the summary's final values of NAME, space separated
param_values() {
    grep -o '"parameters": {[^}]*}' "$tmp/$1" | grep -o "\"$2\": \[[^]]*\]" | sed 's/.*\[//; s/\]//; s/,//g'
}
# check "DESCRIPTION" AWK-CONDITION VAR=VALUE...: fails unless the condition holds
check() {
    local what=$1 cond=$2
    shift 2
    local args=() kv
    for kv in "$@"; do args+=(-v "$kv"); done
    awk "${args[@]}" "BEGIN { exit !($cond) }" </dev/null || fail "$what ($*)"
}
csv_rows() { echo $(($(wc -l <"$1") - 1)); }

require_drender
for f in diffuse.gltf texture-true.gltf texture-flat.gltf glossy.gltf texture-true.png texture-flat.png; do
    [ -f "$data/$f" ] || fail "test scene $data/$f not found (python3 tests/data/optimize/make_scenes.py)"
done
have_gnuplot=false
command -v gnuplot >/dev/null 2>&1 && have_gnuplot=true

albedo=/materials/wall/pbrMetallicRoughness/baseColorFactor
albedo_idx=/materials/0/pbrMetallicRoughness/baseColorFactor
strength=/materials/lamp/extensions/KHR_materials_emissive_strength/emissiveStrength
strength_idx=/materials/1/extensions/KHR_materials_emissive_strength/emissiveStrength
rough=/materials/floor/pbrMetallicRoughness/roughnessFactor
rough_idx=/materials/0/pbrMetallicRoughness/roughnessFactor
depth="--max-depth 3"

# ---- targets: the true scenes, 256 spp ----
run render "$data/diffuse.gltf" -o diffuse0.exr --res 24x24 --spp 256 $depth --seed 11
expect_rc 0 "render the diffuse target"
run render "$data/diffuse.gltf" -o diffuse1.exr --res 24x24 --spp 256 $depth --seed 12 --camera 1
expect_rc 0 "render the diffuse target (camera 1)"
run render "$data/texture-true.gltf" -o texture.exr --res 32x32 --spp 256 $depth --seed 13
expect_rc 0 "render the texture target"
run render "$data/glossy.gltf" -o glossy.exr --res 48x48 --spp 256 $depth --seed 14
expect_rc 0 "render the glossy target"

# ---- a. diffuse albedo ----
run optimize "$data/diffuse.gltf" --target diffuse0.exr --param "$albedo" --set "$albedo=0.3,0.3,0.3" \
    --iters 120 --spp 16 $depth --reference "$data/diffuse.gltf" --out-dir a --json
expect_rc 0 "a: optimise the albedo"
summary "a" a.json
e=$(ref_error a.json "$albedo_idx")
[ -n "$e" ] || fail "a: no reference_error for $albedo_idx in the summary: $(cat "$tmp/a.json")"
check "a: albedo not recovered to 0.01 in 120 iterations (max |error|)" 'e < 0.01' e="$e"
[ "$(grep -c '^{"iteration": ' "$tmp/out")" -eq 120 ] || fail "a: expected 120 per-iteration JSON lines"
expect_in err "final loss" "a: human summary on stderr with --json"
# progress files
for f in loss.csv before.png after.png target.png render-0000.png render-0110.png checkpoint.txt; do
    [ -s "a/$f" ] || fail "a: expected a/$f"
done
[ -e a/render-0120.png ] && fail "a: render-0120.png written (iterations are 0..119)"
$have_gnuplot && { [ -s a/loss.png ] || fail "a: expected a/loss.png (gnuplot is installed)"; }
[ "$(head -n 1 a/loss.csv)" = "iteration,loss,seconds,parameter_error" ] || fail "a: loss.csv header: $(head -n 1 a/loss.csv)"
[ "$(csv_rows a/loss.csv)" -eq 120 ] || fail "a: loss.csv should have 120 rows, has $(csv_rows a/loss.csv)"
last=$(tail -n 1 a/loss.csv | cut -d, -f4)
check "a: loss.csv's last parameter_error should be the summary's" 'last - e < 1e-5 && e - last < 1e-5' last="$last" e="$e"
head -n 1 a/checkpoint.txt | grep -qx 'drender-checkpoint 3' || fail "a: checkpoint header"
grep -qx 'iteration 120' a/checkpoint.txt || fail "a: checkpoint should be at iteration 120"
echo "a. albedo recovered: max |error| $e"
# ... also with a primal render per batch (--primal separate; a used the
# default, the cross primal: the gradient's own samples)
run optimize "$data/diffuse.gltf" --target diffuse0.exr --param "$albedo" --set "$albedo=0.3,0.3,0.3" \
    --iters 120 --spp 16 $depth --reference "$data/diffuse.gltf" --out-dir a-separate --primal separate --json
expect_rc 0 "a: optimise the albedo (--primal separate)"
summary "a-separate" a-separate.json
e2=$(ref_error a-separate.json "$albedo_idx")
check "a (--primal separate): albedo not recovered to 0.01 in 120 iterations" 'e < 0.01' e="$e2"
run optimize "$data/diffuse.gltf" --target diffuse0.exr --param "$albedo" --iters 1 --primal nope --out-dir a-bad
expect_rc 2 "optimize --primal nope"
expect_in err "unknown mode 'nope' (available: cross, separate)" "optimize --primal nope"
[ -e a-bad ] && fail "optimize --primal nope: created its output directory"

# --sampling auto decides at every iteration from the values the fit has
# reached: from roughness 0.12 (true 0.3) derivative-roughness sampling, and back to
# detached once the roughness passes 0.2, each change said on stderr and
# every iteration's mode in its --json line; a run resumed before the change
# decides as the uninterrupted one (the same values to the last digit)
auto=("$data/glossy.gltf" --target glossy.exr --param "$rough" --set "$rough=0.12" --spp 2 $depth --threads 2
      --checkpoint-every 1 --json)
run optimize "${auto[@]}" --iters 12 --out-dir auto
expect_rc 0 "optimize a roughness from 0.12"
expect_in err "note: --sampling auto chose derivative-roughness sampling (directions sampled for the roughness derivative; base colours and metallic as detached): $rough is 0.12, below 0.2" "optimize a roughness of 0.12"
expect_in err "--sampling auto goes back to detached sampling" "optimize a roughness from 0.12 to above 0.2"
modes=$(grep -o '^{"iteration": [0-9]*, "loss": [^,]*, "sampling": "[a-z-]*"' "$tmp/out" | sed 's/.*"sampling": "//; s/"//' | uniq | tr '\n' ' ')
[ "$modes" = "derivative-roughness detached " ] ||
    fail "auto: every iteration's sampling: expected derivative-roughness then detached, got '$modes'"
summary "auto" auto.json
# what ran is what was reported: iteration 1's gradient is --sampling derivative-roughness's, to the digit
grad1() { grep -m1 '^{"iteration": 1,' "$tmp/out" | grep -o '"gradient": {[^}]*}'; }
g_auto=$(grad1)
run optimize "${auto[@]}" --iters 1 --out-dir autoD --sampling derivative-roughness
g_der=$(grad1)
run optimize "${auto[@]}" --iters 1 --out-dir autoE --sampling detached
g_det=$(grad1)
[ -n "$g_auto" ] && [ "$g_auto" = "$g_der" ] || fail "auto: iteration 1's gradient is not derivative-roughness sampling's: '$g_auto' vs '$g_der'"
[ "$g_auto" != "$g_det" ] || fail "auto: iteration 1's gradient equals detached sampling's"
grep -q '"sampling": "detached", "sampling_requested": "auto"' "$tmp/auto.json" || fail "auto: summary's sampling"
run optimize "${auto[@]}" --iters 2 --out-dir autoB
expect_rc 0 "optimize a roughness from 0.12, 2 iterations"
run optimize "${auto[@]}" --iters 12 --out-dir autoB --resume
expect_rc 0 "optimize a roughness from 0.12, resumed to 12"
summary "auto (resumed)" autoB.json
A=$(param_values auto.json "$rough_idx") B=$(param_values autoB.json "$rough_idx")
[ -n "$A" ] && [ "$A" = "$B" ] || fail "auto: resumed result differs from the uninterrupted one: '$A' vs '$B'"
run optimize "$data/glossy.gltf" --target glossy.exr --param "$rough" --set "$rough=0.02" --iters 1 --spp 1 \
    $depth --sampling detached --out-dir note --json
expect_rc 0 "optimize a roughness of 0.02, --sampling detached"
grep -q "note:" "$tmp/err" && fail "optimize a roughness of 0.02 with --sampling detached given: a note"
grep -q '"sampling": "detached", "sampling_requested": "detached"' "$tmp/out" || fail "--sampling detached: summary"
# a, two views: camera 0 straight on, camera 1 from the side
run optimize "$data/diffuse.gltf" --target 0=diffuse0.exr --target 1=diffuse1.exr --param "$albedo" \
    --set "$albedo=0.9,0.1,0.5" --iters 100 --spp 8 $depth --reference "$data/diffuse.gltf" --out-dir a2 --json
expect_rc 0 "a: two views"
summary "a (two views)" a2.json
e2=$(ref_error a2.json "$albedo_idx")
check "a: albedo from two views not recovered to 0.01" 'e < 0.01' e="$e2"
echo "a. albedo from two views: max |error| $e2"

# ---- b. texture: flat grey start, true texture in the reference ----
# Relative error of the start: one step with a negligible learning rate.
run optimize "$data/texture-flat.gltf" --target texture.exr --param /images/0 --iters 1 --lr 1e-12 --spp 1 $depth \
    --reference "$data/texture-true.gltf" --out-dir b0 --json
expect_rc 0 "b: starting error"
summary "b (start)" b0.json
e0=$(ref_error b0.json /images/0)
check "b: the flat start should be far from the texture" 'e0 > 0.3' e0="$e0"
run optimize "$data/texture-flat.gltf" --target texture.exr --param /images/0 --iters 100 --spp 8 $depth \
    --reference "$data/texture-true.gltf" --out-dir b --json -o b/result.gltf
expect_rc 0 "b: optimise the texture"
summary "b" b.json
e1=$(ref_error b.json /images/0)
check "b: texture relative error not reduced 10x" 'e1 * 10 <= e0' e1="$e1" e0="$e0"
[ -s b/result.image0.png ] || fail "b: -o b/result.gltf should write the texture as b/result.image0.png"
echo "b. texture relative error $e0 -> $e1"

# ---- c. emission strength and roughness together ----
run optimize "$data/glossy.gltf" --target glossy.exr --param "$strength" --param "$rough" \
    --set "$strength=3" --set "$rough=0.6" --iters 120 --spp 8 $depth \
    --reference "$data/glossy.gltf" --out-dir c --json -o c/result.glb
expect_rc 0 "c: optimise strength and roughness"
summary "c" c.json
es=$(ref_error c.json "$strength_idx")
er=$(ref_error c.json "$rough_idx")
check "c: emission strength not within 5% of 5" 'es < 0.25' es="$es"
check "c: roughness not within 0.05 of 0.3" 'er < 0.05' er="$er"
echo "c. strength |error| $es (of 5), roughness |error| $er"

# ---- d. interrupt and resume ----
# Two threads on purpose: the estimators assign work in a fixed pattern, so a
# resumed run must match to the last digit with any (fixed) thread count.
common=("$data/diffuse.gltf" --target diffuse0.exr --param "$albedo" --set "$albedo=0.3,0.3,0.3" --spp 4 $depth
        --checkpoint-every 1 --threads 2 --json)
run optimize "${common[@]}" --iters 10 --out-dir dA
expect_rc 0 "d: uninterrupted run"
summary "d (uninterrupted)" dA.json
run optimize "${common[@]}" --iters 4 --out-dir dB
expect_rc 0 "d: first 4 iterations"
grep -qx 'iteration 4' dB/checkpoint.txt || fail "d: checkpoint should be at iteration 4"
run optimize "${common[@]}" --iters 10 --out-dir dB --resume
expect_rc 0 "d: --resume to 10"
expect_in err "resuming at iteration 4" "d: --resume"
summary "d (resumed)" dB.json
[ "$(grep -c '^{"iteration": ' "$tmp/out")" -eq 6 ] || fail "d: the resumed run should do iterations 5..10 only"
A=$(param_values dA.json "$albedo_idx") B=$(param_values dB.json "$albedo_idx")
[ -n "$A" ] && [ "$A" = "$B" ] || fail "d: resumed result differs from the uninterrupted one: '$A' vs '$B'"
cut -d, -f1,2 dA/loss.csv >"$tmp/lossA"
cut -d, -f1,2 dB/loss.csv >"$tmp/lossB"
cmp -s "$tmp/lossA" "$tmp/lossB" || fail "d: loss.csv of the resumed run differs: $(diff "$tmp/lossA" "$tmp/lossB" | head -5)"
A=$(grep -v '^adam\|^scene' dA/checkpoint.txt) B=$(grep -v '^adam\|^scene' dB/checkpoint.txt)
[ "$A" = "$B" ] || fail "d: final checkpoints differ"
# resuming a finished run redoes nothing; resuming beyond --iters is refused
run optimize "${common[@]}" --iters 10 --out-dir dB --resume
expect_rc 0 "d: --resume of a finished run"
[ "$(grep -c '^{"iteration": ' "$tmp/out")" -eq 0 ] || fail "d: a finished run should not iterate again"
summary "d (finished)" dF.json
[ "$(param_values dF.json "$albedo_idx")" = "$(param_values dA.json "$albedo_idx")" ] || fail "d: finished run's values changed"
grep -q '"final_loss": \(0\|null\),' "$tmp/dF.json" && fail "d: a resumed finished run reports no final loss"
run optimize "${common[@]}" --iters 6 --out-dir dB --resume
expect_rc 2 "d: --resume with --iters below the checkpoint's iteration"
expect_in err "beyond --iters 6" "d: --resume beyond --iters"
echo "d. resume: $(param_values dB.json "$albedo_idx") (identical)"

# signals: SIGINT, then SIGTERM, while a long run is going
interrupt() {   # interrupt SIGNAL DIR: starts a long run, signals it after 3 iterations
    local sig=$1 dir=$2 n=0
    "$DRENDER" optimize "$data/glossy.gltf" --target glossy.exr --param "$strength" --param "$rough" \
        --set "$strength=3" --set "$rough=0.6" --iters 100000 --spp 8 $depth --checkpoint-every 100000 \
        --out-dir "$dir" >"$tmp/out" 2>"$tmp/err" </dev/null &
    bg_pid=$!
    last_cmd="drender optimize ... --out-dir $dir (background, $sig)"
    while [ "$(cat "$dir/loss.csv" 2>/dev/null | wc -l)" -lt 4 ]; do
        kill -0 "$bg_pid" 2>/dev/null || { wait "$bg_pid"; rc=$?; bg_pid=; fail "d: the run ended before $sig"; }
        n=$((n + 1))
        [ $n -lt 600 ] || { rc=-1; fail "d: no progress in loss.csv after 30 s"; }
        sleep 0.05
    done
    [ ! -e "$dir/checkpoint.txt" ] || fail "d: checkpoint written before $sig (--checkpoint-every 100000)"
    kill -s "$sig" "$bg_pid"
    wait "$bg_pid"
    rc=$?
    bg_pid=
}
interrupt INT dI
expect_rc 130 "d: SIGINT"
expect_in err "interrupted after iteration" "d: SIGINT message"
[ -s dI/checkpoint.txt ] || fail "d: no checkpoint after SIGINT"
head -n 1 dI/checkpoint.txt | grep -qx 'drender-checkpoint 3' || fail "d: checkpoint header after SIGINT"
[ "$(tail -n 1 dI/checkpoint.txt)" = end ] || fail "d: checkpoint after SIGINT does not end with 'end'"
k=$(sed -n 's/^iteration //p' dI/checkpoint.txt)
[ "$k" = "$(csv_rows dI/loss.csv)" ] || fail "d: checkpoint iteration '$k' vs $(csv_rows dI/loss.csv) rows in loss.csv"
ls dI | grep -q '\.tmp' && fail "d: temporary files left in dI: $(ls dI)"
run optimize "$data/glossy.gltf" --target glossy.exr --param "$strength" --param "$rough" \
    --iters $((k + 2)) --spp 8 $depth --out-dir dI --resume --json
expect_rc 0 "d: --resume after SIGINT"
expect_in err "resuming at iteration $k" "d: --resume after SIGINT"
[ "$(csv_rows dI/loss.csv)" -eq $((k + 2)) ] || fail "d: loss.csv after resuming should have $((k + 2)) rows"
interrupt TERM dT
expect_rc 143 "d: SIGTERM"
[ -s dT/checkpoint.txt ] || fail "d: no checkpoint after SIGTERM"
echo "d. SIGINT after iteration $k: exit 130, checkpoint valid, resumed; SIGTERM: exit 143"

# ---- e. output glTF ----
last_cmd=
ensure_gltf_validator
validate_gltf b/result.gltf c/result.glb >"$tmp/validate.log" 2>&1 ||
    { cat "$tmp/validate.log" >&2; fail "e: the glTF validator reports errors in b/result.gltf or c/result.glb"; }
# the written values read back
run params c/result.glb --json
expect_rc 0 "e: params c/result.glb"
for name in "$strength_idx" "$rough_idx"; do
    got=$(grep -o "\"name\": \"$name\", [^]]*\]" "$tmp/out" | sed 's/.*"value": \[//; s/\]//')
    want=$(param_values c.json "$name")
    [ -n "$got" ] && [ -n "$want" ] || fail "e: $name missing in params --json or the summary"
    check "e: $name in c/result.glb differs from the optimiser's final value" \
        'g - w < 1e-6 && w - g < 1e-6' g="$got" w="$want"
done
run params b/result.gltf --json
expect_rc 0 "e: params b/result.gltf"
grep -q '"name": "/images/0", "type": "image"' "$tmp/out" || fail "e: /images/0 missing from params b/result.gltf"
# the result renders, close to the target: the loss of one negligible step from
# result.glb is far below the loss of the wrong start (iteration 0 of run c)
run render c/result.glb -o result.exr --res 48x48 --spp 64 $depth
expect_rc 0 "e: render c/result.glb"
[ -s result.exr ] || fail "e: render c/result.glb wrote nothing"
run optimize c/result.glb --target glossy.exr --param "$rough" --iters 1 --lr 1e-12 --spp 32 $depth --out-dir e --json
expect_rc 0 "e: loss of c/result.glb"
summary "e" e.json
l_res=$(grep -o '"final_loss": [-+0-9.eE]*' "$tmp/e.json" | awk '{print $2}')
l_start=$(sed -n 2p c/loss.csv | cut -d, -f2)
check "e: c/result.glb renders far from the target (loss vs the start's loss)" 'r < s / 5' r="$l_res" s="$l_start"
if $have_oiio; then
    mae=$(oiiotool result.exr glossy.exr --diff 2>&1 | sed -n 's/.*Mean error = //p')
    [ -n "$mae" ] || fail "e: oiiotool --diff gave no mean error"
    check "e: mean absolute difference of c/result.glb's render to the target" 'm < 0.05' m="$mae"
fi
echo "e. results validate; values read back; loss of the result $l_res (start $l_start)"
echo "cli_optimize: all checks passed"
