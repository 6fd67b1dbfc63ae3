#!/usr/bin/env bash
# drender's demo (README's first command, via `make demo`): inverse rendering
# on the bundled Cornell box. Renders a target with the scene's true wall
# colours and sphere roughness, starts the optimiser from wrong values, and
# prints recovered vs true values and the final loss. Output in $1 (default
# out/demo): target.png, before.png, after.png, loss.csv, loss.png,
# render-NNNN.png, result.gltf.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${BUILD:-build}
OUT=${1:-out/demo}
DR="$BUILD/drender"
SCENE=scenes/cornell-box.gltf
mkdir -p "$OUT"

RES=96x96 DEPTH=5
red=/materials/red/pbrMetallicRoughness/baseColorFactor
green=/materials/green/pbrMetallicRoughness/baseColorFactor
rough=/materials/rough-gold/pbrMetallicRoughness/roughnessFactor

echo "== 1/2  target: the bundled scene at its true values ($RES, 1024 spp)"
"$DR" render "$SCENE" -o "$OUT/target.exr" --res "$RES" --spp 1024 --max-depth "$DEPTH" --seed 7

echo "== 2/2  optimise from wrong values (grey walls, roughness 0.9)"
"$DR" optimize "$SCENE" --target "$OUT/target.exr" \
    --param "$red" --param "$green" --param "$rough" \
    --set "$red=0.5,0.5,0.5" --set "$green=0.5,0.5,0.5" --set "$rough=0.9" \
    --iters "${DEMO_ITERS:-80}" --spp 16 --max-depth "$DEPTH" --lr 0.03 \
    --reference "$SCENE" --out-dir "$OUT" -o "$OUT/result.gltf"
