#!/usr/bin/env bash
# The image library's link order (scripts/image-lib-order.sh): the libraries
# most of its load-time symbol bindings go to are its first dependencies, in
# the script's order, so its dlopen finds their symbols early (167 -> 111 ms
# on Debian 12; timings belong in make bench, this checks the order). And the
# library so linked still loads, reads and writes images.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
cli_setup image_lib_order
require_drender

plugin=$(dirname "$DRENDER")/libdrender-image.so
[ -f "$plugin" ] || fail "the image library was not built beside drender: $plugin"
command -v readelf >/dev/null || fail "readelf (binutils) is needed"

first=$(bash "$DR_TESTDIR/../scripts/image-lib-order.sh")
# Debian 12's OpenImageIO links OpenVDB, GDAL and the rest of the ranking: an
# empty answer means the script no longer finds them (and the plugin loads
# slowly again)
[ -n "$first" ] || fail "scripts/image-lib-order.sh found none of its ranked libraries among OpenImageIO's"
soname() { readelf -d "$1" | sed -n 's/.*(SONAME).*\[\(.*\)\]/\1/p'; }
want=()
for f in $first; do want+=("$(soname "$f")"); done
have=()
# (make sanitize's build links the sanitizer runtimes first: not ours to order)
while read -r n; do have+=("$n"); done < <(readelf -d "$plugin" | sed -n 's/.*(NEEDED).*\[\(.*\)\]/\1/p' |
    grep -v -E '^lib(asan|ubsan|tsan|lsan)\.so' | head -n ${#want[@]})
[ "${want[*]}" = "${have[*]}" ] ||
    fail "the image library's first dependencies are not the script's ranking: want '${want[*]:0:5} ...', have '${have[*]:0:5} ...'"
case "${have[0]}" in libopenvdb.so*) ;; *) fail "libopenvdb (57 000 of the 170 000 bindings) is not the first dependency: ${have[0]}" ;; esac

# drender's functions the library calls back into are all exported by the
# binary (-rdynamic exports only what the binary linked: a function of an
# archive member nothing else used would make the dlopen fail at the first
# image, "undefined symbol"; bench/image_lib_rss met that)
# (make sanitize's drender links the image code itself and never loads the
# library: Makefile, SAN=1; its own OpenImageIO dependency tells)
command -v nm >/dev/null || fail "nm (binutils) is needed"
if readelf -d "$DRENDER" | grep -q 'NEEDED.*libOpenImageIO\.'; then
    echo "cli_image_lib_order: $DRENDER links the image code itself: no callbacks to check"
else
    missing=$(comm -23 <(nm -D --undefined-only "$plugin" | awk '$2 ~ /^dr_/ {print $2}' | sort -u) \
        <(nm -D --defined-only "$DRENDER" | awk '$3 ~ /^dr_/ {print $3}' | sort -u))
    [ -z "$missing" ] || fail "the image library needs functions drender does not export: $missing"
    [ "$(nm -D --undefined-only "$plugin" | grep -c ' dr_')" -ge 5 ] ||
        fail "nm found fewer than 5 dr_ functions the image library calls back into"
fi

# it loads and works: a scene with a PNG texture (read through the library)
# rendered to PNG and EXR (written through it)
scene=$DR_SCENES/cornell-box.gltf
for out in a.png a.exr; do
    run render "$scene" --res 16x16 --spp 1 -o "$out"
    expect_rc 0 "render with a PNG texture to $out"
    [ -s "$out" ] || fail "render wrote no $out"
done
echo "cli_image_lib_order: all passed (${#want[@]} libraries first, ${have[0]} leading)"
