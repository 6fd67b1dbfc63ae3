#!/usr/bin/env bash
# An example batch script: `drender compare` over several scenes, one
# directory each, and every results.csv collected into one table.
#
#   scripts/compare-scenes.sh [OUT]          (default OUT: out/compare)
#
# OUT/<name>/ holds each comparison (report.md, results.csv, results.json,
# plots); OUT/all.csv all rows (one header, the scene in the first column);
# OUT/best.txt the most efficient combination per scene (from the --json
# summaries). Extra options for every run: COMPARE_OPTS, e.g.
#   COMPARE_OPTS="--spp 1,4,16 --repeat 3" scripts/compare-scenes.sh
# Edit the SWEEP list for your own scenes: NAME|SCENE|ARGS (ARGS: --param,
# --set, --target... as for drender compare).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${BUILD:-build}
DR=${DRENDER:-$BUILD/drender}
OUT=${1:-out/compare}
mkdir -p "$OUT"

red=/materials/red/pbrMetallicRoughness/baseColorFactor
rough=/materials/rough-gold/pbrMetallicRoughness/roughnessFactor
SWEEP=(
    "cornell-albedo|scenes/cornell-box.gltf|--param $red --res 48x48"
    "cornell-roughness|scenes/cornell-box.gltf|--param $rough --res 48x48 --max-depth 4,8"
    "cornell-texture|scenes/cornell-box.gltf|--param /images/0 --res 48x48"
    "cornell-emission|scenes/cornell-box.gltf|--param /materials/light/extensions/KHR_materials_emissive_strength/emissiveStrength --res 48x48"
    "environment|tests/data/gltf/env_map.gltf|--param /extensions/DR_environment/strength --res 48x48"
)

: >"$OUT/best.txt"
rm -f "$OUT/all.csv"
for entry in "${SWEEP[@]}"; do
    IFS='|' read -r name scene args <<<"$entry"
    echo "== $name: $scene $args"
    # shellcheck disable=SC2086  # ARGS and COMPARE_OPTS are word lists
    "$DR" compare "$scene" $args ${COMPARE_OPTS:-} --json -o "$OUT/$name" >"$OUT/$name.json"
    if [ ! -f "$OUT/all.csv" ]; then
        head -1 "$OUT/$name/results.csv" >"$OUT/all.csv"
    fi
    tail -n +2 "$OUT/$name/results.csv" >>"$OUT/all.csv"
    python3 - "$name" "$OUT/$name.json" >>"$OUT/best.txt" <<'EOF'
import json, sys
d = json.load(open(sys.argv[2]))
b = d["best"]
num = lambda v: "undefined" if v is None else f"{v:.4g}"   # null: a zero reference
print(f"{sys.argv[1]}: {b['estimator']} {b['sampling']} depth {b['max_depth']} at {b['spp']} spp "
      f"(efficiency {num(b['efficiency'])}; reference {d['reference']['kind']}, "
      f"its relative standard error {num(d['reference']['rel_se'])})")
EOF
done
echo "== $OUT/all.csv: $(($(wc -l <"$OUT/all.csv") - 1)) rows"
cat "$OUT/best.txt"
