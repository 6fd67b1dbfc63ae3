#!/usr/bin/env bash
# drender gradient benchmarks (run by `make bench` after bench/run.sh):
#   e. cost: reverse-mode prb gradient time / primal render time (same spp and
#      depth; goal <= 2.5), tape time / prb time, on the bundled Cornell box
#   f. accuracy per cost: gradient standard error x sqrt(gradient seconds), both
#      estimators (lower is better: the cost of a given accuracy)
#   g. memory vs depth: prb peak memory at max depth 4, 64, 1000 (goal: flat
#      within 5%) and tape bytes at those depths
#   h. peer comparison (../shared/bench): red wall set to (0.2, 0.6, 0.3), L2
#      against a render at the true value, 256x256, 64 spp, 2 threads: prb
#      gradient time at max_depth 8 vs the peer's 3.68 s (with the default cross
#      primal and with --primal separate); tape at max_depth 4, 8, 16, 32 vs the
#      peer's conventional AD (prb and tape: medians of 3 runs, each paired with
#      drender's own primal render for a same-run ratio),
#      and its peak memory at max_depth 32 vs the peer's 15.3 GiB
#   i. honest standard error (issue 14): reverse mode with a primal image per
#      batch vs one shared primal (the old estimator), same samples: time ratio
#      (goal <= 1.1), primal share of the run, and both reported standard errors;
#      then the cross primal (default) vs a primal per batch over 8 seeds each:
#      time ratio and efficiency (variance x time); and the cross primal
#      with sobol numbers against independent ones, the same way
#   m. a texture parameter (NormalTangentTest's 2048x2048x3 base colour, 12.6 M
#      scalars): grad's peak memory, gradient time and the gradient image's
#      write, and optimize's per iteration time, peak memory and checkpoint
#      size (5 iterations, a checkpoint at the end)
#   s. forward mode, three parameters in one run against three runs of one
#   t. a light's emission: prb's and the tape's time over the primal's
# Writes $BUILD/bench/grad-results.json.
set -euo pipefail
BUILD=${BUILD:-build}
PEER=${PEER:-../shared/bench/peer-cornell-box.gltf}
NTT=${NTT:-../shared/gltf-samples/NormalTangentTest/glTF/NormalTangentTest.gltf}
OUT=$BUILD/bench
mkdir -p "$OUT"
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
cp "$BUILD/drender" "$BUILD/libdrender-image.so" "$TMP/"
DR=$TMP/drender
# shellcheck source=bench/lib.sh
source bench/lib.sh

CORNELL=scenes/cornell-box.gltf
RED=/materials/red/pbrMetallicRoughness/baseColorFactor
GOLD=/materials/rough-gold/pbrMetallicRoughness/roughnessFactor
RES=128x128 SPP=16 DEPTH=8

# first number of the "stderr" array of the first parameter
first_stderr() { printf '%s\n' "$1" | sed -n 's/.*"stderr": \[\([-+0-9.eE]*\).*/\1/p' | head -n 1; }

echo "drender gradient benchmarks ($(date '+%Y-%m-%d %H:%M'), $(nproc) CPUs, load average $(cut -d' ' -f1 /proc/loadavg))"
echo
# Every render and gradient here draws independent numbers (--sampler
# independent), as the peer does and this bench's history did: render's
# default became sobol in 2026-12, grad's and optimize's later that month.
"$DR" render "$CORNELL" --sampler independent -o "$TMP/target.exr" --res $RES --spp 256 --max-depth $DEPTH --seed 99

echo "e. cost on $CORNELL ($RES, $SPP spp, depth $DEPTH, 2 threads; params: red wall colour, sphere roughness)"
P=$("$DR" render "$CORNELL" --sampler independent -o "$TMP/p.exr" --res $RES --spp $SPP --max-depth $DEPTH --threads 2 --json)
T_PRIMAL=$(json_num "$P" render time)
declare -A T SE MEM TAPE
for est in prb tape; do
    J=$("$DR" grad "$CORNELL" --sampler independent --target "$TMP/target.exr" --param $RED --param $GOLD --set $RED=0.3,0.3,0.3 \
        --estimator $est --spp $SPP --batches 4 --max-depth $DEPTH --threads 2 --json)
    T[$est]=$(json_num "$J" gradient time)
    SE[$est]=$(first_stderr "$J")
    TAPE[$est]=$(json_num "$J" record_bytes)
