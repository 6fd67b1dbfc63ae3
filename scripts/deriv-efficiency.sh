#!/bin/sh
# Standard error, seconds and efficiency 1 / (variance x seconds) of the
# gradient for --sampling detached, attached and derivative on the bundled
# Cornell box (issue 12): the red wall's albedo, the gold sphere's metallic
# factor and its roughness at 0.001, 0.1 and 0.5. Reverse mode against a
# target rendered at the file's values; every case evaluated away from them
# so gradients are not ~0. Timings are the estimator's own ("time.gradient")
# and depend on the machine's load: take them as a rough guide.
#
#   scripts/deriv-efficiency.sh [drender] [seeds]     (defaults: build/drender, 3)
# Env: RES (64x64), SPP (32), BATCHES (8), DEPTH (6), THREADS (2).
set -eu
DR=${1:-build/drender}
SEEDS=${2:-3}
RES=${RES:-64x64} SPP=${SPP:-32} BATCHES=${BATCHES:-8} DEPTH=${DEPTH:-6} THREADS=${THREADS:-2}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
"$DR" render -o "$tmp/target.exr" --res "$RES" --spp 256 --max-depth "$DEPTH" --threads "$THREADS" 2>/dev/null
M=/materials
cases="red-albedo|$M/red/pbrMetallicRoughness/baseColorFactor|$M/red/pbrMetallicRoughness/baseColorFactor=0.4,0.2,0.2
gold-metallic|$M/rough-gold/pbrMetallicRoughness/metallicFactor|$M/rough-gold/pbrMetallicRoughness/metallicFactor=0.7
gold-rough-0.001|$M/rough-gold/pbrMetallicRoughness/roughnessFactor|$M/rough-gold/pbrMetallicRoughness/roughnessFactor=0.001
gold-rough-0.1|$M/rough-gold/pbrMetallicRoughness/roughnessFactor|$M/rough-gold/pbrMetallicRoughness/roughnessFactor=0.1
gold-rough-0.5|$M/rough-gold/pbrMetallicRoughness/roughnessFactor|$M/rough-gold/pbrMetallicRoughness/roughnessFactor=0.5"
echo "$cases" | while IFS='|' read -r name param set; do
    for s in detached attached derivative; do
        seed=1
        while [ "$seed" -le "$SEEDS" ]; do
            "$DR" grad --target "$tmp/target.exr" --param "$param" --set "$set" --res "$RES" --spp "$SPP" \
                --batches "$BATCHES" --max-depth "$DEPTH" --threads "$THREADS" --sampling "$s" --seed "$seed" \
                --sampler independent --json 2>/dev/null >"$tmp/$name.$s.$seed.json"   # (as its recorded figures)
            seed=$((seed + 1))
        done
    done
done
python3 - "$tmp" "$SEEDS" <<'PY'
import glob, json, os, sys
tmp, seeds = sys.argv[1], int(sys.argv[2])
rows = {}
for f in sorted(glob.glob(os.path.join(tmp, "*.json"))):
    name, s, seed = os.path.basename(f)[:-5].rsplit(".", 2) if f.count(".") >= 3 else (None, None, None)
    d = json.load(open(f))
    p = d["parameters"][0]
    # mean over components of the gradient's own variance (the primal's noise is common to all modes)
    var = sum(e * e for e in p["stderr_gradient"]) / len(p["stderr_gradient"])
    r = rows.setdefault((name, s), {"var": 0.0, "sec": 0.0, "grad": 0.0, "rays": 0})
    r["var"] += var / seeds
    r["sec"] += d["time"]["gradient"] / seeds
    r["grad"] += p["gradient"][0] / seeds
    r["rays"] += d["rays"]["total"] // seeds
print("| case | sampling | gradient[0] | stderr (gradient) | seconds | rays | efficiency 1/(var s) | vs detached |")
print("|---|---|---|---|---|---|---|---|")
for name in sorted({k[0] for k in rows}):
    base = rows.get((name, "detached"))
    e0 = 1.0 / (base["var"] * base["sec"]) if base else None
    for s in ("detached", "attached", "derivative"):
        r = rows.get((name, s))
        if not r:
            continue
        e = 1.0 / (r["var"] * r["sec"]) if r["var"] > 0 else float("inf")
        print("| %s | %s | %.4g | %.3g | %.3f | %d | %.4g | %.2fx |" % (name, s, r["grad"], r["var"] ** 0.5, r["sec"],
              r["rays"], e, e / e0 if e0 else float("nan")))
PY
