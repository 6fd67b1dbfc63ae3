#!/usr/bin/env bash
# Write failures: the disk fills up while drender writes its results. Each
# command runs under a file-size limit (ulimit -f, with SIGXFSZ ignored, so
# that a write past the limit fails with EFBIG as a write to a full disk
# fails with ENOSPC: the same error path, through stdio, OpenEXR's streams
# and drender's own writes alike), once at 0 bytes and once just below the
# size of each file the command writes. Each run must end in one of two ways:
#   - the work failed: exit 1, an error naming the cause ("File too large")
#     and the file as the user named it (not a temporary),
#     and nothing half-written: every file left at its final name is whole
#     (the reference run's, byte for byte; optimize's progress images decode
#     and its checkpoint is a whole one), and no temporary file is left over;
#   - every file fitted under the limit: exit 0 and the reference's files.
# And when standard output cannot be written (> /dev/full), every command
# that prints exits 1 and says so, instead of losing its output silently.
# Run by tests/run.sh (env: DRENDER, DR_TESTDIR); also runs alone.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
cli_setup write_failures
require_drender
box=$DR_SCENES/cornell-box.gltf
"$DRENDER" render "$box" --res 16x16 --spp 8 -o "$tmp/target.exr" 2>"$tmp/err" || fail "cannot render the target"

# limited DIR BLOCKS ARGS...: drender ARGS in DIR with files limited to BLOCKS KiB;
# stdout -> $tmp/out, stderr -> $tmp/err, exit code -> $rc. Its output
# reaches those files through pipes, which the limit does not cover.
mkfifo "$tmp/fo" "$tmp/fe" || fail "mkfifo"
limited() {
    local dir=$1 blocks=$2 p1 p2
    shift 2
    cat <"$tmp/fo" >"$tmp/out" &
    p1=$!
    cat <"$tmp/fe" >"$tmp/err" &
    p2=$!
    (cd "$dir" && trap '' XFSZ && ulimit -f "$blocks" && exec "$DRENDER" "$@") >"$tmp/fo" 2>"$tmp/fe"
    rc=$?
    wait "$p1" "$p2"
    last_cmd="(ulimit -f $blocks; drender $*)"
}

# whole DIR REF: every file in DIR is whole. Files the reference also wrote
# byte for byte the same, unless KIND says they may differ (progress: an
# earlier iteration's, or times): then images must decode and text must be
# a whole checkpoint or table. No temporary file.
whole() {
    local dir=$1 ref=$2 f
    # (a temporary directory too: the glTF writer's .NAME.tmpXXXXXX)
    f=$(cd "$dir" && find . -name '*.tmp*' | head -n 1)
    [ -z "$f" ] || { echo "temporary left: $f"; return 1; }
    while IFS= read -r f; do
        [ -e "$ref/$f" ] || { echo "a file the reference run did not write: $f"; return 1; }
        cmp -s "$ref/$f" "$dir/$f" && continue
        if [ "$kind" = exact ]; then   # (an EXR holds its DateTime: the pixels then)
            case $f in *.exr | *.tif | *.png) oiiotool -q "$ref/$f" "$dir/$f" --diff --fail 0 --failpercent 0 \
                >/dev/null 2>&1 && continue ;; esac
            echo "$f differs from the reference (half-written?)"
            return 1
        fi
        case $f in
        *.png | *.exr) oiiotool -q "$dir/$f" -o "$tmp/decoded.exr" >/dev/null 2>&1 || { echo "$f does not decode"; return 1; } ;;
        *checkpoint.txt) tail -n 1 "$dir/$f" | grep -q . && [ "$(tail -c 1 "$dir/$f" | od -An -c | tr -d ' ')" = '\n' ] ||
            { echo "$f is cut short"; return 1; } ;;
        *.csv | *.md | *.gp | *.txt) [ "$(tail -c 1 "$dir/$f" | od -An -c | tr -d ' ')" = '\n' ] ||
            { echo "$f is cut short"; return 1; } ;;
        *.json) python3 -c 'import json,sys; json.load(open(sys.argv[1]))' "$dir/$f" 2>/dev/null ||
            { echo "$f is not whole JSON"; return 1; } ;;
        *) echo "$f differs from the reference"; return 1 ;;
        esac
    done < <(cd "$dir" && find . -type f | sed 's|^\./||')
}