done
R_PRB=$(calc "${T[prb]} / $T_PRIMAL")
R_TAPE=$(calc "${T[tape]} / ${T[prb]}")
printf '   primal %.3f s, prb gradient %.3f s: ratio %s (goal <= 2.5: %s)\n' "$T_PRIMAL" "${T[prb]}" "$R_PRB" \
    "$(yesno "$R_PRB <= 2.5")"
printf '   tape gradient %.3f s: tape / prb %s; tape held %s MiB\n' "${T[tape]}" "$R_TAPE" \
    "$(calc "${TAPE[tape]:-0} / 1048576" %.1f)"
echo
echo "f. accuracy per cost: stderr(d loss / d red.r) x sqrt(gradient seconds)"
for est in prb tape; do
    printf '   %-5s stderr %s, %.3f s: %s\n' $est "${SE[$est]}" "${T[$est]}" "$(calc "${SE[$est]} * sqrt(${T[$est]})")"
done
echo
echo "g. memory vs max depth ($RES, 4 spp, 1 sample per pixel per tape batch)"
MEM_JSON=""
for d in 4 64 1000; do
    for est in prb tape; do
        J=$("$DR" grad "$CORNELL" --sampler independent --target "$TMP/target.exr" --param $RED --estimator $est --spp 4 --batches 2 \
            --max-depth $d --threads 2 --json)
        MEM[$est$d]=$(json_num "$J" peak_memory_bytes)
        TAPE[$est$d]=$(json_num "$J" record_bytes)
    done
    printf '   depth %4d: prb peak %.1f MiB; tape peak %.1f MiB, of which tape %.1f MiB\n' $d \
        "$(calc "${MEM[prb$d]} / 1048576" %.3f)" "$(calc "${MEM[tape$d]} / 1048576" %.3f)" \
        "$(calc "${TAPE[tape$d]:-0} / 1048576" %.3f)"
    MEM_JSON+="{\"max_depth\": $d, \"prb_peak_bytes\": ${MEM[prb$d]}, \"tape_peak_rss_bytes\": ${MEM[tape$d]}, \"tape_bytes\": ${TAPE[tape$d]:-0}},"
