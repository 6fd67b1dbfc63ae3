#!/usr/bin/env bash
# Runs the Khronos glTF validator on what drender writes: the scenes written by
# dr_gltf_write (build/tests/test_gltf_write DIR keeps its .gltf/.glb outputs
# in DIR) and the bundled scenes/*.gltf. Zero errors are required; warnings and
# infos are printed. Run by tests/run.sh (env: BUILD, DR_TESTDIR, DR_SCENES);
# also runs alone from anywhere.
#
# The validator is the npm package gltf-validator (pinned below), installed on
# first use into build/node (outside git; needs node, npm and the npm registry).
# This test does not skip: without node/npm it fails with a message naming
# what to install (scripts/install-deps.sh installs Debian's nodejs and npm).
set -u
cd "$(dirname "$0")/.." || exit 1
build=${BUILD:-build}
export DR_TESTDIR="${DR_TESTDIR:-$PWD/tests}" DR_SCENES="${DR_SCENES:-$PWD/scenes}"
validator_pkg="gltf-validator@2.0.0-dev.3.10"
node_dir="$PWD/build/node"
export GLTF_VALIDATOR_DIR="$node_dir"

fail() { echo "FAIL: $*" >&2; exit 1; }

command -v node >/dev/null 2>&1 || fail "node is not installed (Debian: apt-get install nodejs npm, or scripts/install-deps.sh)"
if [ ! -f "$node_dir/node_modules/gltf-validator/package.json" ]; then
    command -v npm >/dev/null 2>&1 || fail "npm is not installed (Debian: apt-get install npm)"
    mkdir -p "$node_dir" || fail "cannot create $node_dir"
    # one installer at a time (make test and make sanitize may run together)
    (
        flock 9
        [ -f "$node_dir/node_modules/gltf-validator/package.json" ] ||
            npm install --no-audit --no-fund --prefix "$node_dir" "$validator_pkg" >&2
    ) 9>"$node_dir/.install-lock" || fail "npm install --prefix $node_dir $validator_pkg failed"
fi

tester="$build/tests/test_gltf_write"
[ -x "$tester" ] || fail "$tester is missing (make $tester)"
out=$(mktemp -d "${TMPDIR:-/tmp}/drender-gltf-validate.XXXXXX") || exit 1
trap 'rm -rf "$out"' EXIT
trap 'exit 130' INT TERM

"$tester" "$out" >"$out/test.log" 2>&1 || { cat "$out/test.log" >&2; fail "$tester $out failed"; }

shopt -s nullglob
written=("$out"/*.gltf "$out"/*.glb)
[ ${#written[@]} -ge 4 ] || fail "expected written .gltf and .glb files in $out, found ${#written[@]}"
bundled=("$DR_SCENES"/*.gltf "$DR_SCENES"/*.glb)
[ ${#bundled[@]} -ge 1 ] || fail "no bundled scenes in $DR_SCENES"

node tests/validate_gltf.mjs "${written[@]}" "${bundled[@]}" ||
    fail "the glTF validator reports errors (above)"
echo "validated ${#written[@]} written and ${#bundled[@]} bundled files: no errors"
