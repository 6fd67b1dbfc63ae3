#!/usr/bin/env bash
# drender participating-media benchmarks (run by `make bench` after grad.sh),
# on the smoke cube tests/data/media/smoke.gltf (16^3 density grid):
#   i. a volume gradient (density_scale and every voxel; L2 against a render at
#      the true values, starting from density_scale 0.5), prb vs tape and DRT
#      vs baseline: time, stderr of d loss / d density_scale, stderr^2 x seconds
#      (lower is better: the cost of a given accuracy), peak memory, tape bytes
#      (DRT takes a grid's density-scale gain at the path's collisions and
#      its voxels' from gain paths, medium_grad.c)
#  ii. prb peak memory at max depth 4, 64, 1000 (goal: flat within 5%)
# iii. render time of the smoke cube (rays per second)
#  iv. a dense, almost white medium at depth 1000: gradient / primal time
#      (DRT takes a thick homogeneous medium's gain at the path's collisions,
#      medium_grad.c; gain paths, where taken, are spread so that the cost
#      stays linear in depth)
#   v. the pilot's choice on two thin homogeneous fogs (medium_grad.c):
#      fog-khr (a fog seen once: DRT takes gain paths) and fog-global's
#      global fog (crossed on every bounce: the collisions); reverse-mode
#      stderr^2 x seconds of d loss / d extinction (red) with DRT over the
#      baseline's, which takes the collisions in homogeneous media (below 1:
#      DRT's choice is the better one; 1: the same estimator)
#  vi. a medium in part of a scene: the peer's Cornell box with a small
#      cube of smoke (the smoke cube's grid) or of homogeneous fog
#      (bench/make_box_medium.py), rendered as the box alone is: the time per
#      ray over the box's (the median of three triples run back to back; the
#      packet tracer keeps the paths that enter no medium, wave_soa.c); and
#      the grid's density and the fog's extinction gradients over the same
#      scene's primal render
# Writes $BUILD/bench/media-results.json.
set -euo pipefail
BUILD=${BUILD:-build}
OUT=$BUILD/bench
mkdir -p "$OUT"
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
DR=$BUILD/drender
# shellcheck source=bench/lib.sh
source bench/lib.sh

SMOKE=tests/data/media/smoke.gltf
SCALE=/materials/smoke/extensions/DR_medium/density_scale
GRID=/materials/smoke/extensions/DR_medium/density
RES=64x64 SPP=8 DEPTH=8
first_stderr() { printf '%s\n' "$1" | sed -n 's/.*"stderr": \[\([-+0-9.eE]*\).*/\1/p' | head -n 1; }

echo "drender media benchmarks ($(date '+%Y-%m-%d %H:%M'), $(nproc) CPUs, load average $(cut -d' ' -f1 /proc/loadavg))"
echo
"$DR" render "$SMOKE" --sampler independent -o "$TMP/target.exr" --res $RES --spp 256 --max-depth $DEPTH --seed 99
echo "i. volume gradient on $SMOKE ($RES, $SPP spp x 4 batches, depth $DEPTH, 2 threads; density_scale + 4096 voxels)"
ROWS=""
for est in prb tape; do
    for mg in drt baseline; do
        J=$("$DR" grad "$SMOKE" --sampler independent --grad-dir "$TMP" --target "$TMP/target.exr" --param $SCALE --param $GRID --set $SCALE=0.5 \
            --estimator $est --medium-grad $mg --spp $SPP --batches 4 --max-depth $DEPTH --threads 2 --json)
        T=$(json_num "$J" gradient time)
        SE=$(first_stderr "$J")
        M=$(json_num "$J" peak_memory_bytes)
        TB=$(json_num "$J" record_bytes)
        printf '   %-4s %-8s %.3f s  stderr %s  stderr^2 x s %s  peak %.1f MiB  tape %.1f MiB\n' $est $mg "$T" "$SE" \
            "$(calc "$SE * $SE * $T")" "$(calc "$M / 1048576" %.3f)" "$(calc "${TB:-0} / 1048576" %.3f)"
        ROWS+="{\"estimator\": \"$est\", \"medium_grad\": \"$mg\", \"seconds\": $T, \"stderr\": $SE, \"peak_memory_bytes\": $M, \"record_bytes\": ${TB:-0}},"
    done