done
SPREAD=$(calc "(${MEM[prb1000]} - ${MEM[prb4]}) / ${MEM[prb4]} * 100" %.2f)
echo "   prb peak memory change from depth 4 to 1000: $SPREAD % (goal: within 5%: $(yesno "$SPREAD <= 5 && $SPREAD >= -5"))"
echo
PEER_JSON=null
if [[ -f $PEER ]]; then
    echo "h. peer comparison ($PEER, 256x256, 64 spp, 2 threads, red wall (0.2, 0.6, 0.3), L2)"
    "$DR" render "$PEER" --sampler independent -o "$TMP/peer-target.exr" --res 256x256 --spp 64 --max-depth 8 --threads 2 --seed 5
    # Single runs move 15-25% on this kind of machine: each gradient figure
    # below is the median of 3 runs, each run paired with a render of
    # drender's own primal at the same depth, whose median gives the same-run
    # ratio (gradient time / own primal time), the figure that drifts least.
    own_primal() {
        json_num "$("$DR" render "$PEER" --sampler independent -o "$TMP/own.exr" --res 256x256 --spp 64 --max-depth "$1" --threads 2 \
            --json)" render time
    }
    GS=() PS=() OWN=()
    for r in 1 2 3; do
        J=$("$DR" grad "$PEER" --sampler independent --target "$TMP/peer-target.exr" --param $RED --set $RED=0.2,0.6,0.3 --spp 64 \
            --batches 2 --max-depth 8 --threads 2 --json)
        GS+=("$(json_num "$J" gradient time)") PS+=("$(json_num "$J" primal time)") OWN+=("$(own_primal 8)")
    done
    T_PEER=$(median "${GS[@]}")
    T_PEER_PRIMAL=$(median "${PS[@]}")
    T_OWN8=$(median "${OWN[@]}")
    R=$(calc "$T_PEER / 3.68")
    # like for like (../shared/bench/README.md): the peer's figure includes its
    # primal render; drender's loss needs its primal images (time.primal)
    T_PEER_BOTH=$(calc "$T_PEER + $T_PEER_PRIMAL")
    R_BOTH=$(calc "$T_PEER_BOTH / 3.68")
    echo "   prb gradient (primal + replay), depth 8: $(calc "$T_PEER" %.2f) s vs the peer's 3.68 s: ratio $R (goal < 1: $(yesno "$R < 1"))"
    echo "   ... with the loss's primal (like for like; the cross primal: the gradient's own samples, time.primal $(calc "$T_PEER_PRIMAL" %.2f) s): $(calc "$T_PEER_BOTH" %.2f) s: ratio $R_BOTH (goal < 1: $(yesno "$R_BOTH < 1"))"
    R_OWN8=$(calc "$T_PEER_BOTH / $T_OWN8")
    echo "   ... medians of 3 runs; drender's own primal in the same runs $(calc "$T_OWN8" %.2f) s: gradient / own primal $R_OWN8 (the peer's: 3.68 / 1.16 = 3.17)"
    J=$("$DR" grad "$PEER" --sampler independent --target "$TMP/peer-target.exr" --param $RED --set $RED=0.2,0.6,0.3 --spp 64 \
        --batches 2 --max-depth 8 --threads 2 --primal separate --json)
    T_SEP=$(calc "$(json_num "$J" gradient time) + $(json_num "$J" primal time)")
    R_SEP=$(calc "$T_SEP / 3.68")
    echo "   ... with --primal separate (a render per batch): $(calc "$T_SEP" %.2f) s: ratio $R_SEP"
    # material fitting: the base colour of every wall, so that most vertices
    # are differentiated (prb's replays shade them eight lanes at a time too)
    WALLS=()
    for m in white green red; do WALLS+=(--param "/materials/$m/pbrMetallicRoughness/baseColorFactor"); done
    GS=()
    for r in 1 2 3; do
        J=$("$DR" grad "$PEER" --sampler independent --target "$TMP/peer-target.exr" "${WALLS[@]}" --spp 64 --batches 2 --max-depth 8 \
            --threads 2 --json)
        GS+=("$(json_num "$J" gradient time)")
    done
    T_WALLS=$(median "${GS[@]}")
    R_WALLS=$(calc "$T_WALLS / $T_OWN8")
    echo "   prb gradient of every wall's base colour (most vertices differentiated), depth 8: $(calc "$T_WALLS" %.2f) s, / own primal $R_WALLS (median of 3; the red wall's alone: $R_OWN8)"
    # tape against the peer's conventional AD at every depth of its table,
    # like for like (its time includes its primal render, ours the loss's primal images)
    declare -A PEER_AD=([4]=2.28 [8]=3.66 [16]=4.26 [32]=5.29)
    TAPE_JSON=""
    for d in 4 8 16 32; do
        GS=() PS=() OWN=()
        for r in 1 2 3; do
            J=$("$DR" grad "$PEER" --sampler independent --target "$TMP/peer-target.exr" --param $RED --set $RED=0.2,0.6,0.3 --spp 64 \
                --batches 2 --max-depth $d --threads 2 --estimator tape --json)
            GS+=("$(json_num "$J" gradient time)") PS+=("$(json_num "$J" primal time)") OWN+=("$(own_primal $d)")
        done
        TG=$(median "${GS[@]}") TP=$(median "${PS[@]}") TO=$(median "${OWN[@]}")
        RT=$(calc "($TG + $TP) / ${PEER_AD[$d]}")
        RO=$(calc "($TG + $TP) / $TO")
        printf '   tape, depth %2d: gradient %.2f s + separate primal %.2f s vs the peer'"'"'s conventional AD %.2f s: ratio %s (goal <= 1: %s); / own primal %.2f s: %s; peak memory %.0f MiB\n' \
            $d "$TG" "$TP" "${PEER_AD[$d]}" "$RT" "$(yesno "$RT <= 1")" "$TO" "$RO" \
            "$(calc "$(json_num "$J" peak_memory_bytes) / 1048576" %.0f)"
        TAPE_JSON+="{\"max_depth\": $d, \"gradient_seconds\": $TG, \"primal_seconds\": $TP, \"ratio_to_peer_ad\": $RT, \"own_primal_seconds\": $TO, \"ratio_to_own_primal\": $RO},"
    done
    echo "   (tape rows: medians of 3 runs, each paired with drender's own primal at that depth; the peer's AD / its primal: 2.71 at depth 4, 3.16 at 8)"
    M32=$(json_num "$J" peak_memory_bytes)
    TB32=$(json_num "$J" record_bytes)
    echo "   tape, depth 32: peak memory $(calc "$M32 / 1048576" %.0f) MiB (tape $(calc "$TB32 / 1048576" %.1f) MiB) vs the peer's 15.3 GiB: $(calc "$M32 / (15.3 * 1073741824) * 100" %.2f) %"
    PEER_JSON="{\"prb_gradient_seconds_depth8\": $T_PEER, \"ratio_to_peer\": $R, \"own_primal_seconds_depth8\": $T_OWN8, \"prb_ratio_to_own_primal\": $R_OWN8, \"primal_seconds_depth8\": $T_PEER_PRIMAL, \"ratio_to_peer_like_for_like\": $R_BOTH, \"separate_primal_seconds_depth8\": $T_SEP, \"separate_ratio_to_peer\": $R_SEP, \"record_bytes_depth32\": $M32, \"tape_bytes_depth32\": $TB32, \"walls_gradient_seconds_depth8\": $T_WALLS, \"walls_ratio_to_own_primal\": $R_WALLS, \"tape_vs_peer_ad\": [${TAPE_JSON%,}]}"
