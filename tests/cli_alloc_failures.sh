#!/usr/bin/env bash
# Allocation failures: every allocation drender's own code makes, made to
# fail in turn (tests/failalloc.c, preloaded), in render (the bundled box,
# two real assets: Draco, a normal map), grad (each estimator's paths: the
# wavefront, the arrays, the walks ahead under derivative sampling,
# attached sampling, media, textures), fdcheck, compare and optimize. Each
# run must end in one of two ways:
#   - the work failed: exit 1, "out of memory" on stderr, nothing on stdout
#     and no output file (nothing half-written);
#   - a fallback took over (the lanes, the arrays and the walk-ahead each
#     fall back to one path at a time): exit 0 and the reference run's
#     result: the same image, the same gradients and standard errors (to
#     1e-9 of the largest: a fallback may add the same terms in another
#     order).
# Never a crash, another exit code or a sanitizer report. And the fallbacks
# are exercised: the grad cases that have one must see it taken.
#
# Under the sanitizers (drender linked with libasan) the injector is
# preloaded before AddressSanitizer and hands on to its allocator; the runs
# are slower there, so every second call site is tried (SWEEP_STRIDE).
# Run by tests/run.sh (env: DRENDER, DR_TESTDIR); also runs alone.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
cli_setup alloc_failures
require_drender
shim=$(cd "$(dirname "$DRENDER")" && pwd)/tests/libfailalloc.so
[ -f "$shim" ] || fail "no $shim (make test builds it)"
preload=$shim stride=${SWEEP_STRIDE:-1}
asan=$(ldd "$DRENDER" | awk '/libasan/ {print $3}')
if [ -n "$asan" ]; then
    preload="$shim $asan"
    export ASAN_OPTIONS="${ASAN_OPTIONS:+$ASAN_OPTIONS:}verify_asan_link_order=0"
    stride=${SWEEP_STRIDE:-2}
fi
media=$DR_TESTDIR/data/media
box=$DR_SCENES/cornell-box.gltf
tex=$DR_TESTDIR/data/optimize/texture-flat.gltf
"$DRENDER" render "$box" --res 16x16 --spp 8 -o "$tmp/target.exr" 2>"$tmp/err" || fail "cannot render the target"

# same_result KIND REF RUN: the run's result (stdout, or --json's numbers,
# and its output files) is the reference's
same_result() {
    local kind=$1 ref=$2 got=$3 f
    for f in $(ls -A "$ref"); do
        [ "$kind" = files ] && break
        [ -e "$got/$f" ] || { echo "no $f"; return 1; }
        cmp -s "$ref/$f" "$got/$f" || oiiotool "$ref/$f" "$got/$f" --diff --fail 0 --failpercent 0 >/dev/null 2>&1 ||
            { echo "$f differs"; return 1; }
    done
    if [ "$kind" = files ]; then   # (compare: its results hold times, so only that the same files are there)
        [ "$(cd "$ref" && find . | sort)" = "$(cd "$got" && find . | sort)" ] || { echo "other files"; return 1; }
        return 0
    fi
    if [ "$kind" = json ]; then
        python3 - "$ref.stdout" "$got.stdout" <<'PY'
import json, sys
a, b = (json.loads(open(p).read().strip().splitlines()[-1]) for p in sys.argv[1:3])
def nums(d):
    out = [d.get("loss", 0.0), d.get("invalid_samples", 0)]
    for p in d["parameters"]:   # (an image's: its norms; its gradient is a file, compared above)
        values = p["gradient"] + p["stderr"] if "gradient" in p else [p["norm"], p["stderr_norm"]]
        out += [x for x in values if x is not None]
    return out
x, y = nums(a), nums(b)
scale = max([abs(v) for v in x] + [1e-300])
bad = len(x) != len(y) or any(abs(u - v) > 1e-9 * scale for u, v in zip(x, y))
if bad:
    print("gradients differ:", x[:8], y[:8])
sys.exit(1 if bad else 0)
PY
    else
        cmp -s "$ref.stdout" "$got.stdout" || { echo "stdout differs"; return 1; }
    fi
}

