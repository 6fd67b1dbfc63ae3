#!/usr/bin/env bash
# drender render, the successful paths: the bundled default scene to every
# output format, --json, --res, determinism across --threads, --seed,
# --camera, and a quiet stderr when stderr is not a terminal.
# Run by tests/run.sh (env: DRENDER = the binary, DR_TESTDIR = tests/);
# also runs alone. Uses oiiotool (openimageio-tools) and python3 if present.
#
# Expected exit codes (cli/cli.h, man/drender.1):
#   0 = success (every render here)
#   2 = usage error (bad option values, unknown option/command) -- cli_basics.sh, cli_errors.sh
#   3 = input error (scene/image missing or malformed)          -- cli_errors.sh
#   1 = other failures (e.g. cannot write the output file)       -- cli_errors.sh
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
gltf=$DR_TESTDIR/data/gltf
cli_setup render
cli_cmd_label="last command"
# A render that must succeed quietly: exit 0, nothing on stdout or stderr
# (no progress bar: stderr is a file here, not a terminal), output written.
render_ok() {   # render_ok OUTPUT ARGS...
    local o=$1; shift
    run render "$@" -o "$o"
    expect_rc 0 "render to $o"
    expect_empty out "render to $o without --json (stdout)"
    expect_empty err "render to $o (stderr: no progress bar or message when not a terminal)"
    [ -s "$o" ] || fail "render to $o: expected a non-empty file $o"
}
magic() { head -c "$2" "$1" | od -An -tx1 | tr -d ' \n'; }

# OpenEXR files carry a capDate header attribute (the time of writing), so two
# renders a second apart differ in those 19 bytes: blank it before comparing
# the files byte for byte (without perl: oiiotool compares the pixels exactly).
have_perl=false
command -v perl >/dev/null 2>&1 && have_perl=true
normalize_exr() {   # normalize_exr IN OUT
    perl -0777 -pe 's/((?:capDate|DateTime)\0string\0\x13\0\0\0).{19}/$1 . ("0" x 19)/gse' "$1" >"$2"
}
same_pixels() {   # same_pixels A.exr B.exr
    if $have_perl; then
        normalize_exr "$1" "$tmp/a.norm" && normalize_exr "$2" "$tmp/b.norm" || fail "perl failed on $1 / $2"
        cmp -s "$tmp/a.norm" "$tmp/b.norm" || return 1
    elif ! $have_oiio; then
        cmp -s "$1" "$2" || return 1   # may see the time stamp differ; no better tool here
    fi
    if ! $have_perl && $have_oiio; then
        oiiotool "$1" "$2" --fail 0 --warn 0 --diff >"$tmp/diff" 2>&1 || return 1
    fi
    return 0
}

require_drender

# ---- the bundled default scene (no SCENE argument) to every format ----
res="--res 24x16 --spp 2"
render_ok img.png $res
render_ok img.exr $res
render_ok img.hdr $res
render_ok img.jpg $res
[ "$(magic img.png 8)" = 89504e470d0a1a0a ] || fail "img.png: not a PNG (magic $(magic img.png 8))"
[ "$(magic img.exr 4)" = 762f3101 ] || fail "img.exr: not OpenEXR (magic $(magic img.exr 4))"
[ "$(head -c 2 img.hdr)" = "#?" ] || fail "img.hdr: not Radiance HDR (starts '$(head -c 10 img.hdr)')"
[ "$(magic img.jpg 3)" = ffd8ff ] || fail "img.jpg: not JPEG (magic $(magic img.jpg 3))"
if $have_oiio; then
    # one oiiotool call for all four (each OpenImageIO process takes a while to start)
    info=$(oiiotool --info img.png img.exr img.hdr img.jpg 2>&1) || fail "oiiotool --info failed: $info"
    check_info() {   # check_info FILE REGEX: oiiotool --info prints "F : 24 x 16, 3 channel, TYPE FORMAT"
        echo "$info" | grep -F "$1 " | grep -Eq "$2" \
            || fail "$1: expected oiiotool --info to match '$2', got: $info"
    }
    check_info img.png ' 24 x +16, 3 channel, uint8 png'
    check_info img.exr ' 24 x +16, 3 channel, (float|half) openexr'
    check_info img.hdr ' 24 x +16, 3 channel, float hdr'
    check_info img.jpg ' 24 x +16, 3 channel, uint8 jpeg'
    # the image is not black: the Cornell box light is in view
    stats=$(oiiotool --stats img.exr 2>&1)
    max=$(echo "$stats" | sed -n 's/.*Max: *\([0-9.e+-]*\).*/\1/p' | head -n 1)
    awk -v m="${max:-0}" 'BEGIN { exit !(m > 0) }' || fail "img.exr: expected some light, oiiotool --stats says: $stats"
