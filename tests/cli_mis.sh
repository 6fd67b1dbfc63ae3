#!/usr/bin/env bash
# --sampling mis (detached and attached combined, estimators/mis.h) from the
# command line, on the bundled Cornell box:
#   a. help texts of grad, fdcheck and optimize and the manual name it; an
#      unknown mode is refused listing every mode (exit 2);
#   b. grad --json reports the weights per parameter (reverse and forward
#      mode): roughness gets a real mix, a colour all detached; with no
#      parameter in a sampling map mis runs detached, the same gradient bit
#      for bit; prb and tape agree to rounding;
#   c. fdcheck --sampling mis agrees for roughness;
#   d. compare takes the mode from the registry: listed in --help, run by
#      default, and by name;
#   e. what attached cannot do (media), mis refuses the same way;
#   f. the memory estimate counts mis's copies and refuses what exceeds the limit.
# Run by tests/run.sh (env: DRENDER = the binary); also runs alone.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
cli_setup mis
require_drender
red=/materials/red/pbrMetallicRoughness/baseColorFactor
rough=/materials/rough-gold/pbrMetallicRoughness/roughnessFactor
fast="--res 16x16 --max-depth 6"


# ---- a. help and the unknown mode ----
for cmd in grad fdcheck optimize; do
    run "$cmd" --help
    expect_rc 0 "$cmd --help"
    grep -A3 -- '--sampling S' "$tmp/out" | grep -q 'mis' || fail "$cmd --help: --sampling does not mention mis"
done
# the manual documents the mode, its option value and the JSON key
man_page="$cli_root/man/drender.1"
grep -q 'detached\\fR|\\fPattached\\fR|\\fPmis' "$man_page" || fail "man/drender.1: --sampling does not list mis"
grep -q '^\.B mis$' "$man_page" || fail "man/drender.1: SAMPLING has no mis entry"
grep -q 'mis_weight' "$man_page" || fail "man/drender.1: mis_weight undocumented"
run grad --param "$red" --sampling sideways -o d.exr $fast
expect_rc 2 "grad --sampling sideways"
expect_mentions "--sampling|sideways|detached, attached, mis"

# ---- b. grad: weights, detached when nothing moves, prb = tape ----
run render -o t.exr $fast --spp 64
expect_rc 0 "render target"
run grad --target t.exr --param "$rough" --param "$red" --set "$rough=0.1" --sampling mis --spp 8 --batches 4 $fast --json
expect_rc 0 "grad --sampling mis (reverse)"
cp "$tmp/out" prb.json
json_check prb.json 'd["sampling"] == "mis" and d["sampling_effective"] == "mis"
and all(0 <= p["mis_weight"]["detached"] <= 1 and abs(p["mis_weight"]["detached"] + p["mis_weight"]["attached"] - 1) < 1e-12
        for p in d["parameters"])
and d["parameters"][0]["mis_weight"]["detached"] < 0.9
and d["parameters"][1]["mis_weight"]["detached"] == 1
and all(math.isfinite(x) for p in d["parameters"] for x in p["gradient"] + p["stderr"])
and all(p["stderr_gradient"] == [None] * p["size"] and p["stderr_primal"] == [None] * p["size"]
        for p in d["parameters"])'
run grad --target t.exr --param "$rough" --param "$red" --set "$rough=0.1" --sampling mis --spp 8 --batches 4 $fast --json \
    --estimator tape
expect_rc 0 "grad --sampling mis --estimator tape"
cp "$tmp/out" tape.json
if $have_python; then
    python3 - prb.json tape.json <<'EOF' || fail "prb and tape disagree under mis"
import json, sys
a, b = (json.load(open(f)) for f in sys.argv[1:3])
for p, q in zip(a["parameters"], b["parameters"]):
    for x, y in zip(p["gradient"], q["gradient"]):
        assert abs(x - y) <= 1e-9 * abs(y) + 1e-15, (p["name"], x, y)
    assert abs(p["mis_weight"]["detached"] - q["mis_weight"]["detached"]) <= 1e-9, p["name"]
EOF
fi
run grad --target t.exr --param "$rough" --param "$red" --set "$rough=0.1" --sampling mis --spp 8 --batches 4 $fast
expect_rc 0 "grad --sampling mis (text)"
expect_in out "mis weight" "grad text output: the weights"
# no parameter in a sampling map: detached, bit for bit
run grad --target t.exr --param "$red" --sampling mis --spp 8 --batches 4 $fast --json
cp "$tmp/out" mis_red.json
json_check mis_red.json 'd["sampling_effective"] == "detached" and d["parameters"][0]["mis_weight"]["detached"] == 1'
run grad --target t.exr --param "$red" --sampling detached --spp 8 --batches 4 $fast --json
cp "$tmp/out" det_red.json
json_check det_red.json '"mis_weight" not in d["parameters"][0]'
if $have_python; then
    python3 -c 'import json, sys
