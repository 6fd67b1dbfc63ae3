#!/usr/bin/env bash
# The accuracy table of issue 12: `drender compare` on the bundled Cornell box
# for five gradients, with every estimator and every sampling mode the
# registry offers (compare's defaults: nothing is listed here, so a mode added
# to the registry appears by itself) and the samplers independent,
# stratified and sobol; one markdown table per case.
#
#   scripts/accuracy-table.sh [OUT]          (default OUT: out/accuracy)
#
# Reverse mode, as an optimisation sees it: d loss / d parameter, L2 against a
# render of the box at its true values (OUT/target.exr), from wrong values:
# the red wall's albedo set to 0.4,0.3,0.3; the gold sphere's roughness set to
# 0.001, 0.1 and 0.5 (true: 0.35); its metallic set to 0.7 (true: 1, inside
# [0, 1] as bench/sampling.sh). The reference is finite differences with
# common random numbers (--reference fd: no estimator's own weakness, such as
# detached sampling's variance at roughness 0.001, leaks into it), with a step
# of a tenth of the value or less.
# Within a case every efficiency is over the same |reference|^2, so their
# ratios do not depend on the reference; "rel. error" does, and is not
# resolved where the reference's own relative error (printed) is near 1
# (roughness 0.001: the mirror's gradient is nearly 0).
# Efficiency = 1 / (relative variance x seconds per estimate); "x independent"
# is it divided by the same estimator and mode's with the first sampler.
# Seconds are wall time on whatever machine runs it (shared machines: noisy).
# Settings (environment): RES (32x32), SPP (16), BATCHES (64), REF_SPP (16 per batch),
# DEPTH (6), THREADS (2), SAMPLERS (independent,stratified,sobol).
# Many small batches rather than a few large images: a gradient is one number
# per batch, and its variance (hence the efficiency) is estimated from the
# batches; these estimators are heavy-tailed, and with 16 batches of 64x64 the
# sampler ratios swung by 2x and more between runs. 64 batches of 32x32 cost
# the same (about 7 minutes on 2 shared cores).
# OUT/<case>/ holds each comparison; OUT/tables.md the tables (also printed).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${BUILD:-build}
DR=${DRENDER:-$BUILD/drender}
OUT=${1:-out/accuracy}
RES=${RES:-32x32} SPP=${SPP:-16} BATCHES=${BATCHES:-64} REF_SPP=${REF_SPP:-16} DEPTH=${DEPTH:-6}
THREADS=${THREADS:-2} SAMPLERS=${SAMPLERS:-independent,stratified,sobol}
mkdir -p "$OUT"

red=/materials/red/pbrMetallicRoughness/baseColorFactor
rough=/materials/rough-gold/pbrMetallicRoughness/roughnessFactor
metal=/materials/rough-gold/pbrMetallicRoughness/metallicFactor
CASES=(   # name|title|finite-difference step|arguments
    "albedo|red wall albedo (at 0.4,0.3,0.3)|1e-2|--param $red --set $red=0.4,0.3,0.3"
    "roughness-0.001|gold roughness 0.001|1e-4|--param $rough --set $rough=0.001"
    "roughness-0.1|gold roughness 0.1|1e-2|--param $rough --set $rough=0.1"
    "roughness-0.5|gold roughness 0.5|2e-2|--param $rough --set $rough=0.5"
    "metallic|gold metallic (at 0.7)|2e-2|--param $metal --set $metal=0.7"
)

"$DR" render scenes/cornell-box.gltf --res "$RES" --spp 256 --max-depth "$DEPTH" --threads "$THREADS" --seed 99 \
    -o "$OUT/target.exr"
: >"$OUT/tables.md"
for entry in "${CASES[@]}"; do
    IFS='|' read -r name title eps args <<<"$entry"
    echo "== $title" >&2
    # shellcheck disable=SC2086  # args is a word list
    "$DR" compare scenes/cornell-box.gltf $args --target "$OUT/target.exr" --res "$RES" --spp "$SPP" --batches "$BATCHES" \
        --reference "fd:$REF_SPP" --eps "$eps" --max-depth "$DEPTH" --threads "$THREADS" --sampler "$SAMPLERS" \
        -o "$OUT/$name" >/dev/null
    python3 - "$OUT/$name/results.json" "$title" >>"$OUT/tables.md" <<'PY'
import json, math, sys
d = json.load(open(sys.argv[1]))
ref, first = d["reference"], d["samplers"][0]
num = lambda v, f: "n/a" if v is None or not math.isfinite(v) else format(v, f)
print(f"### {sys.argv[2]}\n")
what = f"{ref['estimator']} {ref['sampling']}" if ref["estimator"] else f"finite differences, step {ref['eps']:g}"
print(f"{d['width']}x{d['height']}, {d['combinations'][0]['spp']} spp x {d['batches']} batches, max depth "
      f"{ref['max_depth']}; reference {ref['kind']} ({what}, {first} numbers; its own relative error "
      f"{num(ref['rel_se'], '.3g')})\n")
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
