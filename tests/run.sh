#!/usr/bin/env bash
# Runs every test: the compiled unit tests (build/tests/test_*) and the
# command-line tests (tests/cli_*.sh), one process each, and closes with
# "N passed, N failed". TESTS="name ..." limits the run to those tests. Exit
# status is non-zero if any failed or none ran.
#
# TEST_JOBS tests run at a time (default: one per CPU). Most tests keep one
# CPU busy, so on a 2-core machine two at a time take about half as long;
# under the sanitizers that is what keeps `.ci/run` well inside its time.
# Every test has its own temporary directory and log, and the one shared
# install (the glTF validator's, tests/lib/cli.sh) takes a lock. The
# results are printed in the tests' order whatever order they end in, so
# logs compare line by line; TEST_JOBS=1 runs them one after the other.
#
# A test that runs past TEST_TIMEOUT seconds (default 1800: the slowest,
# test_reverse_stderr under the sanitizers, took 808-939 s beside the others
# on a 2-core machine; most take under a minute) is stopped and fails, so a
# hang costs one test instead of the whole run.
set -u
timeout_s=${TEST_TIMEOUT:-1800}
build=${BUILD:-build}
jobs=${TEST_JOBS:-$(nproc 2>/dev/null || echo 1)}
case "$jobs" in '' | *[!0-9]* | 0) echo "TEST_JOBS=$jobs: expected a positive whole number" >&2; exit 2 ;; esac
cd "$(dirname "$0")/.."
export DRENDER="${DRENDER:-$PWD/$build/drender}"
export DR_TESTDIR="$PWD/tests" DR_SCENES="$PWD/scenes"
log_dir="$build/test-logs"; mkdir -p "$log_dir"

# The tests to run, in order.
names=() paths=()
for t in "$build"/tests/test_* tests/cli_*.sh; do
    [ -f "$t" ] || continue
    case "$t" in *.sh) ;; *) [ -x "$t" ] || continue ;; esac   # skip build/tests/*.o, *.d
    name=$(basename "$t")
    # TESTS="test_a cli_b" runs only the named tests (for quick iteration)
    if [ -n "${TESTS:-}" ]; then case " $TESTS " in *" ${name%.sh} "*|*" $name "*) ;; *) continue ;; esac; fi
    names+=("$name"); paths+=("$t")
done

# run_one I: test I, its output in its log, "EXIT SECONDS" in its .result
# (written last, through a rename, so that a result seen is complete).
run_one() {
    local name=${names[$1]} t=${paths[$1]} start=$EPOCHREALTIME rc
    rm -f "$log_dir/$name.result"
    if [ "${t%.sh}" != "$t" ]; then
        timeout --kill-after=10 "$timeout_s" bash "$t" >"$log_dir/$name.log" 2>&1
    else
        timeout --kill-after=10 "$timeout_s" "$t" >"$log_dir/$name.log" 2>&1
    fi
    rc=$?
    [ $rc -eq 124 ] && echo "(stopped after $timeout_s s: TEST_TIMEOUT)" >>"$log_dir/$name.log"
    awk -v a="$start" -v b="$EPOCHREALTIME" -v rc="$rc" 'BEGIN{printf "%d %.1f\n", rc, b-a}' \
        >"$log_dir/$name.result.tmp"
    mv "$log_dir/$name.result.tmp" "$log_dir/$name.result"
}

passed=0 failed=0 next_print=0
# Prints the results of the tests from next_print on that have ended, in order.
print_ended() {
    local name rc secs
    while [ "$next_print" -lt "${#names[@]}" ]; do
        name=${names[$next_print]}
        [ -f "$log_dir/$name.result" ] || return 0
        read -r rc secs <"$log_dir/$name.result"
        if [ "$rc" -eq 0 ]; then
            passed=$((passed + 1)); printf 'PASS %-34s %6ss\n' "$name" "$secs"
        else
            failed=$((failed + 1))
            printf 'FAIL %-34s %6ss (exit %d)\n' "$name" "$secs" "$rc"
            sed 's/^/    | /' "$log_dir/$name.log" | tail -n 25
        fi
        next_print=$((next_print + 1))
    done
}

for name in "${names[@]}"; do rm -f "$log_dir/$name.result"; done
trap 'kill $(jobs -p) 2>/dev/null; exit 130' INT TERM
running=0
for i in "${!names[@]}"; do
    if [ "$running" -ge "$jobs" ]; then
        wait -n
        running=$((running - 1))
        print_ended
    fi
    run_one "$i" &
    running=$((running + 1))
done
wait
print_ended
# (a test whose result is missing, which only a killed runner leaves: failed)
for name in "${names[@]:$next_print}"; do
    failed=$((failed + 1)); printf 'FAIL %-34s (no result)\n' "$name"
done
echo "$passed passed, $failed failed"
[ $failed -eq 0 ] && [ $passed -gt 0 ]