else
    echo "note: oiiotool not found; checked the files by their magic bytes only"
fi
# a successful render leaves no temporary files behind
# ---- SOURCE_DATE_EPOCH: EXR and TIFF files carry it as their DateTime
# (UTC), so two renders seconds apart are the same bytes; a malformed value
# stops every command before any work (exit 2, naming the variable) ----
for ext in exr tif; do
    SOURCE_DATE_EPOCH=1700000000 render_ok "stamp1.$ext" --res 8x8 --spp 1
    sleep 1.1   # (a second boundary: without the variable the stamps would differ)
    SOURCE_DATE_EPOCH=1700000000 render_ok "stamp2.$ext" --res 8x8 --spp 1
    cmp -s "stamp1.$ext" "stamp2.$ext" || fail "SOURCE_DATE_EPOCH: two $ext renders differ in bytes"
    if $have_oiio; then
        iinfo -v "stamp1.$ext" | grep -q 'DateTime: "2023:11:14 22:13:20"' ||
            fail "SOURCE_DATE_EPOCH=1700000000: $ext DateTime is not 2023:11:14 22:13:20 (UTC): $(iinfo -v "stamp1.$ext" | grep DateTime)"
    fi
    rm -f "stamp1.$ext" "stamp2.$ext"
done
for bad in 12x -5 " 7" 0x10 99999999999999999999 253402300800; do
    SOURCE_DATE_EPOCH=$bad run render --res 8x8 --spp 1 -o stamp.exr
    expect_rc 2 "SOURCE_DATE_EPOCH='$bad'"
    expect_in err "SOURCE_DATE_EPOCH='$bad' is not a number of seconds" "SOURCE_DATE_EPOCH='$bad'"
    [ ! -e stamp.exr ] || fail "SOURCE_DATE_EPOCH='$bad': stamp.exr was written"
done
SOURCE_DATE_EPOCH= render_ok stamp.exr --res 8x8 --spp 1   # (empty: unset)
rm -f stamp.exr

extra=$(ls -A | grep -v '^img\.\(png\|exr\|hdr\|jpg\)$')
[ -z "$extra" ] || fail "stray files after rendering: $extra"

# ---- --json: one object on stdout, the image still written ----
run render --res 16x16 --spp 3 --json -o j.exr
expect_rc 0 "render --json"
expect_empty err "render --json (stderr)"
[ -s j.exr ] || fail "render --json: expected j.exr to be written"
[ "$(wc -l <"$tmp/out")" -eq 1 ] || fail "render --json: expected exactly one line on stdout"
if $have_python; then
    python3 - "$tmp/out" <<'EOF' || fail "render --json: stdout is not the expected JSON object"
import json, sys
with open(sys.argv[1]) as f:
    doc = json.load(f)      # raises on anything besides one JSON value
assert isinstance(doc, dict), "not an object: %r" % (doc,)
for k in ("time", "rays", "peak_memory_bytes", "effects", "spp"):
    assert k in doc, "key %r missing from %s" % (k, sorted(doc))
assert doc["spp"] == 3, "spp %r, want 3" % doc["spp"]
assert (doc.get("width"), doc.get("height")) == (16, 16), "size %r" % ((doc.get("width"), doc.get("height")),)
assert isinstance(doc["time"], dict) and isinstance(doc["time"].get("total"), (int, float)), doc["time"]
assert isinstance(doc["rays"], dict) and doc["rays"].get("total", 0) > 0, doc["rays"]
assert isinstance(doc["peak_memory_bytes"], int) and doc["peak_memory_bytes"] > 0, doc["peak_memory_bytes"]
assert isinstance(doc["effects"], list) and all(isinstance(e, str) for e in doc["effects"]), doc["effects"]
# the bundled box's untextured hits are shaded eight lanes at a time (path_simd.h)
hits = doc["rays"]["camera"] + doc["rays"]["extension"]
assert 0 < doc["vertices_shaded_8_wide"] <= hits, (doc["vertices_shaded_8_wide"], hits)
# the array tracer's time by stage: every stage, none negative, ray queries
# among them, and no more time than the render's threads had
st = doc["stage_seconds"]
assert sorted(st) == ["camera", "continuation", "escaped", "ray_queries", "shading"], st
assert all(isinstance(v, (int, float)) and v >= 0 for v in st.values()), st
assert st["ray_queries"] > 0 and st["shading"] > 0, st
assert sum(st.values()) <= doc["threads"] * doc["time"]["render"] + 1e-3, (st, doc["threads"], doc["time"])
EOF
    # ... with the Sobol sampler too (its draws taken lane by lane inside the eight-lane stages)
    run render --res 16x16 --spp 3 --json --sampler sobol -o j2.exr
    json_check "$tmp/out" '0 < d["vertices_shaded_8_wide"] <= d["rays"]["camera"] + d["rays"]["extension"]'