done
echo
echo "ii. prb memory vs max depth (smoke cube, $RES, 4 spp)"
declare -A MEM
MEM_JSON=""
for d in 4 64 1000; do
    J=$("$DR" grad "$SMOKE" --sampler independent --grad-dir "$TMP" --target "$TMP/target.exr" --param $SCALE --param $GRID --spp 4 --batches 2 \
        --max-depth $d --threads 2 --json)
    MEM[$d]=$(json_num "$J" peak_memory_bytes)
    printf '   depth %4d: prb peak %.3f MiB\n' $d "$(calc "${MEM[$d]} / 1048576" %.3f)"
    MEM_JSON+="{\"max_depth\": $d, \"prb_peak_bytes\": ${MEM[$d]}},"
done
SPREAD=$(calc "(${MEM[1000]} - ${MEM[4]}) / ${MEM[4]} * 100" %.2f)
echo "   change from depth 4 to 1000: $SPREAD % (goal: within 5%: $(yesno "$SPREAD <= 5 && $SPREAD >= -5"))"
echo
J=$("$DR" render "$SMOKE" --sampler independent -o "$TMP/r.exr" --res 256x256 --spp 16 --threads 2 --json)
RT=$(json_num "$J" render time)
RPS=$(json_num "$J" per_second rays)
echo "iii. render $SMOKE 256x256 16 spp: $(calc "$RT" %.3f) s, $(calc "$RPS / 1e6" %.2f) M rays/s"
DENSE=tests/data/media/fog-dense.gltf
J=$("$DR" render "$DENSE" --sampler independent -o "$TMP/d.exr" --res 32x32 --spp 4 --max-depth 1000 --threads 2 --json)
TP=$(json_num "$J" render time)
J=$("$DR" grad "$DENSE" --sampler independent --param /materials/0/extensions/DR_medium/extinction -o "$TMP/dd.exr" --res 32x32 --spp 4 \
    --max-depth 1000 --threads 2 --json)
TG=$(json_num "$J" gradient time)
echo " iv. dense medium (extinction 1e4/1e3/1e2, albedo 0.999, depth 1000, 32x32, 4 spp): primal $(calc "$TP" %.3f) s," \
    "prb DRT gradient $(calc "$TG" %.3f) s: ratio $(calc "$TG / $TP")"
