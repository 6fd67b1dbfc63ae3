# shellcheck shell=bash disable=SC2034  # sets variables for the scripts that source it
# Shared helpers of the command-line tests tests/cli_*.sh. Sourced, not run
# (tests/run.sh runs only tests/cli_*.sh), first thing in each script, before
# any cd:
#
#   . "$(dirname "$0")/lib/cli.sh"
#
# Sets on sourcing:
#   here        the tests/ directory, cli_root the top directory (absolute)
#   DRENDER     the binary, default build/drender (tests/run.sh passes it)
#   DR_TESTDIR  default tests/, DR_SCENES default scenes/ (not exported)
#   have_oiio, have_python   true or false: oiiotool; python3 with json
# Functions:
#   cli_setup NAME       private temporary directory $tmp (drender-cli-NAME.*,
#                        removed on exit, with a background process whose id
#                        is in $bg_pid killed first), cd into an empty $work
#   require_drender      fails unless $DRENDER is executable
#   run ARGS...          runs drender: stdout -> $tmp/out, stderr -> $tmp/err,
#                        exit code -> $rc, "drender ARGS" -> $last_cmd
#   fail MESSAGE         prints FAIL: MESSAGE (and, after a run, the command
#                        and its output: cli_show_output, which a script may
#                        redefine) and exits 1
#   expect_rc CODE WHAT, expect_in out|err TEXT WHAT, expect_empty out|err WHAT
#   expect_mentions "N1|N2|..." [WHAT]: stderr contains every needle (fixed strings)
#   check_failed CODE "N1|N2|...": after run, exit CODE, an error message
#                        naming every needle, nothing on stdout
#   json_check FILE EXPR   the file is one JSON object d and the Python
#                        expression EXPR over d (math, json available) holds;
#                        otherwise fail, with the object on stderr
#   find_samples         sets $samples to ../shared/gltf-samples beside the
#                        checkout (DR_TESTDIR/../../ or, in a work tree one level
#                        deeper, ../../../), or fails naming it
#   ensure_gltf_validator  installs the Khronos glTF validator into build/node
#   validate_gltf FILE...  runs it (tests/validate_gltf.mjs): status 0 = no errors
#
# Settings a script may change after sourcing: cli_cmd_label (fail's label of
# the last command, default "command"), cli_out_bytes (how much of stdout fail
# shows, default 2000).

here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cli_root=$(cd "$here/.." && pwd)
DRENDER=${DRENDER:-$cli_root/build/drender}
DR_TESTDIR=${DR_TESTDIR:-$here}
DR_SCENES=${DR_SCENES:-$cli_root/scenes}
last_cmd=
rc=0
bg_pid=
cli_cmd_label="command"
cli_out_bytes=2000
# oiiotool and python3 are installed by scripts/install-deps.sh: a check that
# needs them must not pass silently where they are missing, so they are required.
have_oiio=true have_python=true
command -v oiiotool >/dev/null 2>&1 || { echo "FAIL: oiiotool is required (scripts/install-deps.sh installs openimageio-tools)"; exit 1; }
python3 -c 'import json' 2>/dev/null || { echo "FAIL: python3 is required (scripts/install-deps.sh installs it)"; exit 1; }

# A misspelt or missing helper or tool must fail the test, not print
# "command not found" and carry on (the scripts do not run with set -e).
# bash runs this handler in a subshell, so it stops the script by signal: the
# TERM trap below exits non-zero.
command_not_found_handle() {
    echo "FAIL: command not found: $1 (a missing helper or tool)" >&2
    kill -TERM $$
    return 127
}

cli_setup() {   # cli_setup NAME
    tmp=$(mktemp -d "${TMPDIR:-/tmp}/drender-cli-$1.XXXXXX") || exit 1
    trap '[ -n "$bg_pid" ] && kill "$bg_pid" 2>/dev/null; rm -rf "$tmp"' EXIT
    trap 'exit 130' INT TERM
    work=$tmp/work
    mkdir "$work" && cd "$work" || exit 1
}

