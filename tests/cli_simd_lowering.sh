#!/usr/bin/env bash
# The eight-lane kernels stay vector code on processors without AVX-512.
#
# GCC lowers 8-wide double arithmetic to pairs of AVX instructions there, but
# turns a comparison of 8-wide vectors (and a selection by its mask) into
# eight scalar compares and branches, which made the shading kernel three
# times slower on an AVX2 machine (core/simd.h: write dr_f8_lt(a, b), never
# a < b). This compiles every file that uses the 8-wide types for an AVX2
# target, whatever this machine is, with -Wvector-operation-performance, and
# fails on any comparison or condition GCC says it will expand piecewise.
# It first checks that the warning still catches a plain `a < b`, so that the
# check cannot pass vacuously.
set -euo pipefail
cd "$(dirname "$0")/.."
CC=${CC:-cc}
FLAGS=(-std=c11 -D_GNU_SOURCE -O2 -march=haswell -Icore -Iestimators -Idrivers -fno-math-errno -Wno-psabi
       -Wvector-operation-performance)
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
PATTERN='vector (condition|comparison) will be expanded piecewise'

# the detector: an 8-wide comparison written with the operator must be reported
cat >"$TMP/probe.c" <<'EOF'
#include <stdbool.h>
#include "vec.h"
#include "simd.h"
dr_f8 probe(dr_f8 a, dr_f8 b) { return dr_f8_sel(a < b, a, b); }
EOF
if ! "$CC" "${FLAGS[@]}" -c "$TMP/probe.c" -o "$TMP/probe.o" 2>"$TMP/probe.err"; then
    echo "FAIL: the probe does not compile:"; cat "$TMP/probe.err"; exit 1
fi
if ! grep -Eq "$PATTERN" "$TMP/probe.err"; then
    echo "FAIL: $CC does not report a piecewise 8-wide comparison for -march=haswell; this check would pass vacuously"
    cat "$TMP/probe.err"
    exit 1
fi
echo "ok: the warning catches an operator comparison of 8-wide vectors"

files=$(grep -l 'simd.h\|path_simd.h' core/*.c estimators/*.c | sort)
checked=0 failed=0
for f in $files; do
    if ! "$CC" "${FLAGS[@]}" -c "$f" -o "$TMP/out.o" 2>"$TMP/err"; then
        echo "FAIL: $f does not compile for -march=haswell:"; cat "$TMP/err"; failed=$((failed + 1)); continue
    fi
    checked=$((checked + 1))
    if grep -E "$PATTERN" "$TMP/err" | sort | uniq -c | grep .; then
        echo "FAIL: $f: 8-wide comparisons lowered to scalar branches (use dr_f8_lt & co., core/simd.h)"
        failed=$((failed + 1))
    else
        echo "ok: $f"
    fi
done
[[ $checked -ge 3 ]] || { echo "FAIL: only $checked files checked (expected the kernels, the arrays and the lanes)"; exit 1; }
[[ $failed -eq 0 ]] || exit 1
echo "$checked files: no 8-wide comparison lowered to branches"
