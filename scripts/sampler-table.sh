#!/usr/bin/env bash
# Which random numbers gradients should draw: `drender compare --primal cross`
# (every run its own primal, as grad and optimize run it) with the
# independent and sobol samplers, per parameter kind and samples a batch, on
# the bundled Cornell box. One markdown table: per case and spp, the ratio of
# the two samplers' variances and of their efficiencies (> 1: sobol better).
#
#   scripts/sampler-table.sh [OUT]          (default OUT: out/samplers)
#
# The cases start from wrong values (the red wall's albedo 0.5 grey; the gold
# sphere's roughness 0.05, 0.15, 0.3 and 0.6, its metallic 0.5; the light's
# strength 12 instead of 17) plus the floor's texture at its own values, L2
# against a 1024 spp render of the box as it is (OUT/target.exr).
# Variances come from BATCHES independent estimates of SPP samples a pixel (a
# batch of grad --batches K --spp K*SPP), so the variance ratio's own error is
# about sqrt(4 / BATCHES) (more for heavy-tailed cases); seconds are wall
# time on whatever machine runs it (shared machines: noisy; the variance
# ratio is the steadier column).
# Settings (environment): RES (96x96), SPP (4,8,16,32), BATCHES (64),
# REF_SPP (64: the reference only scales both samplers' variances alike),
# DEPTH (5), THREADS (2), CASES (all: a comma-separated subset of the names).
# About 6 minutes on 2 cores with the defaults (docs/sampler-table.md holds a run).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${BUILD:-build}
DR=${DRENDER:-$BUILD/drender}
OUT=${1:-out/samplers}
RES=${RES:-96x96} SPP=${SPP:-4,8,16,32} BATCHES=${BATCHES:-64} REF_SPP=${REF_SPP:-64} DEPTH=${DEPTH:-5}
THREADS=${THREADS:-2} CASES=${CASES:-all}
mkdir -p "$OUT"

pbr=pbrMetallicRoughness
red=/materials/red/$pbr/baseColorFactor
rough=/materials/rough-gold/$pbr/roughnessFactor
metal=/materials/rough-gold/$pbr/metallicFactor
strength=/materials/light/extensions/KHR_materials_emissive_strength/emissiveStrength
ALL=(   # name|title|arguments
    "albedo|red wall albedo (at 0.5 grey)|--param $red --set $red=0.5,0.5,0.5"
    "roughness-0.05|gold roughness 0.05|--param $rough --set $rough=0.05"
    "roughness-0.15|gold roughness 0.15|--param $rough --set $rough=0.15"
    "roughness-0.3|gold roughness 0.3|--param $rough --set $rough=0.3"
    "roughness-0.6|gold roughness 0.6|--param $rough --set $rough=0.6"
    "metallic|gold metallic (at 0.5)|--param $metal --set $metal=0.5"
    "emission|light strength (at 12)|--param $strength --set $strength=12"
    "texture|floor texture (gradient norm)|--param /images/0"
)

: >"$OUT/cases"
"$DR" render scenes/cornell-box.gltf --res "$RES" --spp 1024 --max-depth "$DEPTH" --threads "$THREADS" --seed 99 \
    -o "$OUT/target.exr"
for entry in "${ALL[@]}"; do
    IFS='|' read -r name title args <<<"$entry"
    [[ $CASES == all || ",$CASES," == *",$name,"* ]] || continue
    echo "== $title" >&2
    # shellcheck disable=SC2086  # args is a word list
    "$DR" compare scenes/cornell-box.gltf $args --target "$OUT/target.exr" --primal cross \
        --sampler independent,sobol --estimators prb --sampling detached --spp "$SPP" --batches "$BATCHES" \
        --reference "spp:$REF_SPP" --max-depth "$DEPTH" --threads "$THREADS" -o "$OUT/$name" >/dev/null
    echo "$name|$title" >>"$OUT/cases"
done

python3 - "$OUT" "$BATCHES" <<'PY' | tee "$OUT/table.md"
import json, os, sys
out, batches = sys.argv[1], sys.argv[2]
rows, spps = [], None
for line in open(os.path.join(out, "cases")):
    name, title = line.rstrip("\n").split("|", 1)
    d = json.load(open(os.path.join(out, name, "results.json")))
    by = {(c["sampler"], c["spp"]): c for c in d["combinations"]}
    spps = sorted({c["spp"] for c in d["combinations"]})
    cells = []
    for s in spps:
        a, b = by[("independent", s)], by[("sobol", s)]
        var = a["rel_variance"] / b["rel_variance"]
        eff = var * a["seconds_median"] / b["seconds_median"]
        cells.append(f"{var:.2f} / {eff:.2f}")
    rows.append(f"| {title} | " + " | ".join(cells) + " |")
print(f"Sobol against independent numbers under the cross primal (compare --primal cross, {batches} batches): "
      "variance ratio / efficiency ratio (independent / sobol; > 1: sobol better), by samples a batch.\n")
print("| case | " + " | ".join(f"{s} a batch" for s in spps) + " |")
print("|---|" + "---:|" * len(spps))
print("\n".join(rows))
PY
