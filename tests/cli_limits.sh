#!/usr/bin/env bash
# Absurd requests (issue 13): options and inputs that would need more memory
# than a machine has, or make no sense (more batches than samples), are
# refused before any work with exit 2 (options) or 3 (input files), a
# message naming the option or the file, nothing on stdout and no output
# file -- never an out-of-memory kill. And --json reports the memory
# estimate ("memory_estimate_bytes") of render, grad, fdcheck and optimize.
#
# Requests that are absurd on any machine are tried as they are; those that
# depend on the machine's size run with DRENDER_MEM_LIMIT (the limit drender
# otherwise takes from /proc/meminfo), so the test does not depend on the
# machine. Run by tests/run.sh (env: DRENDER, DR_TESTDIR); also runs alone.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
data=$DR_TESTDIR/data
cli_setup limits
require_drender
scene=$data/optimize/diffuse.gltf
tex=$data/optimize/texture-flat.gltf
P=/materials/0/pbrMetallicRoughness/baseColorFactor
ncases=0

# refused CODE "NEEDLE|..." ARGS...: exit CODE, message, nothing on stdout, no files written
refused() {
    local want=$1 needles=$2 before
    shift 2
    ncases=$((ncases + 1))
    before=$(ls -A "$work")
    run "$@"
    check_failed "$want" "$needles"
    [ "$(ls -A "$work")" = "$before" ] || fail "files left behind: $(ls -A "$work")"
}

# A PNG whose header claims SIZExSIZE RGBA pixels; the file itself is tiny.
huge_png() {   # huge_png FILE SIZE
    python3 - "$1" "$2" <<'PY' || fail "cannot write $1"
import struct, sys, zlib
def chunk(t, d): return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xffffffff)
w = int(sys.argv[2])
open(sys.argv[1], "wb").write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, w, 8, 6, 0, 0, 0))
                              + chunk(b"IDAT", zlib.compress(b"\0" * 64)) + chunk(b"IEND", b""))
PY
}

# ---- option values no machine can serve ----
refused 2 "--res|100000x100000" render "$scene" --res 100000x100000 -o r.exr
refused 2 "--spp|1e12" render "$scene" --spp 1e12 -o r.exr
refused 2 "--spp|1000000000000" render "$scene" --spp 1000000000000 -o r.exr
refused 2 "--max-depth|1e9" render "$scene" --max-depth 1e9 -o r.exr
refused 2 "--max-depth|1000000000" render "$scene" --max-depth 1000000000 -o r.exr
refused 2 "--max-depth|1e9" grad "$scene" --param $P --max-depth 1e9 -o d.exr
# the tape of 16.7M paths x 100000 vertices: petabytes
refused 2 "--max-depth x --batch|more than the|memory" grad "$scene" --param $P --estimator tape --max-depth 100000 \
    --res 4096x4096 --batch 9223372036854775807 -o d.exr
refused 2 "--batch|not a whole number" grad "$scene" --param $P --estimator tape --batch 1e30 -o d.exr

# ---- batches beyond the samples ----
"$DRENDER" render "$scene" -o t.exr --res 8x8 --spp 4 2>/dev/null || fail "cannot render a target"
refused 2 "--batches 8|--spp 4" grad "$scene" --target t.exr --param $P --spp 4 --batches 8
run grad "$scene" --target t.exr --param $P --spp 4 --batches 4
expect_rc 0 "--batches equal to --spp"

# ---- requests that exceed this machine's memory (limit set by DRENDER_MEM_LIMIT) ----
export DRENDER_MEM_LIMIT=8G
# 32768x32768 is a legal size, but its float image alone is 12 GiB
refused 2 "--res|more than the 8.0 GiB drender may use|DRENDER_MEM_LIMIT" render "$scene" --res 32768x32768 -o r.exr
DRENDER_MEM_LIMIT=1M refused 2 "--res|1.0 MiB" render "$scene" --res 1024x1024 -o r.exr
DRENDER_MEM_LIMIT=100M refused 2 "--batches" fdcheck "$tex" --param /images/0 --batches 1048576 --res 4x4
DRENDER_MEM_LIMIT=1G refused 2 "--max-depth|tape" optimize "$tex" --target t.exr --param /images/0 \
    --estimator tape --max-depth 100000 --iters 1 --out-dir progress
