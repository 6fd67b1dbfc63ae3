#!/usr/bin/env bash
# drender sampling benchmark (run by `make bench` after bench/grad.sh):
#   i. detached vs attached vs mis vs derivative (and derivative-roughness) sampling, and auto (the
#      default: what it ran is the "ran" column): standard error^2 x gradient seconds of
#      d loss / d theta (lower is better: the cost of a given accuracy) for
#      both estimators on the bundled Cornell box, L2 against a 256-spp render:
#      red wall colour (albedo), the gold sphere's roughness at 0.001, 0.1 and
#      0.5 (and 0.1 beside the albedo) and its metallic, and the floor's texture (the
#      norm's error bar).
#      Where an estimator does not implement a mode, the row says so; where no
#      parameter enters a sampling map, attached runs as detached (the JSON's
#      sampling_effective) and the figures only differ by timing noise.
#   j. prb attached: peak memory at max depth 4, 64, 1000 (goal: flat within 5%).
# Writes $BUILD/bench/sampling-results.json.
set -euo pipefail
BUILD=${BUILD:-build}
OUT=$BUILD/bench
mkdir -p "$OUT"
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
cp "$BUILD/drender" "$BUILD/libdrender-image.so" "$TMP/"   # (drender loads its image library from beside itself)
DR=$TMP/drender
# shellcheck source=bench/lib.sh
source bench/lib.sh

CORNELL=scenes/cornell-box.gltf
RES=64x64 SPP=32 BATCHES=8 DEPTH=6
RED=/materials/red/pbrMetallicRoughness/baseColorFactor
GOLD_R=/materials/rough-gold/pbrMetallicRoughness/roughnessFactor
GOLD_M=/materials/rough-gold/pbrMetallicRoughness/metallicFactor
TEX=/images/0

# the first parameter's first "stderr" number, or an image's "stderr_norm"
first_stderr() {
    python3 -c 'import json, sys
p = json.loads(sys.argv[1])["parameters"][0]
print(p["stderr"][0] if "stderr" in p else p["stderr_norm"])' "$1"
}

echo "i. detached vs attached vs mis vs derivative and derivative-roughness sampling, and auto (the default), on $CORNELL ($RES, $SPP spp in $BATCHES batches, depth $DEPTH, 2 threads)"
"$DR" render "$CORNELL" --sampler independent -o "$TMP/target.exr" --res $RES --spp 256 --max-depth $DEPTH --seed 99 --threads 2
printf '   %-22s %-5s %-20s %-20s %12s %9s %12s\n' parameter est sampling ran stderr seconds "stderr^2*s"
ROWS=""
row() {   # label param set-args...
    local label=$1 param=$2
    shift 2
    for est in prb tape; do
        for smp in detached attached mis derivative derivative-roughness auto; do
            local J rc=0
            J=$("$DR" grad "$CORNELL" --sampler independent --grad-dir "$TMP" --target "$TMP/target.exr" --param "$param" "$@" --estimator $est \
                --sampling $smp --spp $SPP --batches $BATCHES --max-depth $DEPTH --threads 2 --seed 3 --json \
                2>"$TMP/err") || rc=$?
            if [[ $rc -eq 2 ]]; then
                printf '   %-22s %-5s %-20s %s\n' "$label" $est $smp "not implemented"
                ROWS+="{\"parameter\": \"$label\", \"estimator\": \"$est\", \"sampling\": \"$smp\", \"implemented\": false},"
                continue
            fi
            [[ $rc -eq 0 ]] || { cat "$TMP/err" >&2; exit 1; }
            local se t ran cost
            se=$(first_stderr "$J")
            t=$(json_num "$J" gradient time)
            ran=$(printf '%s\n' "$J" | sed -n 's/.*"sampling_effective": *"\([a-z-]*\)".*/\1/p')
            cost=$(calc "$se * $se * $t" %.3g)
            printf '   %-22s %-5s %-20s %-20s %12.4g %9.3f %12s\n' "$label" $est $smp "$ran" "$se" "$t" "$cost"
            ROWS+="{\"parameter\": \"$label\", \"estimator\": \"$est\", \"sampling\": \"$smp\", \"implemented\": true, \"ran\": \"$ran\", \"stderr\": $se, \"seconds\": $t, \"stderr2_seconds\": $cost},"
        done
    done
}
row "albedo (red wall r)" $RED
row "roughness 0.001" $GOLD_R --set $GOLD_R=0.001
row "roughness 0.1" $GOLD_R --set $GOLD_R=0.1
row "roughness 0.5" $GOLD_R --set $GOLD_R=0.5
# the roughness's standard error beside a differentiated colour (the colour
# is the second parameter): derivative draws directions for both,
# derivative-roughness (auto's choice) for the roughness alone
row "roughness 0.1 + albedo" $GOLD_R --param $RED --set $GOLD_R=0.1
row "metallic (gold)" $GOLD_M --set $GOLD_M=0.7
row "texture (floor)" $TEX
echo
echo "j. prb --sampling attached: peak memory vs max depth (gold roughness, $RES, 4 spp; goal: flat within 5%)"
MEM_JSON=""
declare -A MEM
for d in 4 64 1000; do
    J=$("$DR" grad "$CORNELL" --sampler independent --target "$TMP/target.exr" --param $GOLD_R --estimator prb --sampling attached \
        --spp 4 --batches 2 --max-depth $d --threads 2 --json)
    MEM[$d]=$(json_num "$J" peak_memory_bytes)
    printf '   depth %4d: peak %.2f MiB, gradient %.3f s\n' $d "$(calc "${MEM[$d]} / 1048576" %.4f)" \
        "$(json_num "$J" gradient time)"
    MEM_JSON+="{\"max_depth\": $d, \"peak_bytes\": ${MEM[$d]}},"
done
SPREAD=$(calc "(${MEM[1000]} - ${MEM[4]}) / ${MEM[4]} * 100" %.2f)
echo "   change from depth 4 to 1000: $SPREAD % (within 5%: $(yesno "$SPREAD <= 5 && $SPREAD >= -5"))"
printf '{"scene": "%s", "res": "%s", "spp": %d, "batches": %d, "max_depth": %d, "rows": [%s],\n "prb_attached_memory_vs_depth": [%s], "prb_attached_memory_change_percent": %s}\n' \
    "$CORNELL" $RES $SPP $BATCHES $DEPTH "${ROWS%,}" "${MEM_JSON%,}" "$SPREAD" >"$OUT/sampling-results.json"
echo
echo "results in $OUT/sampling-results.json"
