#!/usr/bin/env bash
# drender convergence benchmark (run by `make bench` after bench/sampling.sh;
# also runs alone: BUILD=build bench/convergence.sh):
#   k. pixel RMS error of a primal render against a high-spp reference, over
#      spp 4..256, for --sampler independent, stratified and sobol, and the
#      least-squares slope of log error against log spp (-0.5: plain Monte
#      Carlo; steeper: the sampler's stratification pays). The scene is the
#      bundled Cornell box with its sphere made diffuse (no glossy fireflies),
#      lit by its area light, at 64x64 cropped to rows 10..35 (the walls, the
#      tall box and the sphere's top: the light itself, whose edge pixels
#      would dominate the error, and the checker floor's texture edges are
#      out of the crop); twice: direct light only (max depth 2, a smooth
#      low-dimensional integrand) and full paths (max depth 8).
#      Errors are pooled over SEEDS seeds; the reference (sobol, 4096 spp) is
#      rendered twice with other seeds and its own mean squared error, half
#      the squared difference of the two, is subtracted.
# No timing is measured: the figures are errors, the same on any machine.
# Writes $BUILD/bench/convergence-results.json.
set -euo pipefail
BUILD=${BUILD:-build}
OUT=$BUILD/bench
mkdir -p "$OUT"
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
cp "$BUILD/drender" "$TMP/"
[[ -e $BUILD/libdrender-image.so ]] && cp "$BUILD/libdrender-image.so" "$TMP/"
DR=$TMP/drender
# shellcheck source=bench/lib.sh
source bench/lib.sh

RES=64x64 CROP=0,10,64,26 SEEDS=${SEEDS:-4} REF_SPP=${REF_SPP:-4096}
SPPS=(4 8 16 32 64 128 256)
SAMPLERS=(independent stratified sobol)

# the diffuse Cornell box: the rough-gold sphere's metallic 0, roughness 1
cp scenes/cornell-box.bin scenes/cornell-box-checker.png "$TMP/"
awk '/"name": "rough-gold"/ { gold = 1 }
     gold && /"metallicFactor"/ { sub(/[0-9.]+/, "0.0") }
     gold && /"roughnessFactor"/ { sub(/[0-9.]+/, "1.0"); gold = 0 }
     { print }' scenes/cornell-box.gltf >"$TMP/diffuse.gltf"
grep -A9 '"rough-gold"' "$TMP/diffuse.gltf" | grep -q '"metallicFactor": 0.0' ||
    { echo "convergence.sh: could not make the sphere diffuse" >&2; exit 1; }

# mse A B: the mean squared pixel difference of two images (idiff's RMS error, squared)
mse() {
    local e
    e=$(idiff -a "$1" "$2" 2>&1 | awk '/RMS error/ { print $NF }')
    [[ -n $e ]] || { echo "convergence.sh: idiff failed on $1 $2" >&2; exit 1; }
    calc "$e * $e" %.10g
}

# slope over the arrays X (spp) and Y (errors): least squares in log-log
slope() {
    printf '%s\n' "$@" | awk 'NR % 2 { x = log($1); next } { y = log($1); n++; sx += x; sy += y; sxx += x * x; sxy += x * y }
        END { printf "%.3f", (n * sxy - sx * sy) / (n * sxx - sx * sx) }'
}

JSON=""
echo "k. error vs spp on the diffuse Cornell box ($RES cropped to $CROP, $SEEDS seeds, reference $REF_SPP spp x 2)"
for depth in 2 8; do
    S="$TMP/diffuse.gltf --res $RES --crop $CROP --max-depth $depth --threads 2"
    "$DR" render $S --spp "$REF_SPP" --sampler sobol --seed 1000 -o "$TMP/ref1.exr"
    "$DR" render $S --spp "$REF_SPP" --sampler sobol --seed 1001 -o "$TMP/ref2.exr"
    oiiotool "$TMP/ref1.exr" "$TMP/ref2.exr" --add --mulc 0.5 -o "$TMP/ref.exr" >/dev/null
    # the mean of two references: its MSE is (|r1 - r2|^2 / 2) / 2
    ref_mse=$(calc "$(mse "$TMP/ref1.exr" "$TMP/ref2.exr") / 4" %.10g)
    printf '   max depth %d (reference RMS error %.3g)\n   %-12s' "$depth" "$(calc "sqrt($ref_mse)" %.6g)" spp
    printf ' %9s' "${SPPS[@]}"
    printf ' %8s\n' slope
    for smp in "${SAMPLERS[@]}"; do
        pts=() errs=""
        printf '   %-12s' "$smp"
        for spp in "${SPPS[@]}"; do
            sum=0
            for ((seed = 1; seed <= SEEDS; seed++)); do
                "$DR" render $S --spp "$spp" --sampler "$smp" --seed "$seed" -o "$TMP/x.exr"
                sum=$(calc "$sum + $(mse "$TMP/ref.exr" "$TMP/x.exr")" %.10g)
            done
            e=$(calc "sqrt(($sum / $SEEDS - $ref_mse) > 0 ? $sum / $SEEDS - $ref_mse : 0)" %.6g)
            pts+=("$spp" "$e")
            errs+="${errs:+, }$e"
            printf ' %9.4g' "$e"
        done
        sl=$(slope "${pts[@]}")
        printf ' %8s\n' "$sl"
        JSON+="{\"max_depth\": $depth, \"sampler\": \"$smp\", \"spp\": [$(IFS=,; echo "${SPPS[*]}")], \"rms_error\": [$errs], \"slope\": $sl},"
    done
done
printf '{"bench": "convergence", "scene": "cornell-box, diffuse sphere", "res": "%s", "crop": "%s", "seeds": %d, "reference_spp": %d, "rows": [%s]}\n' \
    "$RES" "$CROP" "$SEEDS" "$REF_SPP" "${JSON%,}" >"$OUT/convergence-results.json"
echo "   written: $OUT/convergence-results.json"
