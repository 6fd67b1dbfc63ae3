#!/usr/bin/env bash
# Runs every test: the compiled unit tests (build/tests/test_*) and the
# command-line tests (tests/cli_*.sh), one process each, and closes with
# "N passed, N failed". TESTS="name ..." limits the run to those tests. Exit status is non-zero if any failed or none ran.
# A test that runs past TEST_TIMEOUT seconds (default 1200: the slowest takes
# about 30 s, a few minutes under the sanitizers) is stopped and fails, so a
# hang costs one test instead of the whole run.
set -u
timeout_s=${TEST_TIMEOUT:-1200}
build=${BUILD:-build}
cd "$(dirname "$0")/.."
export DRENDER="${DRENDER:-$PWD/$build/drender}"
export DR_TESTDIR="$PWD/tests" DR_SCENES="$PWD/scenes"
passed=0 failed=0 failed_names=()
log_dir="$build/test-logs"; mkdir -p "$log_dir"
for t in "$build"/tests/test_* tests/cli_*.sh; do
    [ -f "$t" ] || continue
    case "$t" in *.sh) ;; *) [ -x "$t" ] || continue ;; esac   # skip build/tests/*.o, *.d
    name=$(basename "$t")
    # TESTS="test_a cli_b" runs only the named tests (for quick iteration)
    if [ -n "${TESTS:-}" ]; then case " $TESTS " in *" ${name%.sh} "*|*" $name "*) ;; *) continue ;; esac; fi
    start=$EPOCHREALTIME
    if [ "${t%.sh}" != "$t" ]; then
        timeout --kill-after=10 "$timeout_s" bash "$t" >"$log_dir/$name.log" 2>&1
    else
        timeout --kill-after=10 "$timeout_s" "$t" >"$log_dir/$name.log" 2>&1
    fi
    rc=$?
    [ $rc -eq 124 ] && echo "(stopped after $timeout_s s: TEST_TIMEOUT)" >>"$log_dir/$name.log"
    secs=$(awk -v a="$start" -v b="$EPOCHREALTIME" 'BEGIN{printf "%.1f", b-a}')
    if [ $rc -eq 0 ]; then
        passed=$((passed + 1)); printf 'PASS %-34s %6ss\n' "$name" "$secs"
    else
        failed=$((failed + 1)); failed_names+=("$name")
        printf 'FAIL %-34s %6ss (exit %d)\n' "$name" "$secs" "$rc"
        sed 's/^/    | /' "$log_dir/$name.log" | tail -n 25
    fi
done
echo "$passed passed, $failed failed"
[ $failed -eq 0 ] && [ $passed -gt 0 ]
