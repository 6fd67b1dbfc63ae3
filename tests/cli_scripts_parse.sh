#!/usr/bin/env bash
# Every shell script of the project parses (bash -n): the bench's, the
# set-up's, the CI's and the tests' own. `make bench` runs for ten minutes
# before reaching its last parts, and no other test runs the bench, so a
# quoting slip there (an apostrophe inside a single-quoted printf format
# broke bench/run.sh at its part c in 2026-12) went unseen until the next
# bench run. Run by tests/run.sh; also runs alone.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
root=$(cd "$(dirname "$0")/.." && pwd)
cli_setup scripts_parse

# the detector: a script with that very slip must be refused
printf '%s\n' '#!/usr/bin/env bash' "printf '   the threads' seconds: %s\\n' \"\$x\"" 'echo done' >"$tmp/broken.sh"
if bash -n "$tmp/broken.sh" 2>/dev/null; then
    fail "bash -n accepts a script with an unterminated quote; this check would pass vacuously"
fi

checked=0
for f in "$root"/bench/*.sh "$root"/scripts/*.sh "$root"/tests/*.sh "$root"/tests/lib/*.sh "$root"/.ci/run; do
    [ -f "$f" ] || continue
    if ! bash -n "$f" 2>"$tmp/err"; then
        fail "${f#"$root"/} does not parse: $(head -c 400 "$tmp/err")"
    fi
    checked=$((checked + 1))
done
[ "$checked" -ge 20 ] || fail "only $checked scripts found to check (expected the bench's, scripts/ and tests/)"
echo "cli_scripts_parse: all $checked scripts parse"