a, b = (json.load(open(f))["parameters"][0]["gradient"] for f in sys.argv[1:3])
sys.exit(a != b)' mis_red.json det_red.json || fail "mis with a colour only is not the detached gradient"
fi
# forward mode: one weight per --param (the direction)
run grad --param "$rough" --set "$rough=0.1" --sampling mis --spp 8 $fast -o d.exr --json
expect_rc 0 "grad --sampling mis (forward)"
json_check "$tmp/out" 'd["sampling_effective"] == "mis" and 0 <= d["parameters"][0]["mis_weight"]["detached"] < 0.9'
[ -s d.exr ] || fail "grad forward: d.exr missing"

# ---- c. fdcheck ----
run fdcheck --param "$rough" --set "$rough=0.5" --sampling mis --spp 16 --batches 8 $fast --z-max 3
expect_rc 0 "fdcheck --sampling mis (roughness 0.5)"
expect_in out "agree" "fdcheck verdict"

# ---- d. compare: the registry's modes, at run time ----
run compare --help
avail=$(sed -n 's/.*available now: //p' "$tmp/out")
case "$avail" in *mis*) ;; *) fail "compare --help: mis not in '$avail'" ;; esac
run compare --param "$rough" --set "$rough=0.5" --res 8x8 --max-depth 4 --spp 2 --reference spp:16 --estimators prb -o cmp_all
expect_rc 0 "compare (default sampling modes)"
# every mode the registry lists runs by default (derivative too); mis among them
json_check cmp_all/results.json '{"attached", "detached", "mis"} <= {c["sampling"] for c in d["combinations"]}'
run compare --param "$rough" --set "$rough=0.5" --res 8x8 --max-depth 4 --spp 2 --reference spp:16 --sampling mis -o cmp_mis
expect_rc 0 "compare --sampling mis"
json_check cmp_mis/results.json '{c["sampling"] for c in d["combinations"]} == {"mis"} and len(d["combinations"]) == 2
and all(math.isfinite(c["rel_error"]) for c in d["combinations"])'

# ---- e. refusals shared with attached (the same exit code as attached's) ----
fog="$DR_TESTDIR/data/media/fog-khr.gltf"
run grad "$fog" --param /materials/0/pbrMetallicRoughness/roughnessFactor --sampling attached --res 8x8 --spp 1 -o m.exr
attached_rc=$rc
[ "$attached_rc" -eq 2 ] || fail "attached sampling on a scene with media: exit $attached_rc, want 2 (bad usage)"
run grad "$fog" --param /materials/0/pbrMetallicRoughness/roughnessFactor --sampling mis --res 8x8 --spp 1 -o m.exr
expect_rc "$attached_rc" "grad --sampling mis on a scene with media (as attached)"
expect_mentions "mis sampling|participating media|--sampling detached"
[ -e m.exr ] && fail "a refused run wrote m.exr"
# ---- f. the memory estimate counts mis's group copies (16 per thread) ----
est() { python3 -c 'import json, sys; print(json.load(open(sys.argv[1]))["memory_estimate_bytes"])' "$1"; }
if $have_python; then
    run grad --param "$rough" --res 16x16 --spp 1 --threads 2 --sampling detached -o e.exr --json
    cp "$tmp/out" est_det.json
    run grad --param "$rough" --res 16x16 --spp 1 --threads 2 --sampling mis -o e.exr --json
    cp "$tmp/out" est_mis.json
    # forward mode: 2 x 8 derivative images (16 x 16 x 3 doubles) and the pixel counts, per thread
    want=$(( (16 * 16 * 3 * 16 + 16 * 16) * 8 * 2 ))
    [ $(( $(est est_mis.json) - $(est est_det.json) )) -eq "$want" ] ||
        fail "memory estimate: mis adds $(( $(est est_mis.json) - $(est est_det.json) )) bytes, want $want"
fi
DRENDER_MEM_LIMIT=2G run grad --param "$rough" --res 2048x2048 --spp 1 --threads 2 --sampling mis -o big.exr
expect_rc 2 "grad --sampling mis over the memory limit"
expect_mentions "--res|DRENDER_MEM_LIMIT"
[ -e big.exr ] && fail "a refused run wrote big.exr"
# compare counts them too: forward mode at 1536x1536 needs about 0.6 GB with
# detached sampling alone, 2.5 GB once a mis run's 16 derivative images per thread count
DRENDER_MEM_LIMIT=1500M run compare --param "$rough" --res 1536x1536 --spp 1 --batches 2 --threads 2 \
    --sampling detached,mis --estimators prb -o cmp_big
expect_rc 2 "compare --sampling mis over the memory limit"
expect_mentions "compare|--sampling mis|DRENDER_MEM_LIMIT"
[ -e cmp_big/results.json ] && fail "a refused compare wrote results.json"
echo "cli_mis: all checks passed"