# wsweep NAME KIND ARGS...: drender ARGS in an empty directory, first
# without a limit (the reference: its files and their sizes), then at each
# limit. KIND: exact (the same seed gives the same bytes) or progress (the
# files may be an earlier iteration's, or hold times).
wsweep() {
    local name=$1 limits b failed=0 ok=0 why
    kind=$2
    shift 2
    cli_cmd_label="$name"
    rm -rf "$tmp/ref" && mkdir "$tmp/ref"
    limited "$tmp/ref" unlimited "$@"
    [ "$rc" -eq 0 ] || fail "$name: the reference run failed"
    # 0, and just below each file's size: the largest limit it does not fit
    limits=$( (echo 0; find "$tmp/ref" -type f -size +0 -printf '%s\n' | awk '{ print int(($1 - 1) / 1024) }') | sort -nu)
    for b in $limits; do
        rm -rf "$tmp/run" && mkdir "$tmp/run"
        limited "$tmp/run" "$b" "$@"
        if grep -q "Sanitizer\|runtime error" "$tmp/err"; then
            fail "$name, limit $b KiB: a sanitizer report"
        elif [ "$rc" -eq 1 ]; then
            grep -q "File too large" "$tmp/err" || fail "$name, limit $b KiB: exit 1 without naming the cause"
            # (the file the user asked for, not drender's temporary)
            ! grep -q "\.tmp" "$tmp/err" || fail "$name, limit $b KiB: the message names a temporary file"
            failed=$((failed + 1))
        elif [ "$rc" -eq 0 ]; then
            # (every file written, each whole: checked below)
            [ "$(cd "$tmp/ref" && find . -type f | sort)" = "$(cd "$tmp/run" && find . -type f | sort)" ] ||
                fail "$name, limit $b KiB: exit 0 without every file"
            ok=$((ok + 1))
        else
            fail "$name, limit $b KiB: exit $rc"
        fi
        why=$(whole "$tmp/run" "$tmp/ref") || fail "$name, limit $b KiB: $why"
    done
    [ "$failed" -gt 0 ] || fail "$name: no limit made a write fail"
    echo "$name: $(echo "$limits" | wc -w) limits: $failed failed the work cleanly, $ok fitted"
}

B=/materials/2/pbrMetallicRoughness/baseColorFactor
wsweep "render png" exact render "$box" --res 64x64 --spp 2 -o out.png
wsweep "render exr" exact render "$box" --res 64x64 --spp 2 -o out.exr
wsweep "render hdr" exact render "$box" --res 64x64 --spp 2 -o out.hdr
wsweep "render tif" exact render "$box" --res 64x64 --spp 2 -o out.tif
wsweep "render jpg" exact render "$box" --res 64x64 --spp 2 -o out.jpg
# (a format OpenImageIO cannot write to memory: written to the file, then read back whole)
wsweep "render sgi" exact render "$box" --res 64x64 --spp 2 -o out.sgi
wsweep "grad forward" exact grad "$box" --param "$B" --res 32x32 --spp 2 -o d.exr
wsweep "grad texture" exact grad "$DR_TESTDIR/data/optimize/texture-flat.gltf" --param /images/0 --res 16x16 --spp 4 \
    --target "$tmp/target.exr" --grad-dir .
wsweep "optimize" progress optimize "$box" --param "$B" --target "$tmp/target.exr" --res 16x16 --spp 4 --iters 2 -o fit.gltf
wsweep "optimize glb" progress optimize "$box" --param "$B" --target "$tmp/target.exr" --res 16x16 --spp 4 --iters 1 \
    -o fit.glb
wsweep "optimize texture" progress optimize "$DR_TESTDIR/data/optimize/texture-flat.gltf" --param /images/0 \
    --target "$tmp/target.exr" --res 16x16 --spp 4 --iters 1 -o fit.gltf
wsweep "optimize density grid" progress optimize "$DR_TESTDIR/data/media/smoke.gltf" \
    --param /materials/0/extensions/DR_medium/density --target "$tmp/target.exr" --res 16x16 --spp 4 --iters 1 -o fit.gltf
wsweep "compare" progress compare "$box" --param "$B" --spp 2 --res 8x8 --estimators prb,tape -o cmp