unset DRENDER_MEM_LIMIT

# ---- textures and targets larger than any machine's memory ----
huge_png "$tmp/huge.png" 999999
refused 3 "--target|huge.png|999999x999999|more than the" grad "$scene" --target "$tmp/huge.png" --param $P
refused 3 "--target|huge.png|999999x999999" optimize "$scene" --target "$tmp/huge.png" --param $P --out-dir progress
# the same image as a texture of a scene: named by file and JSON path
mkdir "$tmp/hugetex"
cp "$data/gltf/basic.gltf" "$data/gltf/basic.bin" "$data/gltf/mr.png" "$tmp/hugetex/"
cp "$tmp/huge.png" "$tmp/hugetex/checker.png"
refused 3 "basic.gltf|/images/0|999999x999999|more than the" render "$tmp/hugetex/basic.gltf" -o r.exr
# found by make fuzz: a 55-byte BMP claiming 3604481x5 pixels made OpenImageIO
# allocate 256 scanlines (2.7 GB) to convert it; the estimate counted that
# too, and now its pixel data, which cannot be in 54 bytes, is refused first
# (core/bmp_check.h)
tail -c +2 "$cli_root/fuzz/corpus/image/regress-bmp-bogus-bpp" >"$tmp/bogus.bmp"
DRENDER_MEM_LIMIT=1G refused 3 "--target|bogus.bmp|3604481x5|is not all inside its 54 bytes" grad "$scene" \
    --target "$tmp/bogus.bmp" --param $P
# found by make fuzz: a 1 KB GIF claiming a 29702x15720 screen made OpenImageIO's
# GIF reader allocate and clear its 1.9 GB canvas as it opened the file (7 s),
# before drender saw the header; the screen size is now checked first
tail -c +2 "$cli_root/fuzz/corpus/image/regress-gif-huge-canvas" >"$tmp/canvas.gif"
# (before, the reader's own error: "Wrong record type detected"); and one
# whose signature is "GIF88a", which giflib opens as well
tail -c +2 "$cli_root/fuzz/corpus/image/regress-gif88a-huge-canvas" >"$tmp/canvas88.gif"
for g in canvas canvas88; do
    DRENDER_MEM_LIMIT=1G refused 3 "--target|$g.gif|29702x15720|more than the" grad "$scene" \
        --target "$tmp/$g.gif" --param $P
done
# a texture that fits the machine but not DRENDER_MEM_LIMIT (an 8-bit texture
# takes a byte per value: 11.4 MiB here, and 1.5 MiB of decoder scratch)
huge_png "$tmp/hugetex/checker.png" 2000
DRENDER_MEM_LIMIT=8M refused 3 "/images/0|2000x2000|8.0 MiB" params "$tmp/hugetex/basic.gltf"
DRENDER_MEM_LIMIT=nonsense run render "$scene" --res 4x4 --spp 1 -o ok.exr
expect_rc 0 "an unreadable DRENDER_MEM_LIMIT is ignored"
expect_mentions "DRENDER_MEM_LIMIT='nonsense'|ignored"

# ---- the estimate in --json ----
json_estimate() {   # prints memory_estimate_bytes of the last run's JSON (last object)
    tail -n 1 "$tmp/out" | sed -n 's/.*"memory_estimate_bytes": \([0-9]*\).*/\1/p'
}
# at least the float image (64x64x3x4 bytes), at most what the machine could hold
check_estimate() {   # check_estimate WHAT MIN
    local e
    e=$(json_estimate)
    [ -n "$e" ] || fail "$1: no memory_estimate_bytes in --json"
    [ "$e" -ge "$2" ] || fail "$1: memory_estimate_bytes $e is below $2"
    [ "$e" -lt 1000000000 ] || fail "$1: memory_estimate_bytes $e is absurd for a 64x64 job"
}
run render "$scene" --res 64x64 --spp 1 -o r.exr --json
expect_rc 0 "render --json"
check_estimate "render" $((64 * 64 * 12))
e64=$(json_estimate)
run render "$scene" --res 128x128 --spp 1 -o r.exr --json
e128=$(json_estimate)
[ "$e128" -ge $((128 * 128 * 12)) ] && [ "$e128" -gt "$e64" ] ||
    fail "the estimate does not follow --res (64x64: $e64, 128x128: $e128)"
