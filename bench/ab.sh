#!/usr/bin/env bash
# Two drender binaries compared on one scene, their runs interleaved.
#
# On the shared 2-core machines a program's speed drifts by up to 30 % within
# minutes, so two `make bench` runs, or two renders minutes apart, cannot tell
# a 5 % change from the machine. Alternating the two binaries run by run puts
# both in the same minutes; the medians' ratio is then the figure to quote.
#
#   bench/ab.sh OLD NEW [SCENE [ROUNDS [RENDER OPTIONS...]]]
#
# OLD, NEW: drender binaries (each with its libdrender-image.so beside it, as
# `make` leaves them). An older commit's binary, for example:
#   git worktree add /tmp/old REV && make -C /tmp/old build/drender
#   bench/ab.sh /tmp/old/build/drender build/drender
# SCENE defaults to the peer's box, ROUNDS to 5, the options to the bench's
# peer configuration (256x256, 64 spp, depth 8, 2 threads); renders draw
# independent numbers unless the options give --sampler. Prints each run's
# render seconds (`render --json`, time.render), the medians and the minima
# with NEW / OLD for each, and whether the two binaries' last images are
# identical (idiff).
#
#   bench/ab.sh OLD NEW SCENE ROUNDS grad GRAD OPTIONS...
#
# compares gradients instead: `drender grad SCENE GRAD OPTIONS --json`
# (reverse mode: --target, --param ...), each run's time.primal +
# time.gradient, and whether the two binaries' last gradients and standard
# errors are identical to the last digit.
set -euo pipefail
cd "$(dirname "$0")/.."
# shellcheck source=bench/lib.sh
source bench/lib.sh

if [[ $# -lt 2 || $1 == -h || $1 == --help ]]; then
    sed -n '2,27p' "$0" | sed 's/^# \{0,1\}//'
    exit 2
fi
OLD=$1 NEW=$2
SCENE=${3:-../shared/bench/peer-cornell-box.gltf}
ROUNDS=${4:-5}
shift $(($# < 4 ? $# : 4))
OPTS=("$@")
CMD=render
if [[ ${#OPTS[@]} -gt 0 && ${OPTS[0]} == grad ]]; then
    CMD=grad
    OPTS=("${OPTS[@]:1}")
fi
[[ ${#OPTS[@]} -gt 0 ]] || OPTS=(--res 256x256 --spp 64 --max-depth 8 --threads 2)
for b in "$OLD" "$NEW"; do
    [[ -x $b ]] || { echo "ab.sh: $b is not an executable" >&2; exit 1; }
done
[[ -f $SCENE ]] || { echo "ab.sh: no scene $SCENE" >&2; exit 1; }
[[ $ROUNDS =~ ^[1-9][0-9]*$ ]] || { echo "ab.sh: ROUNDS must be a positive integer, not '$ROUNDS'" >&2; exit 1; }
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT

# run BIN TAG: one render (or gradient); prints its seconds
run() {
    local json out=(-o "$TMP/$2.exr")
    # (a gradient's texture images into the run's own directory, not the
    # current one)
    [[ $CMD == render ]] || { mkdir -p "$TMP/$2" && out=(--grad-dir "$TMP/$2"); }
    # (render with independent numbers unless OPTS say otherwise: binaries from
    # before 2026-12 default to them, later ones to sobol)
    local smp=()
    [[ $CMD == render ]] && smp=(--sampler independent)
    if ! json=$("$1" "$CMD" "$SCENE" "${out[@]}" --json "${smp[@]}" "${OPTS[@]}" 2>"$TMP/stderr"); then
        echo "ab.sh: '$1 $CMD $SCENE ${OPTS[*]}' failed:" >&2
        cat "$TMP/stderr" >&2
        exit 1
    fi
    if [[ $CMD == render ]]; then
        calc "$(json_num "$json" render time)" %.4f
    else   # the gradients and their standard errors, for the comparison at the end
        # (an image parameter's gradient file is named by its run's
        # directory: the name left out, the images compared at the end)
        printf '%s\n' "$json" | sed -n 's/.*"parameters": *//p' | sed "s|$TMP/$2/||g" >"$TMP/$2.grad"
        calc "$(json_num "$json" primal time) + $(json_num "$json" gradient time)" %.4f
    fi
}

A=() B=()
echo "$SCENE ${OPTS[*]}: $ROUNDS round(s), alternating"
for ((r = 1; r <= ROUNDS; r++)); do
    A+=("$(run "$OLD" old)")
    B+=("$(run "$NEW" new)")
    echo "  round $r: old ${A[-1]} s, new ${B[-1]} s"
done
MA=$(median "${A[@]}") MB=$(median "${B[@]}")
echo "median: old $MA s, new $MB s; new / old $(calc "$MB / $MA" %.3f)"
# the least disturbed run of each: with many rounds on a noisy machine the
# minima's ratio is steadier than the medians' (session 13's note)
LA=$(printf '%s\n' "${A[@]}" | sort -g | head -n 1) LB=$(printf '%s\n' "${B[@]}" | sort -g | head -n 1)
echo "minimum: old $LA s, new $LB s; new / old $(calc "$LB / $LA" %.3f)"
if [[ $CMD == grad ]]; then
    same_images=true
    for f in "$TMP"/old/*.exr; do
        [[ -e $f ]] || continue
        command -v idiff >/dev/null && idiff -fail 0 -warn 0 "$f" "$TMP/new/${f##*/}" >/dev/null 2>&1 || same_images=false
    done
    if cmp -s "$TMP/old.grad" "$TMP/new.grad" && $same_images; then
        echo "gradients: identical (and the gradient images, idiff -fail 0)"
    else
        echo "gradients: differ"
        echo "  old: $(cat "$TMP/old.grad")"
        echo "  new: $(cat "$TMP/new.grad")"
    fi
elif command -v idiff >/dev/null; then
    if idiff -fail 0 -warn 0 "$TMP/old.exr" "$TMP/new.exr" >/dev/null 2>&1; then
        echo "images: identical"
    else
        echo "images: differ (idiff -fail 0)"
    fi
fi
