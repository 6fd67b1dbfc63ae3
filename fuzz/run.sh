#!/usr/bin/env bash
# Runs libFuzzer targets (make fuzz): fuzz/run.sh TARGET...
# Each build-fuzz/fuzz_TARGET runs for FUZZ_SECONDS (default 60) from the
# committed seeds fuzz/corpus/TARGET plus what earlier runs found
# (build-fuzz/corpus/TARGET, where new inputs go). A crash, leak, sanitizer
# report, timeout or out-of-memory stops that target and leaves the input in
# build-fuzz/crash-TARGET-*. Prints executions, exec/s and crashes per target
# and exits non-zero when any target crashed.
set -u
cd "$(dirname "$0")/.."
build=${FUZZ_BUILD:-build-fuzz}
secs=${FUZZ_SECONDS:-60}
[ $# -gt 0 ] || set -- gltf checkpoint cli image
declare -A max_len=([gltf]=65536 [checkpoint]=4096 [cli]=512 [image]=16384)
failed=0
summary=()
for t in "$@"; do
    bin=$build/fuzz_$t
    [ -x "$bin" ] || { echo "fuzz: $bin missing (make fuzz-build)" >&2; exit 2; }
    mkdir -p "$build/corpus/$t"
    log=$build/fuzz-$t.log
    echo "fuzz: $t for ${secs}s (log: $log)" >&2
    # -close_fd_mask=3: the target's own stdout/stderr (drender's messages) are
    # closed; libFuzzer and the sanitizers still report on a duplicate of stderr.
    # Leaks inside OpenImageIO (tests/lsan.supp) are suppressed as in make
    # sanitize; they need full stacks (fast_unwind_on_malloc=0) to be matched.
    ASAN_OPTIONS=detect_leaks=1:allocator_may_return_null=1:fast_unwind_on_malloc=0 \
    LSAN_OPTIONS=suppressions=$PWD/tests/lsan.supp \
    UBSAN_OPTIONS=print_stacktrace=1 \
        "$bin" -max_total_time="$secs" -timeout=10 -rss_limit_mb=2560 -max_len="${max_len[$t]:-65536}" \
        -close_fd_mask=3 -print_final_stats=1 -artifact_prefix="$build/crash-$t-" \
        "$build/corpus/$t" "fuzz/corpus/$t" >"$log" 2>&1
    rc=$?
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
    speed=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
    crashes=0
    if [ $rc -ne 0 ]; then
        crashes=1; failed=1
        grep -E "^(==[0-9]+==ERROR|SUMMARY|.*runtime error|artifact_prefix|Test unit written)" "$log" | head -8 >&2
    fi
    summary+=("$(printf '%-11s %12s executions %8s exec/s  %d crash%s' "$t" "${execs:-?}" "${speed:-?}" \
        $crashes "$([ $crashes -eq 1 ] && echo "" || echo "es")")")
done
printf '%s\n' "${summary[@]}"
exit $failed