fi
echo "i. reverse-mode standard error with a primal per batch vs one shared primal ($RES, 32 spp, 4 batches)"
cp "$OUT/reverse_stderr" "$TMP/"
SEJ=$("$TMP/reverse_stderr" $CORNELL $RED $RES 32 4 2)
echo "   $SEJ"
echo "   time ratio $(json_num "$SEJ" time_ratio) (goal <= 1.1: $(yesno "$(json_num "$SEJ" time_ratio) <= 1.1"))"
echo "   cross primal (the default: no render) vs a primal per batch, over $(json_num "$SEJ" runs) seeds each: time ratio $(json_num "$SEJ" cross_time_ratio), efficiency (variance x time, per-batch / cross) $(json_num "$SEJ" cross_efficiency)"
echo "   the cross primal with --sampler sobol (halves scrambled apart) vs independent, $(json_num "$SEJ" runs) seeds each: efficiency (variance x time, independent / sobol) $(json_num "$SEJ" sobol_cross_efficiency)"
TEX_JSON=null
if [[ -f $NTT ]]; then
    echo
    echo "m. a texture parameter: $NTT /images/0 (2048x2048x3), 64x64, 16 spp, 2 threads"
    "$DR" render "$NTT" --sampler independent -o "$TMP/ntt.exr" --res 64x64 --spp 64 --threads 2 2>/dev/null
    J=$("$DR" grad "$NTT" --sampler independent --target "$TMP/ntt.exr" --param /images/0 --spp 16 --threads 2 --grad-dir "$TMP" --json 2>/dev/null)
    G_PEAK=$(json_num "$J" peak_memory_bytes) G_T=$(json_num "$J" gradient time) G_W=$(json_num "$J" write time)
    O=$("$DR" optimize "$NTT" --sampler independent --target "$TMP/ntt.exr" --param /images/0 --spp 16 --threads 2 --iters 5 \
        --out-dir "$TMP/ntt-opt" --json 2>/dev/null | tail -n 1)
    O_T=$(json_num "$O" seconds) O_PEAK=$(json_num "$O" peak_memory_bytes)
    CK_BYTES=$(stat -c %s "$TMP/ntt-opt/checkpoint.txt" 2>/dev/null || echo 0)
    printf '   grad: peak %.0f MiB, gradient %.2f s, its image written in %.2f s; optimize: %.2f s per iteration (checkpoint included), peak %.0f MiB, checkpoint %.0f MiB\n' \
        "$(calc "$G_PEAK / 1048576")" "$G_T" "$G_W" "$(calc "$O_T / 5")" "$(calc "$O_PEAK / 1048576")" "$(calc "$CK_BYTES / 1048576")"
    # a fit of 20 iterations with the default checkpoints: its first
    # iteration (fresh pages), the median of the others, and all of it
    W0=$(date +%s.%N)
    "$DR" optimize "$NTT" --sampler independent --target "$TMP/ntt.exr" --param /images/0 --spp 16 --threads 2 --iters 20 \
        --out-dir "$TMP/ntt-opt20" --json 2>/dev/null >"$TMP/ntt-opt20.json"
    O20_WALL=$(calc "$(date +%s.%N) - $W0" %.3f)
    ITER_S=($(grep '^{"iteration"' "$TMP/ntt-opt20.json" | sed 's/.*, "seconds": \([^,]*\),.*/\1/'))
    O20_FIRST=${ITER_S[0]:-0} O20_MED=$(median "${ITER_S[@]:1}")
    printf '   optimize, 20 iterations (checkpoints every 10): the first %.3f s, the others %.4f s each (median), %.2f s in all\n' \
        "$O20_FIRST" "$O20_MED" "$O20_WALL"
    TEX_JSON="{\"grad_peak_bytes\": $G_PEAK, \"grad_seconds\": $G_T, \"grad_write_seconds\": $G_W, \"optimize_seconds_per_iteration\": $(calc "$O_T / 5" %.4f), \"optimize_peak_bytes\": $O_PEAK, \"checkpoint_bytes\": $CK_BYTES, \"optimize20_first_seconds\": $O20_FIRST, \"optimize20_median_seconds\": $O20_MED, \"optimize20_wall_seconds\": $O20_WALL}"