run grad "$scene" --param $P --res 64x64 --spp 1 -o d.exr --json
expect_rc 0 "grad forward --json"
check_estimate "grad (forward)" $((64 * 64 * 24))
"$DRENDER" render "$scene" -o t64.exr --res 64x64 --spp 1 2>/dev/null || fail "cannot render a target"
run grad "$scene" --target t64.exr --param $P --spp 2 --batches 2 --json
expect_rc 0 "grad reverse --json"
check_estimate "grad (reverse)" $((64 * 64 * 12 * 2))
# the tape's default batch: 512 paths per thread, recorded then swept
run grad "$scene" --target t64.exr --param $P --spp 2 --batches 2 --json --estimator tape --max-depth 50 --threads 2
expect_rc 0 "grad reverse tape --json"
e=$(json_estimate)
[ "$e" -ge $((2 * 512 * 50 * 704)) ] || fail "the tape estimate ($e) is below paths x depth x record size"
# --batch: every pixel's sample of a batch at once (4096 paths)
run grad "$scene" --target t64.exr --param $P --spp 2 --batches 2 --json --estimator tape --max-depth 50 --threads 2 \
    --batch 4096
expect_rc 0 "grad reverse tape --batch 4096 --json"
eb=$(json_estimate)
[ "$eb" -ge $((64 * 64 * 50 * 704)) ] && [ "$eb" -gt "$e" ] ||
    fail "the tape estimate does not follow --batch (default: $e, 4096 paths: $eb)"
# the estimate covers what each estimator's workers held (their paths in
# flight, prb's parked samples: estimator_memory_bytes), on 1 and 2 threads
for est in prb tape; do
    for t in 1 2; do
        run grad "$scene" --target t64.exr --param $P --spp 16 --json --estimator $est --threads $t
        expect_rc 0 "grad reverse $est --threads $t --json"
        e=$(json_estimate)
        held=$(tail -n 1 "$tmp/out" | sed -n 's/.*"estimator_memory_bytes": \([0-9]*\).*/\1/p')
        [ -n "$held" ] && [ "$e" -ge "$held" ] ||
            fail "$est, $t threads: the estimate ($e) is below what the estimator held (${held:-none})"
    done
done
run fdcheck "$scene" --param $P --res 16x16 --spp 1 --batches 2 --json
[ "$rc" -eq 0 ] || [ "$rc" -eq 4 ] || fail "fdcheck --json: exit $rc"
check_estimate "fdcheck" $((16 * 16 * 12))
run optimize "$scene" --target t64.exr --param $P --iters 1 --spp 1 --out-dir progress --json
expect_rc 0 "optimize --json"
check_estimate "optimize" $((64 * 64 * 12 * 3))

# fdcheck counts the estimator's sums as grad does: its thread 0 sums into
# the batch's vector and, from 4 threads on, the others share one vector of
# exact sums (estimator.h), so the estimate stops growing a vector per thread
find_samples
ntt=$samples/NormalTangentTest/glTF/NormalTangentTest.gltf
[ -f "$ntt" ] || fail "NormalTangentTest.gltf not found"
T=$((2048 * 2048 * 3))
for t in 2 4 8; do
    run fdcheck "$ntt" --param /images/0 --res 4x4 --spp 1 --batches 2 --threads $t --json
    [ "$rc" -eq 0 ] || [ "$rc" -eq 4 ] || fail "fdcheck NormalTangentTest --threads $t: exit $rc"
    eval "fd$t=\$(json_estimate)"
done
# direction, theta, its copy and range, two batches' gradients: 7 vectors
[ "$fd2" -ge $((T * 7 * 8)) ] || fail "fdcheck's estimate ($fd2) is below its 7 vectors of $T doubles"
[ $((fd8 - fd4)) -lt $((T * 8)) ] ||
    fail "fdcheck's estimate grows a vector per thread from 4 threads on (4: $fd4, 8: $fd8)"

echo "cli_limits: $ncases absurd requests refused; estimates in --json checked"
