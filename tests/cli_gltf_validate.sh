#!/usr/bin/env bash
# Runs the Khronos glTF validator on what drender writes: the scenes written by
# dr_gltf_write (build/tests/test_gltf_write DIR keeps its .gltf/.glb outputs
# in DIR) and the bundled scenes/*.gltf. Zero errors are required; warnings and
# infos are printed. Run by tests/run.sh (env: BUILD, DR_TESTDIR, DR_SCENES);
# also runs alone from anywhere.
#
# The validator is the npm package gltf-validator (pinned in tests/lib/cli.sh),
# installed on first use into build/node (outside git; needs node, npm and the npm registry).
# This test does not skip: without node/npm it fails with a message naming
# what to install (scripts/install-deps.sh installs Debian's nodejs and npm).
set -u
# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
export DR_TESTDIR DR_SCENES
cd "$cli_root" || exit 1
build=${BUILD:-build}

ensure_gltf_validator

tester="$build/tests/test_gltf_write"
[ -x "$tester" ] || fail "$tester is missing (make $tester)"
cli_setup gltf-validate
cd "$cli_root" || exit 1   # $build may be relative to the top directory
out=$work

"$tester" "$out" >"$out/test.log" 2>&1 || { cat "$out/test.log" >&2; fail "$tester $out failed"; }

shopt -s nullglob
written=("$out"/*.gltf "$out"/*.glb)
[ ${#written[@]} -ge 4 ] || fail "expected written .gltf and .glb files in $out, found ${#written[@]}"
bundled=("$DR_SCENES"/*.gltf "$DR_SCENES"/*.glb)
[ ${#bundled[@]} -ge 1 ] || fail "no bundled scenes in $DR_SCENES"

validate_gltf "${written[@]}" "${bundled[@]}" ||
    fail "the glTF validator reports errors (above)"
echo "validated ${#written[@]} written and ${#bundled[@]} bundled files: no errors"