fi
# s. forward mode with several parameters (grad -o): the three wall colours
# of the peer's box in one run, which differentiates up to four parameters in
# one pass over the paths, against the three one at a time (their sum), and
# the scene's primal at the same size (medians of 3)
FWD_JSON=null
if [[ -f $PEER ]]; then
    echo
    echo "s. forward mode, three wall colours of the peer's box (256x256, 16 spp, 2 threads; medians of 3)"
    WALLS=(/materials/0/pbrMetallicRoughness/baseColorFactor /materials/1/pbrMetallicRoughness/baseColorFactor
        /materials/2/pbrMetallicRoughness/baseColorFactor)
    FOPT=(--res 256x256 --spp 16 --threads 2 --json)
    F3=() F1=() FP=()
    for _ in 1 2 3; do
        J=$("$DR" grad "$PEER" --param "${WALLS[0]}" --param "${WALLS[1]}" --param "${WALLS[2]}" -o "$TMP/fw.exr" "${FOPT[@]}" 2>/dev/null)
        F3+=("$(json_num "$J" gradient time)")
        S=0
        for w in "${WALLS[@]}"; do
            J=$("$DR" grad "$PEER" --param "$w" -o "$TMP/fw1.exr" "${FOPT[@]}" 2>/dev/null)
            S=$(calc "$S + $(json_num "$J" gradient time)")
        done
        F1+=("$S")
        J=$("$DR" render "$PEER" -o "$TMP/fp.exr" "${FOPT[@]}" 2>/dev/null)
        FP+=("$(json_num "$J" render time)")
    done
    M3=$(median "${F3[@]}") M1=$(median "${F1[@]}") MP=$(median "${FP[@]}")
    printf '   one run of three: %.3f s; three runs of one: %.3f s (ratio %s); primal %.3f s: the run of three / primal %s\n' \
        "$M3" "$M1" "$(calc "$M3 / $M1")" "$MP" "$(calc "$M3 / $MP")"
    FWD_JSON="{\"three_in_one_seconds\": $M3, \"one_at_a_time_seconds\": $M1, \"primal_seconds\": $MP}"
