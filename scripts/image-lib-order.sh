#!/usr/bin/env bash
# The libraries to name first when linking libdrender-image.so, so that its
# dlopen resolves symbols sooner (core/image_plugin.h).
#
#   scripts/image-lib-order.sh             the files to link first, one line
#   scripts/image-lib-order.sh --measure   where a textured render's symbol
#                                          bindings go, most first
#
# Why: Debian's OpenImageIO brings in about 260 shared libraries (OpenVDB,
# GDAL, DICOM, ffmpeg, ...). Every symbol a library binds to at load time is
# looked up object by object along the search list: the global scope (the
# drender binary and its 10 libraries), then the plugin's dependencies in
# breadth-first order, where OpenImageIO's own list decides who comes early.
# Of the 170 000 bindings, 57 000 go to libopenvdb (its C++ code calling its
# own exported functions), 8 600 to libxerces-c, 6 500 to libgdal, ..., and
# those sat at places 37 to 262 of the list: 91 objects tried per binding
# on average, the dynamic loader's symbol search most of the load's 167 ms.
# Naming the libraries bound to most as the plugin's own first dependencies
# (DT_NEEDED) moves them to the front of its search list: 111 ms (3 x 5
# runs, the plugin's dlopen alone; --measure on Debian 12 gave the ranking
# below, the 50 most bound to).
#
# What else changes: the same libraries are loaded, the same objects
# initialised. Where two libraries define the same symbol, the first in the
# list provides it; on Debian 12, 671 of the 167 000 bindings went to
# another library's copy, every one a C++ template, inline function or
# function-local static (vague linkage: the copies are the same code, and
# which one a process uses depends on its link order anyway) but one:
# libnetcdf's strlcat, now its own instead of libbsd's.
#
# A ranked library that OpenImageIO does not link here is skipped, so on
# another system the list shrinks (nothing breaks; the load is as before).
# Prints nothing when OpenImageIO is not installed (make's deps step comes
# first on a fresh machine; the link then asks again).
set -euo pipefail

RANKED=(libopenvdb libxerces-c-3.2 libgdal libgeos libcrypto libhdf5_serial libproj libOpenImageIO
        libglib-2.0 libdcmdata libpoppler libgdcmMSFF libkmldom libsqlite3 libopencv_core libnetcdf
        liblapack libOpenEXR-3_1 libgstreamer-1.0 libOpenColorIO liblog4cplus-2.0 libcfitsio libIex-3_1
        libspatialite libgobject-2.0 liboflog libX11 libsrt-gnutls libgnutls libgeos_c libOpenImageIO_Util
        libgio-2.0 libnettle libdfalt libmbedcrypto librttopo libkrb5 libnss3 libavutil libofstd
        libgdcmDSED libraw_r libcodec2 libunistring libgmp libpango-1.0 libqhull_r libcairo libpng16
        libblas)

oiio_deps() {
    local libdir
    libdir=$(pkg-config --variable=libdir OpenImageIO 2>/dev/null) || return 0
    [[ -e $libdir/libOpenImageIO.so ]] || return 0
    # (ldd lists the whole closure; "name => path (address)")
    { echo "$libdir/libOpenImageIO.so"; ldd "$libdir/libOpenImageIO.so" 2>/dev/null | awk '$2 == "=>" && $3 ~ /^\// { print $3 }'; } | sort -u
}

if [[ ${1:-} == --measure ]]; then
    # A render of a textured scene (images go through the plugin), the
    # loader's bindings counted by the library bound to.
    cd "$(dirname "$0")/.."
    scene=${2:-scenes/cornell-box.gltf}   # (its floor is a PNG texture)
    [[ -x build/drender && -f $scene ]] || { echo "usage: $0 --measure [TEXTURED_SCENE] (after make)" >&2; exit 2; }
    tmp=$(mktemp -d)
    trap 'rm -rf "$tmp"' EXIT
    LD_DEBUG=bindings LD_DEBUG_OUTPUT=$tmp/bind build/drender render "$scene" --res 8x8 --spp 1 -o "$tmp/out.exr" >/dev/null 2>&1
    cat "$tmp"/bind.* | sed -n 's/.* to \([^ ]*\) \[[0-9]*\]: normal symbol.*/\1/p' | sort | uniq -c | sort -rn
    exit 0
fi

deps=$(oiio_deps)
[[ -n $deps ]] || exit 0
out=()
for stem in "${RANKED[@]}"; do
    # (awk reads to the end: an early exit could make printf die of SIGPIPE,
    # which under pipefail and -e ended the script with nothing printed, and
    # the plugin was linked without the ranking, now and then under load)
    path=$(printf '%s\n' "$deps" | awk -v s="$stem.so" '!found { n = split($0, p, "/"); if (index(p[n], s) == 1) { print; found = 1 } }')
    [[ -n $path ]] && out+=("$path")
done
echo "${out[*]}"
