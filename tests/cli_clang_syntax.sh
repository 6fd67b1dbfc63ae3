#!/usr/bin/env bash
# Every C and C++ source compiles with clang, warning-free.
#
# `make test` and `make sanitize` build with GCC; only `make fuzz` (libFuzzer)
# builds with clang, and nothing in the CI ran it, so GCC extensions clang
# refuses went unnoticed (taking the address of a vector's element,
# &u[l] on a dr_f8: `make fuzz` stopped at core/sampler8.h, core/render.c
# and estimators/common.c), as did a dead static function clang warns about
# where GCC does not. This checks every source with clang -fsyntax-only at
# two targets: the plain one (as `make fuzz` builds) and this machine's
# (-march=native: the AVX-512 or AVX2 branches of core/simd.h). About 30 s.
set -uo pipefail
cd "$(dirname "$0")/.."
command -v clang >/dev/null && command -v clang++ >/dev/null ||
    { echo "FAIL: clang not installed (scripts/install-deps.sh installs it)"; exit 1; }
inc=(-Icore -Iestimators -Idrivers -Icli -Itests -Ibench)
# (the Makefile's WARN, and bench/'s GCC-only loop pragmas left aside)
cflags=(-std=c11 -D_GNU_SOURCE -pthread -O1 -Wall -Wextra -Wpedantic -Wno-psabi -Wno-unknown-pragmas
        -DDR_DATADIR='"x"' -DDR_LIBDIR='"x"' -DDR_FUZZ_DATA='"x"')
read -r -a cxxflags <<<"-std=c++17 -O1 -Wall -Wextra -Wno-psabi $(pkg-config --cflags OpenImageIO stb)"
csrc=(core/*.c estimators/*.c drivers/*.c cli/*.c tests/*.c fuzz/*.c bench/*.c)
cxxsrc=(core/*.cpp fuzz/*.cpp)
checked=0 failed=0
check() {   # check COMPILER FLAGS... -- FILE
    local out
    if ! out=$("$@" -fsyntax-only 2>&1) || [ -n "$out" ]; then
        echo "FAIL: ${*: -1} (${1}${march:+ $march}):"
        echo "$out" | head -20
        failed=$((failed + 1))
    fi
    checked=$((checked + 1))
}
for march in "" -march=native; do
    for f in "${csrc[@]}"; do check clang "${inc[@]}" "${cflags[@]}" $march "$f"; done
    for f in "${cxxsrc[@]}"; do check clang++ "${inc[@]}" "${cxxflags[@]}" $march "$f"; done
done
# (a glob that matched nothing would check nothing)
[ "$checked" -ge 100 ] || { echo "FAIL: only $checked compilations checked"; exit 1; }
echo "cli_clang_syntax: $checked compilations, $failed with errors or warnings"
[ "$failed" -eq 0 ]