fi
# t. a light's emission as the parameter (the peer box's light, its
# emissiveFactor set to (0.8, 0.8, 0.4), L2 against the render at the true
# value, 256x256, 64 spp, depth 8, 2 threads): prb's and the tape's gradient
# time over the primal's (medians of 3), and the tape's record. Most
# vertices then have a derivative term (their light sample's).
LIGHT_JSON=null
if [[ -f $PEER ]]; then
    echo
    echo "t. a light's emission, the peer's box (256x256, 64 spp, depth 8, 2 threads; medians of 3)"
    LIGHT=/materials/3/emissiveFactor
    LOPT=(--sampler independent --target "$TMP/peer-target.exr" --param $LIGHT --set $LIGHT=0.8,0.8,0.4 --spp 64
        --res 256x256 --max-depth 8 --threads 2 --json)
    [[ -f $TMP/peer-target.exr ]] ||
        "$DR" render "$PEER" --sampler independent -o "$TMP/peer-target.exr" --res 256x256 --spp 64 --max-depth 8 >/dev/null
    LP=() LPRB=() LTAPE=()
    for _ in 1 2 3; do
        J=$("$DR" render "$PEER" --sampler independent -o "$TMP/lp.exr" --res 256x256 --spp 64 --max-depth 8 --threads 2 --json)
        LP+=("$(json_num "$J" render time)")
        J=$("$DR" grad "$PEER" --estimator prb "${LOPT[@]}" 2>/dev/null)
        LPRB+=("$(json_num "$J" gradient time)")
        J=$("$DR" grad "$PEER" --estimator tape "${LOPT[@]}" 2>/dev/null)
        LTAPE+=("$(json_num "$J" gradient time)")
        LREC=$(json_num "$J" record_bytes)
    done
    MLP=$(median "${LP[@]}") MLPRB=$(median "${LPRB[@]}") MLTAPE=$(median "${LTAPE[@]}")
    printf '   primal %.3f s; prb %.3f s (%s x the primal); tape %.3f s (%s x the primal), its record %s bytes\n' \
        "$MLP" "$MLPRB" "$(calc "$MLPRB / $MLP")" "$MLTAPE" "$(calc "$MLTAPE / $MLP")" "$LREC"
    LIGHT_JSON="{\"primal_seconds\": $MLP, \"prb_seconds\": $MLPRB, \"tape_seconds\": $MLTAPE, \"tape_record_bytes\": $LREC}"
fi
cat >"$OUT/grad-results.json" <<JSON
{"primal_seconds": $T_PRIMAL, "prb_seconds": ${T[prb]}, "tape_seconds": ${T[tape]},
 "prb_over_primal": $R_PRB, "tape_over_prb": $R_TAPE,
 "stderr_sqrt_seconds": {"prb": $(calc "${SE[prb]} * sqrt(${T[prb]})" %.6g), "tape": $(calc "${SE[tape]} * sqrt(${T[tape]})" %.6g)},
 "memory_vs_depth": [${MEM_JSON%,}], "prb_memory_change_percent": $SPREAD,
 "peer": $PEER_JSON, "reverse_stderr": $SEJ, "texture_parameter": $TEX_JSON, "forward_several": $FWD_JSON,
 "light_emission": $LIGHT_JSON}
JSON
echo
echo "results in $OUT/grad-results.json"
