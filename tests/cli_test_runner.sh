#!/usr/bin/env bash
# tests/run.sh itself, on a tree of made-up tests (a copy of run.sh beside
# them, as it finds its tests relative to itself): with TEST_JOBS=2 two tests
# run at once (one waits for a file the other writes), the results come in
# the tests' order although they end in another, a failing test's exit code
# and log tail are shown and counted, the closing line and the exit status
# say so, TESTS= picks tests, and a bad TEST_JOBS is refused.
# Run by tests/run.sh; also runs alone.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
cli_setup test-runner
tree=$tmp/tree
mkdir -p "$tree/tests" "$tree/build/tests"
cp "$DR_TESTDIR/run.sh" "$tree/tests/run.sh"
# (unit tests are executables in build/tests, command-line tests scripts in tests/)
cat >"$tree/build/tests/test_a_waits" <<'EOF'
#!/usr/bin/env bash
# passes only if test_b_signals runs at the same time: it writes the file
for _ in $(seq 100); do [ -f "$SIGNAL" ] && { echo "saw the signal"; exit 0; }; sleep 0.05; done
echo "no signal: the tests ran one after the other"; exit 1
EOF
cat >"$tree/build/tests/test_b_signals" <<'EOF'
#!/usr/bin/env bash
touch "$SIGNAL"; echo signalled
EOF
cat >"$tree/tests/cli_c_fails.sh" <<'EOF'
echo "first line of the failure"
echo "last line of the failure"
exit 7
EOF
cat >"$tree/tests/cli_d_passes.sh" <<'EOF'
exit 0
EOF
chmod +x "$tree/build/tests/test_a_waits" "$tree/build/tests/test_b_signals"
export SIGNAL=$tmp/signal

runner() {   # runner ENV...: runs the copied run.sh; output in $tmp/runner.out, status in $rrc
    rm -f "$SIGNAL"
    env -u TESTS "$@" BUILD=build bash "$tree/tests/run.sh" >"$tmp/runner.out" 2>&1
    rrc=$?
}
show() { sed 's/^/    | /' "$tmp/runner.out" >&2; }

# two at a time: the waiting test sees the signal; results in the tests' order
runner TEST_JOBS=2
[ "$rrc" -ne 0 ] || { show; fail "one test failed, but run.sh exited 0"; }
order=$(grep -E '^(PASS|FAIL) ' "$tmp/runner.out" | awk '{print $1, $2}' | tr '\n' ',')
[ "$order" = "PASS test_a_waits,PASS test_b_signals,FAIL cli_c_fails.sh,PASS cli_d_passes.sh," ] ||
    { show; fail "TEST_JOBS=2: expected the four results in the tests' order, got: $order"; }
grep -q '^FAIL cli_c_fails.sh .*(exit 7)$' "$tmp/runner.out" || { show; fail "the failure's exit code is not shown"; }
grep -q '^    | first line of the failure$' "$tmp/runner.out" && grep -q '^    | last line of the failure$' "$tmp/runner.out" ||
    { show; fail "the failing test's log is not shown"; }
[ "$(tail -n 1 "$tmp/runner.out")" = "3 passed, 1 failed" ] || { show; fail "expected the closing line '3 passed, 1 failed'"; }
grep -q "saw the signal" "$tree/build/test-logs/test_a_waits.log" || fail "test_a_waits' log was not kept"

# one at a time: the waiting test, started first, cannot see the signal
runner TEST_JOBS=1
grep -q '^FAIL test_a_waits ' "$tmp/runner.out" || { show; fail "TEST_JOBS=1 ran the tests at the same time"; }
[ "$(tail -n 1 "$tmp/runner.out")" = "2 passed, 2 failed" ] || { show; fail "TEST_JOBS=1: expected '2 passed, 2 failed'"; }

# TESTS= picks tests by name, with or without .sh; all passing: status 0
runner TEST_JOBS=2 TESTS="test_b_signals cli_d_passes"
[ "$rrc" -eq 0 ] && [ "$(tail -n 1 "$tmp/runner.out")" = "2 passed, 0 failed" ] ||
    { show; fail "TESTS='test_b_signals cli_d_passes': expected 2 passed and status 0 (got $rrc)"; }
# none chosen: 0 passed is a failure
runner TESTS=no_such_test
[ "$rrc" -ne 0 ] && [ "$(tail -n 1 "$tmp/runner.out")" = "0 passed, 0 failed" ] ||
    { show; fail "a run of no test must fail"; }
# a bad TEST_JOBS is refused before any test runs
for bad in 0 two -1 1.5; do
    runner TEST_JOBS="$bad"
    [ "$rrc" -eq 2 ] && grep -q "TEST_JOBS" "$tmp/runner.out" && ! grep -qE '^(PASS|FAIL) ' "$tmp/runner.out" ||
        { show; fail "TEST_JOBS='$bad': expected a refusal naming TEST_JOBS and exit 2 (got $rrc)"; }
done
echo "ok"
