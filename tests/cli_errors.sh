#!/usr/bin/env bash
# drender render, the failing paths: every case must exit non-zero with the
# code below, print a message on stderr naming the option or the file (and
# the JSON path inside a glTF), print nothing on stdout, and leave nothing
# behind: no output file, no temporary (.NAME.tmp*) file, and a pre-existing
# output file keeps its content.
# Run by tests/run.sh (env: DRENDER = the binary, DR_TESTDIR = tests/);
# also runs alone. Scenes: tests/data/gltf/ (make_scenes.py) and tests/data/cli/.
#
# Expected exit codes (cli/cli.h, man/drender.1):
#   2 = usage error: bad option values (--spp 0, --res 10, --camera beyond
#       the scene's cameras, -o with an unknown format), unknown option/command
#   3 = input error: scene or image missing or malformed
#   1 = other failures: e.g. the output file cannot be written
#   0 = success (cli_render.sh)
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
gltf=$DR_TESTDIR/data/gltf
clidata=$DR_TESTDIR/data/cli
cli_setup errors
ncases=0
# expect_fail CODE "NEEDLE1|NEEDLE2|..." ARGS...
#   runs `drender render ARGS...` in an empty directory and checks the exit
#   code, that stderr contains every NEEDLE (fixed strings), that stdout is
#   empty and that the directory is still empty afterwards.
expect_fail() {
    local want=$1 needles=$2
    shift 2
    ncases=$((ncases + 1))
    run render "$@"
    check_failed "$want" "$needles"
    local left
    left=$(ls -A "$work")
    [ -z "$left" ] || fail "expected no files left in the output directory, found: $left"
}

require_drender
[ -f "$gltf/bad_json.gltf" ] && [ -f "$clidata/missing_texture.gltf" ] || fail "test scenes not found under $DR_TESTDIR/data"

R="--res 16x16 --spp 1"
tri=$gltf/tex_nosource.gltf   # (used only where the scene does not matter)

# ---- usage errors (2): bad option values, found before any work ----
expect_fail 2 "--spp|0" --spp 0 -o out.png
expect_fail 2 "--spp|-3" --spp -3 -o out.png
expect_fail 2 "--spp|abc" --spp abc -o out.png
expect_fail 2 "--spp|1.5" --spp 1.5 -o out.png
expect_fail 2 "--res|0x5" --res 0x5 --spp 1 -o out.png
expect_fail 2 "--res|10" --res 10 --spp 1 -o out.png
expect_fail 2 "--res|10x" --res 10x --spp 1 -o out.png
expect_fail 2 "--res|x10" --res x10 --spp 1 -o out.png
expect_fail 2 "--max-depth|0" --max-depth 0 $R -o out.png
expect_fail 2 "--threads|-1" --threads -1 $R -o out.png
expect_fail 2 "--seed|-1" --seed -1 $R -o out.png
# --camera beyond the cameras of the file: the message gives the count
expect_fail 2 "--camera 5|has 1 camera|cornell-box" --camera 5 $R -o out.png
expect_fail 2 "--camera 0|has 0 cameras|env_map.gltf" "$gltf/env_map.gltf" --camera 0 $R -o out.png
# an output format OpenImageIO cannot write: the message names the file
expect_fail 2 "out.xyz" $R -o out.xyz
expect_fail 2 "noextension" $R -o noextension
# more than one scene
expect_fail 2 "extra.gltf" "$gltf/basic.gltf" extra.gltf $R -o out.png

# ---- input errors (3): the message names the file and the JSON path ----
expect_fail 3 "does-not-exist.gltf" "$work/does-not-exist.gltf" $R -o out.png
expect_fail 3 "$clidata" "$clidata" $R -o out.png                      # a directory
expect_fail 3 "bad_json.gltf" "$gltf/bad_json.gltf" $R -o out.png      # malformed JSON
expect_fail 3 "accessor_range.gltf|/accessors/0" "$gltf/accessor_range.gltf" $R -o out.png
expect_fail 3 "missing_bin.gltf|/buffers/1|nothere.bin" "$gltf/missing_bin.gltf" $R -o out.png
expect_fail 3 "points.gltf|/meshes/1/primitives/0/mode|points" "$gltf/points.gltf" $R -o out.png
expect_fail 3 "tex_nosource.gltf|/textures/0|source" "$tri" $R -o out.png
expect_fail 3 "missing_texture.gltf|/images/0|nothere.png" "$clidata/missing_texture.gltf" $R -o out.png
expect_fail 3 "truncated_texture.gltf|/images/0|truncated.png" "$clidata/truncated_texture.gltf" $R -o out.png
# images are decoded in parallel: with two broken ones the first in file
# order is named (/images/1), whichever thread finishes first
multi=$tmp/multi-image
mkdir -p "$multi"
cp "$gltf/checker.png" "$multi/good.png"
cp "$clidata/truncated.png" "$multi/bad1.png"
cp "$clidata/truncated.png" "$multi/bad2.png"
python3 - "$clidata/truncated_texture.gltf" "$multi/multi_image.gltf" <<'PY'
import json, sys
g = json.load(open(sys.argv[1]))
g["images"] = [{"uri": "good.png"}, {"uri": "bad1.png"}, {"uri": "bad2.png"}]
g["textures"] = [{"source": 0}, {"source": 1}, {"source": 2}]
json.dump(g, open(sys.argv[2], "w"))
PY
for i in 1 2 3; do
    expect_fail 3 "multi_image.gltf|/images/1|bad1.png" "$multi/multi_image.gltf" $R -o out.png
    grep -q "/images/2" "$tmp/err" && fail "the second broken image was named instead of the first"