else
    echo "note: python3 not found; --json checked with grep only"
    o=$(cat "$tmp/out")
    case $o in "{"*"}") ;; *) fail "render --json: stdout is not one {...} object" ;; esac
    for k in time rays peak_memory_bytes effects spp; do
        grep -q "\"$k\": *[0-9{[]" "$tmp/out" || fail "render --json: key \"$k\" missing"
    done
fi

# ---- determinism: the same seed gives the same image for any --threads ----
render_ok t1.exr --res 16x16 --spp 2 --seed 7 --threads 1
render_ok t2.exr --res 16x16 --spp 2 --seed 7 --threads 2
same_pixels t1.exr t2.exr || fail "--seed 7: --threads 1 and --threads 2 gave different images (t1.exr vs t2.exr)"
render_ok t4.exr --res 16x16 --spp 2 --seed 7 --threads 3
same_pixels t1.exr t4.exr || fail "--seed 7: --threads 1 and --threads 3 gave different images"
# ... and a different seed gives a different image
render_ok s8.exr --res 16x16 --spp 2 --seed 8 --threads 2
same_pixels t1.exr s8.exr && fail "--seed 7 and --seed 8 gave identical images"

# ---- machines without AVX-512 trace 16-wide packets as two 8-wide (avx2)
# or four 4-wide (sse4.2) halves; Embree checks every lane of such a half,
# unused ones included (render once aborted there). The bundled scene's
# single-sided surfaces take the unfiltered-first path; grad's prb runs the
# same packets.
for isa in avx2 sse4.2; do
    DRENDER_EMBREE_CONFIG="isa=$isa" render_ok "isa-$isa.exr" --res 24x16 --spp 4 --threads 2
    DRENDER_EMBREE_CONFIG="isa=$isa" run grad --param /materials/red/pbrMetallicRoughness/baseColorFactor \
        --res 12x8 --spp 4 --threads 2 -o "isa-grad-$isa.exr"
    expect_rc 0 "grad with DRENDER_EMBREE_CONFIG=isa=$isa"
done

# ---- the default scene is the bundled Cornell box; --camera 0 is its camera ----
render_ok d_default.exr --res 16x16 --spp 1
render_ok d_cam0.exr --res 16x16 --spp 1 --camera 0
same_pixels d_default.exr d_cam0.exr || fail "--camera 0 differs from the default camera of the default scene"
if [ -f "$DR_SCENES/cornell-box.gltf" ]; then
    render_ok d_named.exr "$DR_SCENES/cornell-box.gltf" --res 16x16 --spp 1
    same_pixels d_default.exr d_named.exr || fail "no SCENE argument differs from $DR_SCENES/cornell-box.gltf"
fi
# --max-depth 1 sees emitters only: a different image than the default depth
render_ok d_depth1.exr --res 16x16 --spp 1 --max-depth 1
same_pixels d_default.exr d_depth1.exr && fail "--max-depth 1 gave the same image as the default depth"

# ---- scenes given as arguments: .gltf with external files, .glb, embedded ----
# (env_map.gltf has no camera: drender makes one that frames the scene)
for scene in "basic.gltf --camera 0" "basic.glb" "env_map.gltf"; do
    run render "$gltf/"$scene --res 16x16 --spp 1 -o "scene.png"
    expect_rc 0 "render $scene"
    expect_empty out "render $scene (stdout)"
    [ -s scene.png ] || fail "render $scene: expected scene.png"
    # these test scenes use features drender skips: warnings only, naming the file
    if grep -v "warning" "$tmp/err" | grep -q .; then
        fail "render $scene: expected only warnings on stderr"
    fi
    rm -f scene.png
done

extra=$(ls -A | grep -v '\.\(png\|exr\|hdr\|jpg\)$')
[ -z "$extra" ] || fail "stray files after rendering: $extra"
echo "cli_render: all passed"