cli_show_output() {
    echo "  --- stdout ---" >&2; head -c "$cli_out_bytes" "$tmp/out" >&2
    echo "  --- stderr ---" >&2; head -c 2000 "$tmp/err" >&2
}
fail() {
    echo "FAIL: $*" >&2
    if [ -n "$last_cmd" ]; then
        echo "  $cli_cmd_label: $last_cmd (exit $rc)" >&2
        cli_show_output
    fi
    exit 1
}
require_drender() {
    [ -x "$DRENDER" ] || fail "drender binary not found or not executable: $DRENDER"
}
run() {   # run ARGS...: stdout -> $tmp/out, stderr -> $tmp/err, exit code -> $rc
    last_cmd="drender $*"
    "$DRENDER" "$@" >"$tmp/out" 2>"$tmp/err" </dev/null
    rc=$?
}
expect_rc() { [ "$rc" -eq "$1" ] || fail "$2: expected exit $1, got $rc"; }
expect_in() {   # expect_in FILE TEXT DESCRIPTION (fixed string)
    grep -qF -- "$2" "$tmp/$1" || fail "$3: expected '$2' in $1"
}
expect_empty() { [ ! -s "$tmp/$1" ] || fail "$2: expected empty $1, got: $(head -c 300 "$tmp/$1")"; }
# expect_mentions "N1|N2|..." [WHAT]: stderr contains every needle
expect_mentions() {
    local n what=${2:+$2: }
    local IFS='|'
    for n in $1; do
        grep -qF -- "$n" "$tmp/err" || fail "${what}expected the message to mention '$n'"
    done
}
# check_failed CODE "N1|N2|...": the last run exited CODE with an error message
# on stderr mentioning every needle, and printed nothing on stdout
check_failed() {
    [ "$rc" -eq "$1" ] || fail "expected exit $1, got $rc"
    [ -s "$tmp/err" ] || fail "expected an error message on stderr, got none"
    expect_mentions "$2"
    [ ! -s "$tmp/out" ] || fail "expected nothing on stdout"
}

# The Khronos glTF validator: npm package gltf-validator (pinned), installed on
# first use into build/node (outside git; needs node, npm and the npm registry).
gltf_validator_pkg="gltf-validator@2.0.0-dev.3.10"
gltf_validator_dir=$cli_root/build/node
find_samples() {
    samples=$DR_TESTDIR/../../shared/gltf-samples
    [ -d "$samples/Box" ] || samples=$DR_TESTDIR/../../../shared/gltf-samples
    [ -d "$samples/Box" ] || fail "the shared glTF sample models (shared/gltf-samples) were not found beside the checkout"
}
ensure_gltf_validator() {
    local node_dir=$gltf_validator_dir
    command -v node >/dev/null 2>&1 || fail "node is not installed (Debian: apt-get install nodejs npm, or scripts/install-deps.sh)"
    [ -f "$node_dir/node_modules/gltf-validator/package.json" ] && return 0
    command -v npm >/dev/null 2>&1 || fail "npm is not installed (Debian: apt-get install npm)"
    mkdir -p "$node_dir" || fail "cannot create $node_dir"
    # one installer at a time (make test and make sanitize may run together)
    (
        flock 9
        [ -f "$node_dir/node_modules/gltf-validator/package.json" ] ||
            npm install --no-audit --no-fund --prefix "$node_dir" "$gltf_validator_pkg" >&2
    ) 9>"$node_dir/.install-lock" || fail "npm install --prefix $node_dir $gltf_validator_pkg failed"
}
validate_gltf() {   # validate_gltf FILE...: prints every issue; status 0 when no file has errors
    GLTF_VALIDATOR_DIR=$gltf_validator_dir node "$here/validate_gltf.mjs" "$@"
}

json_check() {   # json_check FILE PYTHON-EXPR-over-d
    python3 - "$1" "$2" <<'PY' || fail "JSON check failed: $2"
import json, math, sys
d = json.load(open(sys.argv[1]))
if not eval("(" + sys.argv[2] + "\n)", {"math": math, "json": json, "d": d}):
    print(json.dumps(d, indent=1)[:3000], file=sys.stderr)
    sys.exit(1)
PY
}
