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
[ $# -gt 0 ] || set -- gltf checkpoint cli image ktx2
declare -A max_len=([gltf]=65536 [checkpoint]=4096 [cli]=512 [image]=16384 [ktx2]=16384)
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
    # Leaks: OpenImageIO's own (tests/lsan.supp) can only be suppressed with
    # full malloc stacks (fast_unwind_on_malloc=0), which costs the targets
    # that decode images (gltf, image) most of their speed. Those fuzz with
    # leak detection off, and the whole corpus (seeds and every new input) is
    # then replayed once with it on (-runs=0) before the target counts as clean.
    leak_opts=detect_leaks=1:fast_unwind_on_malloc=0
    case $t in gltf | image) fuzz_leaks=detect_leaks=0 ;; *) fuzz_leaks=$leak_opts ;; esac
    # quarantine_size_mb: freed blocks stay poisoned longer (1 GiB, not 256 MiB),
    # so that a write by the uninstrumented image libraries into a freed or
    # neighbouring block is caught near the input that made it: that is how
    # OpenImageIO 2.4's IFF heap corruption showed itself (FUZZ_QUARANTINE_MB).
    fuzz_run() {   # fuzz_run ASAN_LEAK_OPTIONS LIBFUZZER_ARGS...
        local leaks=$1
        shift
        ASAN_OPTIONS=$leaks:allocator_may_return_null=1:quarantine_size_mb=${FUZZ_QUARANTINE_MB:-1024} \
        LSAN_OPTIONS=suppressions=$PWD/tests/lsan.supp \
        UBSAN_OPTIONS=print_stacktrace=1 \
            "$bin" "$@" -timeout=10 -rss_limit_mb=2560 -max_len="${max_len[$t]:-65536}" \
            -close_fd_mask=3 -print_final_stats=1 -artifact_prefix="$build/crash-$t-" \
            "$build/corpus/$t" "fuzz/corpus/$t"
    }
    # -close_fd_mask=3: the target's own stdout/stderr (drender's messages) are
    # closed; libFuzzer and the sanitizers still report on a duplicate of stderr.
    fuzz_run "$fuzz_leaks" -max_total_time="$secs" >"$log" 2>&1
    rc=$?
    if [ $rc -eq 0 ] && [ "$fuzz_leaks" != "$leak_opts" ]; then
        echo "fuzz: $t: replaying the corpus with leak detection" >&2
        fuzz_run "$leak_opts" -runs=0 >"$log.leaks" 2>&1
        rc=$?
        [ $rc -eq 0 ] || cat "$log.leaks" >>"$log"
    fi
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | head -1)
    speed=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | head -1)
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