# on disk before it has the output's name: the temporary is fsync'ed before
# the rename (a machine that stops right after could otherwise leave an
# empty file under the name), for a format encoded in memory (png) and one
# OpenImageIO's plugin writes itself (sgi)
command -v strace >/dev/null || fail "strace not installed (scripts/install-deps.sh installs it)"
for ext in png sgi; do
    # (LeakSanitizer cannot run under ptrace: make sanitize's build checks leaks everywhere else)
    ASAN_OPTIONS="${ASAN_OPTIONS:+$ASAN_OPTIONS:}detect_leaks=0" \
        strace -f -o "$tmp/strace" -e trace=openat,fsync,rename "$DRENDER" render "$box" --res 8x8 --spp 1 \
        -o "$work/durable.$ext" 2>"$tmp/err" || fail "render to durable.$ext under strace: $(head -c 300 "$tmp/err")"
    python3 - "$tmp/strace" "$ext" <<'PY' || fail "render to durable.$ext: no fsync of its temporary before the rename"
import re, sys
fds, synced, pending = {}, set(), {}
def lines(path):
    # strace -f splits a call another thread interrupts: "PID fsync(3 <unfinished ...>"
    # and later "PID <... fsync resumed>) = 0"; join them (the pid says whose)
    for line in open(path):
        line = line.rstrip("\n")
        pid = line.split(" ", 1)[0]
        if line.endswith("<unfinished ...>"):
            pending[pid] = line[: -len("<unfinished ...>")].rstrip()
            continue
        m = re.match(r'(\S+)\s+<\.\.\. \w+ resumed>(.*)$', line)
        if m and m.group(1) in pending:
            line = pending.pop(m.group(1)) + m.group(2)
        yield line
for line in lines(sys.argv[1]):
    m = re.search(r'openat\(.*"([^"]*\.tmp[^"]*)".* = (\d+)$', line)
    if m: fds[m.group(2)] = m.group(1)
    m = re.search(r'fsync\((\d+)\)\s+= 0', line)
    if m and m.group(1) in fds: synced.add(fds[m.group(1)])
    m = re.search(r'rename\("([^"]*)", "([^"]*durable\.' + sys.argv[2] + r')"\) = 0', line)
    if m: sys.exit(0 if m.group(1) in synced else 1)
sys.exit(1)
PY
    rm -f "$work/durable.$ext"
done

# standard output on a full disk
cli_cmd_label="stdout"
full() {   # full ARGS...: drender ARGS > /dev/full must fail and say so
    (cd "$work" && "$DRENDER" "$@" >/dev/full 2>"$tmp/err")
    rc=$?
    last_cmd="drender $* > /dev/full"
    : >"$tmp/out"
    expect_rc 1 "$1 with stdout on a full device"
    expect_mentions "standard output|No space left on device" "$1 with stdout on a full device"
}
full params "$box"
full params "$box" --json
full render "$box" --res 8x8 --spp 1 -o "$tmp/r.png" --json
full grad "$box" --param "$B" --res 8x8 --spp 1 --target "$tmp/target.exr" --res 16x16
full fdcheck "$box" --param "$B" --res 8x8 --spp 2 --batches 4
full optimize "$box" --param "$B" --target "$tmp/target.exr" --res 16x16 --spp 2 --iters 1 --json --out-dir "$tmp/o"
# (a long run stops at its first lost line, checkpoint written, not at the end)
full optimize "$box" --param "$B" --target "$tmp/target.exr" --res 16x16 --spp 2 --iters 40 --json --out-dir "$tmp/o40"
expect_mentions "stopped after iteration 1, checkpoint written" "optimize --json --iters 40 with stdout on a full device"
rows=$(($(wc -l <"$tmp/o40/loss.csv") - 1))
[ "$rows" -eq 1 ] || fail "optimize --json --iters 40 > /dev/full: ran $rows iterations (expected to stop after 1)"
grep -qx "iteration 1" "$tmp/o40/checkpoint.txt" 2>/dev/null ||
    fail "optimize --json --iters 40 > /dev/full: no checkpoint of iteration 1"
full compare "$box" --param "$B" --spp 1 --res 8x8 --estimators prb -o "$tmp/c" --json
full --help
full help render
printf 'params %s\n' "$box" >"$tmp/jobs"
full batch "$tmp/jobs"
echo "cli_write_failures: passed"