echo "  v. the pilot on thin fogs (reverse mode, 64x64, 256 spp in 32 batches, d loss / d extinction r): stderr^2 x s, DRT / baseline"
PILOT_JSON=""
for scene in fog-khr:/materials/0/extensions/DR_medium/extinction fog-global:/extensions/DR_medium/extinction; do
    name=${scene%%:*} param=${scene#*:}
    f=tests/data/media/$name.gltf
    "$DR" render "$f" --sampler independent -o "$TMP/t-$name.exr" --res 64x64 --spp 64 --seed 7 >/dev/null
    declare -A COST=()
    for mg in drt baseline; do
        J=$("$DR" grad "$f" --sampler independent --target "$TMP/t-$name.exr" --param "$param" --set "$param=0.5,0.5,0.5" \
            --medium-grad $mg --spp 256 --batches 32 --threads 2 --json)
        SE=$(first_stderr "$J")
        COST[$mg]=$(calc "$SE * $SE * $(json_num "$J" gradient time)")
        [[ $mg == drt ]] && SRC=$(printf '%s\n' "$J" | sed -n 's/.*"medium_gain": \[{[^]]*"source": "\([a-z_]*\)".*/\1/p')
    done
    printf '     %-10s DRT takes %-10s  %s / %s = %s\n' "$name" "$SRC" "${COST[drt]}" "${COST[baseline]}" \
        "$(calc "${COST[drt]} / ${COST[baseline]}")"
    PILOT_JSON+="{\"scene\": \"$name\", \"drt_source\": \"$SRC\", \"drt_cost\": ${COST[drt]}, \"baseline_cost\": ${COST[baseline]}},"
done
PEER=${PEER:-../shared/bench/peer-cornell-box.gltf}
PART_JSON=""
if [[ -f $PEER ]]; then
    echo " vi. a medium in part of the peer's box (256x256, 16 spp, depth 8, 2 threads): time per ray over the box's"
    cp tests/data/media/smoke.raw "$TMP/"
    python3 bench/make_box_medium.py "$PEER" "$TMP/box-grid.gltf" grid smoke.raw
    python3 bench/make_box_medium.py "$PEER" "$TMP/box-fog.gltf" fog
    declare -A PER_RAY=()
    per_ray() {   # seconds per ray of one render of scene $1
        local j
        j=$("$DR" render "$1" --sampler independent -o "$TMP/part.exr" --res 256x256 --spp 16 --threads 2 --json)
        calc "$(json_num "$j" render time) / $(json_num "$j" total rays)" %.6e
    }
    for _ in 1 2 3; do
        for sc in box grid fog; do
            f=$PEER
            [[ $sc != box ]] && f=$TMP/box-$sc.gltf
            PER_RAY[$sc]+="$(per_ray "$f") "
        done
    done
    median3() { tr ' ' '\n' <<<"$1" | sed '/^$/d' | sort -g | sed -n 2p; }
    B=$(median3 "${PER_RAY[box]}")
    for sc in grid fog; do
        M=$(median3 "${PER_RAY[$sc]}")
        printf '     %-5s %s s per ray against the box'"'"'s %s: %s\n' $sc "$M" "$B" "$(calc "$M / $B")"
        PART_JSON+="{\"medium\": \"$sc\", \"seconds_per_ray\": $M, \"box_seconds_per_ray\": $B, \"per_ray_over_box\": $(calc "$M / $B")},"
    done
    # ... and the media's gradients (prb, the cross primal) over the same
    # scene's primal render (128x128, 32 spp; medians of three pairs): the
    # paths that meet no medium walk in the arrays and, without a term, are
    # not replayed (prb.c's arrays_pixels)
    echo "     gradients (128x128, 32 spp, 2 threads; medians of 3): time over the scene's own primal render"
    for sc in grid fog; do
        param=/materials/4/extensions/DR_medium/extinction
        [[ $sc == grid ]] && param=/materials/4/extensions/DR_medium/density
        "$DR" render "$TMP/box-$sc.gltf" --sampler independent -o "$TMP/target-$sc.exr" --res 128x128 --spp 64 --threads 2
        GT=() PT=()
        for _ in 1 2 3; do
            J=$("$DR" grad "$TMP/box-$sc.gltf" --sampler independent --target "$TMP/target-$sc.exr" --param $param \
                --grad-dir "$TMP" --res 128x128 --spp 32 --threads 2 --json)
            GT+=("$(json_num "$J" gradient time)")
            J=$("$DR" render "$TMP/box-$sc.gltf" --sampler independent -o "$TMP/p.exr" --res 128x128 --spp 32 --threads 2 --json)
            PT+=("$(json_num "$J" render time)")
        done
        G=$(median "${GT[@]}") P=$(median "${PT[@]}")
        printf '     %-5s %s: gradient %.3f s, primal %.3f s: %s\n' $sc "${param##*/}" "$G" "$P" "$(calc "$G / $P")"
        PART_JSON+="{\"medium\": \"$sc\", \"gradient_param\": \"$param\", \"gradient_seconds\": $G, \"primal_seconds\": $P, \"gradient_over_primal\": $(calc "$G / $P")},"
    done
fi
cat >"$OUT/media-results.json" <<JSON
{"volume_gradient": [${ROWS%,}], "prb_memory_vs_depth": [${MEM_JSON%,}], "prb_memory_change_percent": $SPREAD,
 "render_seconds": $RT, "dense_primal_seconds": $TP, "dense_gradient_seconds": $TG, "pilot": [${PILOT_JSON%,}],
 "medium_in_part_of_box": [${PART_JSON%,}]}
JSON
echo
echo "results in $OUT/media-results.json"