# sweep NAME KIND FALLBACK KEEPS ARGS...: drender ARGS in an empty directory, first
# counting its allocations and their call sites, then with one allocation
# failing per run: the first at each call site no earlier case has tried (a
# site's later allocations take the same way out; the cases share loading).
# (With two threads the workers' allocations may come in another order from
# run to run: the k-th is then another of that phase's sites.)
# KIND: json (grad --json: compare the numbers), text (stdout as it is) or
# files (the same files written; compare's hold times).
# FALLBACK: yes if some failure must be absorbed by a fallback.
# KEEPS: - (a failed run leaves no file) or the output a failed run must not
# leave (optimize keeps its working directory, with its checkpoint: it is
# resumable, cli_optimize_kill.sh).
tried=$tmp/tried-sites
: >"$tried"
sweep() {
    local name=$1 kind=$2 fallback=$3 keeps=$4 n injected k rc absorbed=0 failed=0 why ks where=
    shift 4
    cli_cmd_label="$name"
    mkdir -p "$tmp/ref"
    (cd "$tmp/ref" && FAILALLOC_REPORT=$tmp/report LD_PRELOAD=$preload "$DRENDER" "$@" >"$tmp/ref.stdout" 2>"$tmp/err")
    rc=$?
    last_cmd="drender $*"
    cp "$tmp/ref.stdout" "$tmp/out"
    [ "$rc" -eq 0 ] || fail "$name: the reference run failed"
    read -r n injected <"$tmp/report" || fail "$name: no allocation count"
    cp "$tmp/report" "$tmp/ref-report"
    # (the injector must see drender's allocations: a count of none would pass anything)
    [ "$n" -ge 20 ] || fail "$name: only $n allocations counted"
    # the first allocation at each site not tried before (the report's lines
    # 2.. are the sites, in allocation order), every stride-th of them
    ks=$(tail -n +2 "$tmp/report" | awk -v tried="$tried" -v stride="$stride" '
        BEGIN { while ((getline s < tried) > 0) seen[s] = 1 }
        !($1 in seen) { seen[$1] = 1; if (m++ % stride == 0) { print NR; print $1 >> tried } }')
    [ -n "$ks" ] || fail "$name: no call site left to try"
    for k in $ks; do
        rm -rf "$tmp/run" "$tmp/report"
        mkdir "$tmp/run"
        (cd "$tmp/run" && FAILALLOC_NTH=$k FAILALLOC_REPORT=$tmp/report LD_PRELOAD=$preload \
            "$DRENDER" "$@" >"$tmp/run.stdout" 2>"$tmp/err")
        rc=$?
        cp "$tmp/run.stdout" "$tmp/out"
        last_cmd="FAILALLOC_NTH=$k drender $*"
        read -r _ injected <"$tmp/report" 2>/dev/null || fail "$name: allocation $k: no report (exit $rc: a crash?)"
        if grep -q "Sanitizer\|runtime error" "$tmp/err"; then
            fail "$name: allocation $k: a sanitizer report"
        elif [ "$rc" -eq 1 ]; then
            [ "$injected" = 1 ] || fail "$name: allocation $k: exit 1 without a failed allocation"
            grep -q "out of memory" "$tmp/err" || fail "$name: allocation $k: exit 1 without 'out of memory'"
            [ ! -s "$tmp/run.stdout" ] || fail "$name: allocation $k: output on stdout after the failure"
            if [ "$keeps" = - ]; then
                [ -z "$(ls -A "$tmp/run")" ] || fail "$name: allocation $k: files left behind: $(ls -A "$tmp/run")"
            else
                [ ! -e "$tmp/run/$keeps" ] || fail "$name: allocation $k: $keeps written"
            fi
            failed=$((failed + 1))
        elif [ "$rc" -eq 0 ]; then
            why=$(same_result "$kind" "$tmp/ref" "$tmp/run") ||
                fail "$name: allocation $k failed and the run went on, with another result: $why"
            if [ "$injected" = 1 ]; then   # (named in the summary: which fallbacks were taken)
                absorbed=$((absorbed + 1))
                where+=" $(addr2line -f -e "$DRENDER" "0x$(sed -n "$((k + 1))p" "$tmp/ref-report")" | head -n 1)@$k"
            fi
        else
            fail "$name: allocation $k: exit $rc"
        fi
    done
    [ "$fallback" = no ] || [ "$absorbed" -gt 0 ] || fail "$name: no fallback took a failed allocation"
    echo "$name: $n allocations, $(echo "$ks" | wc -w) tried: $failed failed the work cleanly, $absorbed were absorbed by a fallback${where:+ (in$where)}"
    rm -rf "$tmp/ref"
}

R="--res 16x16 --spp 8 --threads 2 --target $tmp/target.exr --json"
ROUGH="--set /materials/2/pbrMetallicRoughness/metallicFactor=1 --set /materials/2/pbrMetallicRoughness/roughnessFactor=0.3
       --param /materials/2/pbrMetallicRoughness/roughnessFactor"
# shellcheck disable=SC2086  # (R, ROUGH: word lists)
{
sweep "render" text no - render "$box" --res 16x16 --spp 2 -o out.exr
find_samples   # (real assets: Draco, a normal map with supplied tangents)
sweep "render draco" text no - render "$samples/Box/glTF-Draco/Box.gltf" --res 16x16 --spp 2 -o out.exr
sweep "render normal map" text no - render "$samples/NormalTangentTest/glTF/NormalTangentTest.gltf" --res 16x16 \
    --spp 2 -o out.exr
sweep "grad prb" json yes - grad "$box" --param /materials/2/pbrMetallicRoughness/baseColorFactor $R
sweep "grad prb attached" json no - grad "$box" $ROUGH --sampling attached $R
sweep "grad tape derivative" json yes - grad "$box" $ROUGH --sampling derivative --estimator tape $R
sweep "grad prb derivative" json yes - grad "$box" $ROUGH --sampling derivative $R
sweep "grad prb mis" json no - grad "$box" $ROUGH --sampling mis --regularize 0.01 $R
sweep "grad texture" json no - grad "$tex" --param /images/0 --param /materials/0/pbrMetallicRoughness/baseColorFactor \
    --res 16x16 --spp 8 --threads 2 --target "$tmp/target.exr" --json --grad-dir .
sweep "grad prb media" json no - grad "$media/smoke.gltf" --param /materials/smoke/extensions/DR_medium/density_scale $R
sweep "grad forward" text no - grad "$box" --param /materials/2/pbrMetallicRoughness/baseColorFactor --res 16x16 --spp 4 \
    -o d.exr
sweep "fdcheck" text no - fdcheck "$box" --param /materials/2/pbrMetallicRoughness/baseColorFactor --res 8x8 --spp 4 \
    --batches 4
sweep "compare" files no - compare "$box" --param /materials/2/pbrMetallicRoughness/baseColorFactor --spp 2 --res 8x8 \
    --estimators prb,tape -o cmp
sweep "optimize" text no fit.gltf optimize "$box" --param /materials/2/pbrMetallicRoughness/baseColorFactor \
    --target "$tmp/target.exr" --res 16x16 --spp 4 --iters 2 -o fit.gltf
}
echo "cli_alloc_failures: passed"
