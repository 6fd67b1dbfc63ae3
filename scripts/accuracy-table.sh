#!/usr/bin/env bash
# The accuracy table of issue 12: `drender compare` on the bundled Cornell box
# for five gradients, with every estimator and every sampling mode the
# registry offers (compare's defaults: nothing is listed here, so a mode added
# to the registry appears by itself) and the samplers independent,
# stratified and sobol; one markdown table per case.
#
#   scripts/accuracy-table.sh [OUT]          (default OUT: out/accuracy)
#
# Cases: the red wall's albedo; the gold sphere's roughness set to 0.001, 0.1
# and 0.5; its metallic (set to 0.7, inside [0, 1], as bench/sampling.sh).
# Forward mode (d image / d parameter, all components at once): the error and
# variance are over the derivative image's pixels, against a high-spp
# reference of the first estimator, sampling mode and sampler.
# Efficiency = 1 / (relative variance x seconds per estimate); "x independent"
# is it divided by the same estimator and mode's with the first sampler.
# Seconds are wall time on whatever machine runs it (shared machines: noisy).
# Settings (environment): RES (64x64), SPP (16), BATCHES (4), REF_SPP (512),
# DEPTH (6), THREADS (2), SAMPLERS (independent,stratified,sobol).
# OUT/<case>/ holds each comparison; OUT/tables.md the tables (also printed).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${BUILD:-build}
DR=${DRENDER:-$BUILD/drender}
OUT=${1:-out/accuracy}
RES=${RES:-64x64} SPP=${SPP:-16} BATCHES=${BATCHES:-4} REF_SPP=${REF_SPP:-512} DEPTH=${DEPTH:-6}
THREADS=${THREADS:-2} SAMPLERS=${SAMPLERS:-independent,stratified,sobol}
mkdir -p "$OUT"

red=/materials/red/pbrMetallicRoughness/baseColorFactor
rough=/materials/rough-gold/pbrMetallicRoughness/roughnessFactor
metal=/materials/rough-gold/pbrMetallicRoughness/metallicFactor
CASES=(
    "albedo|red wall albedo|--param $red"
    "roughness-0.001|gold roughness 0.001|--param $rough --set $rough=0.001"
    "roughness-0.1|gold roughness 0.1|--param $rough --set $rough=0.1"
    "roughness-0.5|gold roughness 0.5|--param $rough --set $rough=0.5"
    "metallic|gold metallic (at 0.7)|--param $metal --set $metal=0.7"
)

: >"$OUT/tables.md"
for entry in "${CASES[@]}"; do
    IFS='|' read -r name title args <<<"$entry"
    echo "== $title" >&2
    # shellcheck disable=SC2086  # args is a word list
    "$DR" compare scenes/cornell-box.gltf $args --res "$RES" --spp "$SPP" --batches "$BATCHES" \
        --reference "spp:$REF_SPP" --max-depth "$DEPTH" --threads "$THREADS" --sampler "$SAMPLERS" \
        -o "$OUT/$name" >/dev/null
    python3 - "$OUT/$name/results.json" "$title" >>"$OUT/tables.md" <<'PY'
import json, math, sys
d = json.load(open(sys.argv[1]))
ref, first = d["reference"], d["samplers"][0]
num = lambda v, f: "n/a" if v is None or not math.isfinite(v) else format(v, f)
print(f"### {sys.argv[2]}\n")
print(f"{d['width']}x{d['height']}, {d['combinations'][0]['spp']} spp x {d['batches']} batches, max depth "
      f"{ref['max_depth']}; reference {ref['kind']} ({ref['estimator']} {ref['sampling']} {first}, its own "
      f"relative error {num(ref['rel_se'], '.3g')})\n")
print(f"| estimator | sampling | sampler | efficiency | x {first} | rel. error | seconds |")
print("|---|---|---|---:|---:|---:|---:|")
combos = d["combinations"]
for c in combos:
    base = next(b for b in combos if b["estimator"] == c["estimator"] and b["sampling"] == c["sampling"]
                and b["sampler"] == first)
    eff, beff = c["parameters"][0]["efficiency"], base["parameters"][0]["efficiency"]
    ratio = eff / beff if eff and beff else None
    print(f"| {c['estimator']} | {c['sampling']} | {c['sampler']} | {num(eff, '.4g')} | {num(ratio, '.2f')} | "
          f"{num(c['parameters'][0]['rel_error'], '.3g')} | {num(c['seconds_median'], '.3g')} |")
print()
PY
done
cat "$OUT/tables.md"
