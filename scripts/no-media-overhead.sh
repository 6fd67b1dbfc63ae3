#!/usr/bin/env bash
# Checks that a scene without media pays nothing for media: the instructions
# dr_render executes (callgrind, inclusive) on the bundled Cornell box, with
# one thread, for two drender binaries (e.g. a build from before media and the
# current one), and whether they are within 1%, and that the images are equal.
#   scripts/no-media-overhead.sh OLD_DRENDER [NEW_DRENDER (default build/drender)]
# Needs valgrind and idiff (openimageio-tools). Measured when media were added:
# 171.75M -> 172.76M instructions (+0.59%), identical image.
set -euo pipefail
old=${1:?usage: $0 OLD_DRENDER [NEW_DRENDER]}
new=${2:-build/drender}
scene=${SCENE:-scenes/cornell-box.gltf}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
count() {   # count BINARY NAME: instructions inside dr_render
    valgrind --tool=callgrind --callgrind-out-file="$tmp/$2.cg" "$1" render "$scene" --spp 4 --res 64x64 \
        --threads 1 -o "$tmp/$2.exr" >/dev/null 2>&1
    callgrind_annotate --inclusive=yes "$tmp/$2.cg" 2>/dev/null | awk '/:dr_render / && !n { gsub(",", "", $1); n = $1 } END { print n }'
}
a=$(count "$old" old)
b=$(count "$new" new)
awk -v a="$a" -v b="$b" 'BEGIN { printf "dr_render instructions: %d -> %d (%+.2f%%)\n", a, b, (b - a) / a * 100 }'
same=no
idiff "$tmp/old.exr" "$tmp/new.exr" >/dev/null 2>&1 && same=yes
echo "identical image: $same"
awk -v a="$a" -v b="$b" 'BEGIN { exit !((b - a) / a <= 0.01) }' && [ "$same" = yes ]