done
expect_fail 3 "bad_env.gltf|/extensions/DR_environment/uri|nosky.hdr" "$gltf/bad_env.gltf" $R -o out.png
expect_fail 3 "truncated.glb" "$clidata/truncated.glb" $R -o out.png   # binary glTF cut short
expect_fail 3 "empty.gltf" "$clidata/empty.gltf" $R -o out.png         # zero bytes

# ---- other failures (1): the output cannot be written ----
expect_fail 1 "/nonexistent-dir/x.png" $R -o /nonexistent-dir/x.png
# the target is a directory: the rename fails, and the temporary is removed
mkdir "$work/dir.png"
run render $R -o dir.png
[ "$rc" -eq 1 ] || fail "-o dir.png (a directory): expected exit 1, got $rc"
grep -qF "dir.png" "$tmp/err" || fail "-o dir.png (a directory): expected the message to name dir.png"
[ -d dir.png ] && [ -z "$(ls -A dir.png)" ] || fail "-o dir.png: the directory was changed"
[ "$(ls -A "$work")" = dir.png ] || fail "-o dir.png: expected no temporary file left, found: $(ls -A "$work")"
rmdir dir.png
ncases=$((ncases + 1))

# ---- the image library is a plugin loaded on demand (core/image_plugin.h) ----
# (the sanitizer build links it in instead, see the Makefile: nothing to check there)
if ldd "$DRENDER" 2>/dev/null | grep -q libOpenImageIO; then
    echo "note: $DRENDER links OpenImageIO (sanitizer build): the plugin checks are skipped"
else
# missing: exit 1 with a message that says what was not found and how to point at it
# the bundled Cornell box without its texture: a scene that needs no image to load
python3 - "$DR_SCENES/cornell-box.gltf" "$tmp/notex.gltf" <<'PY'
import json, sys
src, dst = sys.argv[1], sys.argv[2]
g = json.load(open(src))
for k in ("textures", "images", "samplers"):
    g.pop(k, None)
for m in g.get("materials", []):
    for d in (m, m.get("pbrMetallicRoughness", {})):
        for k in [k for k in d if k.endswith("Texture")]:
            del d[k]
json.dump(g, open(dst, "w"))
PY
cp "$DR_SCENES/cornell-box.bin" "$tmp/"
DRENDER_IMAGE_LIB=/nonexistent/libdrender-image.so expect_fail 1 "image library|/nonexistent/libdrender-image.so" "$tmp/notex.gltf" $R -o x.png
# a scene with textures needs it to load: exit 3 (the scene cannot be read), naming the image
DRENDER_IMAGE_LIB=/nonexistent/libdrender-image.so expect_fail 3 "/images/0|image library" $R -o x.png
# commands that need no image never load OpenImageIO (the 0.23 s start-up it costs)
for args in "--version" "render --help" "grad --help" "help"; do
    n=$(LD_DEBUG=files "$DRENDER" $args 2>&1 >/dev/null | grep -c "libOpenImageIO\.so") || true
    [ "$n" -eq 0 ] || fail "drender $args loaded OpenImageIO"
    ncases=$((ncases + 1))
done
# ...and commands that do, load it (once) and work
n=$(LD_DEBUG=files "$DRENDER" render $R -o "$work/ok.png" 2>&1 >/dev/null | grep -c "calling init: .*libOpenImageIO\.so") || true
[ "$n" -eq 1 ] || fail "render: expected OpenImageIO to be initialised once, saw $n"
[ -s "$work/ok.png" ] || fail "render with the plugin wrote no image"
rm -f "$work/ok.png"; ncases=$((ncases + 1))

fi

# ---- a failed render leaves an existing output file untouched ----
printf 'precious bytes, not an image\n' >"$tmp/precious"
keeps_output() {   # keeps_output ARGS...: a failing render must not touch out.png
    cp "$tmp/precious" out.png
    run render "$@" $R -o out.png
    [ "$rc" -ne 0 ] || fail "expected failure"
    cmp -s "$tmp/precious" out.png || fail "a pre-existing out.png was modified or removed"
    [ "$(ls -A "$work")" = out.png ] || fail "stray files left: $(ls -A "$work")"
    ncases=$((ncases + 1))
}
keeps_output "$work/does-not-exist.gltf"
keeps_output "$gltf/bad_json.gltf"
keeps_output "$clidata/truncated_texture.gltf"
keeps_output --spp 0
keeps_output --camera 3
rm -f out.png

echo "cli_errors: all $ncases cases passed"
