#!/usr/bin/env bash
# drender batch: command lines run in one process. Each job's output equals
# the same command run alone; quoting is a shell's; every line is checked
# before any runs; a failing job stops the batch (or not, --keep-going) and
# is named by FILE:LINE; the exit status is the first failure's.
# Run by tests/run.sh (env: DRENDER = the binary); also runs alone.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
cli_setup batch
require_drender

scene=$DR_SCENES/cornell-box.gltf
small=(--res 24x16 --spp 2 --max-depth 3)
same_image() {   # same_image A B WHAT
    idiff -fail 0 -warn 0 "$1" "$2" >/dev/null 2>&1 || fail "$3: $1 and $2 differ"
}

# help lists it; batch --help describes it
run help
expect_in out "batch" "drender help lists batch"
run batch --help
expect_rc 0 "batch --help"
expect_in out "usage: drender batch" "batch --help"
expect_in out "--keep-going" "batch --help names --keep-going"

# --- five commands, with quoting, comments, a leading 'drender' ---------
mkdir "out dir"
cat >jobs.txt <<EOF
# a comment line, then a blank one

render $scene ${small[*]} --seed 1 --json -o 'out dir/a b.exr'
drender render "$scene" ${small[*]} --seed 2 -o out\\ 2.exr   # a trailing comment
params $scene --json
grad $scene --param /materials/0/pbrMetallicRoughness/baseColorFactor ${small[*]} -o "d\"q.exr"
render $scene ${small[*]} --seed 3 --json -o three.exr
EOF
run batch jobs.txt
expect_rc 0 "batch of five jobs"
[ -f "out dir/a b.exr" ] || fail "batch: 'out dir/a b.exr' (single quotes) not written"
[ -f "out 2.exr" ] || fail "batch: 'out 2.exr' (backslash-escaped blank) not written"
[ -f 'd"q.exr' ] || fail "batch: 'd\"q.exr' (escaped double quote) not written"
[ -f three.exr ] || fail "batch: three.exr not written"
# stdout: render's JSON object, params', grad's line, render's
python3 - "$tmp/out" <<'PY' || fail "batch stdout is not render's JSON, params', grad's line, render's"
import json, sys
lines = [l for l in open(sys.argv[1]).read().splitlines() if l.strip()]
objs = [json.loads(l) for l in lines if l.startswith("{")]
assert [o["command"] for o in objs] == ["render", "params", "render"], [o.get("command") for o in objs]
assert any(l.startswith('d"q.exr: d image') for l in lines), lines
assert objs[2]["output"] == "three.exr"
# a job's start-up counts from the job's start: were it the process's age, the
# last job's would exceed the whole first job (which loaded the image library)
assert objs[2]["time"]["startup"] < objs[0]["time"]["total"], (objs[2]["time"], objs[0]["time"])
PY
# each output equals the command run alone
mkdir alone
"$DRENDER" render "$scene" "${small[@]}" --seed 1 -o alone/1.exr 2>/dev/null || fail "render alone (seed 1) failed"
"$DRENDER" render "$scene" "${small[@]}" --seed 2 -o alone/2.exr 2>/dev/null || fail "render alone (seed 2) failed"
"$DRENDER" grad "$scene" --param /materials/0/pbrMetallicRoughness/baseColorFactor "${small[@]}" -o alone/g.exr \
    >/dev/null 2>&1 || fail "grad alone failed"
same_image "out dir/a b.exr" alone/1.exr "batch job 1 vs render alone"
same_image "out 2.exr" alone/2.exr "batch job 2 vs render alone"
same_image 'd"q.exr' alone/g.exr "batch grad job vs grad alone"

# standard input, as '-' and by default
printf 'render %s %s --seed 4 -o in1.exr\n' "$scene" "${small[*]}" >stdin.txt
run batch - <stdin.txt
expect_rc 0 "batch - (stdin)"
"$DRENDER" batch <stdin.txt >/dev/null 2>&1 || fail "batch with no FILE (stdin) failed"
[ -f in1.exr ] || fail "batch from stdin: in1.exr not written"

# --- every line is checked before any runs: nothing written ---------------
bad_line() {   # bad_line LINE3 NEEDLES WHAT: line 3 is bad; lines 1-2 must not run
    rm -f early.exr
    printf 'render %s %s -o early.exr\n\n%s\n' "$scene" "${small[*]}" "$1" >bad.txt
    run batch bad.txt
    check_failed 2 "bad.txt:3|$2"
    [ ! -e early.exr ] || fail "$3: line 1 ran before line 3 was checked"
}
bad_line "render 'unterminated" "unterminated" "unterminated quote"
bad_line "render $scene -o x.exr > log" "'>'|shell syntax" "a redirection"
bad_line "render scenes/*.gltf" "'*'" "a glob"
bad_line "rendr $scene" "rendr|not a drender command" "an unknown command"
bad_line "batch other.txt" "cannot run 'batch'" "batch in a batch"
bad_line "render a\\" "continuation" "a trailing backslash"
bad_line "drender   # nothing else" "without a command" "'drender' alone"

# --- a failing job: named, stops the batch; --keep-going goes on --------
printf 'render %s %s -o f1.exr\nrender missing.gltf -o f2.exr\nrender %s %s -o f3.exr\n' \
    "$scene" "${small[*]}" "$scene" "${small[*]}" >fail.txt
run batch fail.txt
expect_rc 3 "a job that cannot read its scene (exit 3, its own status)"
expect_mentions "missing.gltf|fail.txt:2|render"
[ -f f1.exr ] || fail "the job before the failing one did not run"
[ ! -e f3.exr ] || fail "the job after the failing one ran without --keep-going"
run batch --keep-going fail.txt
expect_rc 3 "--keep-going: exit status of the first failure"
expect_mentions "fail.txt:2|going on"
[ -f f3.exr ] || fail "--keep-going: the job after the failing one did not run"

# --- usage and input errors of batch itself ----------------------------
run batch no-such-file.txt
check_failed 3 "no-such-file.txt"
run batch a.txt b.txt
check_failed 2 "one FILE"
run batch --bogus
check_failed 2 "--bogus"

echo "cli_batch: all passed"
