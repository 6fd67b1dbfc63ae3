#!/usr/bin/env bash
# The packet renderer's kernels at a vector width this machine's own build
# does not use.
#
# core/simd.h, core/path_simd.c and core/accel.c choose their loads,
# comparisons, conversions and compaction by the target: AVX-512 registers,
# pairs of AVX halves, or plain C. `make test` (-march=native) runs only this
# machine's choice and `make sanitize` (no -march) the plain C one, so on an
# AVX-512 machine nothing ran the AVX2 code. This builds test_render (the
# packet renderer against the one-path walker, bit for bit) and
# test_estimators (prb and tape walks through the same arrays) for AVX2
# (x86-64-v3) into build-narrow/ and runs them. On an AVX2 machine that
# repeats the native width; a machine without AVX2 builds for x86-64-v2.
set -euo pipefail
cd "$(dirname "$0")/.."
if grep -qw avx2 /proc/cpuinfo; then arch=x86-64-v3; else arch=x86-64-v2; fi
out=build-narrow
tests=(test_render test_estimators)
# (make does not track flags: this directory is only ever built with these;
# and not the calling make's variables, such as make sanitize's SAN=1)
env -u MAKEFLAGS -u MFLAGS -u MAKELEVEL make -s -j2 BUILD=$out OPT="-O2 -march=$arch" "${tests[@]/#/$out/tests/}" >/dev/null
for t in "${tests[@]}"; do
    # built for that width: not one AVX-512 register in the binary
    if objdump -d --no-show-raw-insn "$out/tests/$t" | grep -q '%zmm'; then
        echo "FAIL: $out/tests/$t was not built for $arch (it uses AVX-512 registers)"
        exit 1
    fi
    echo "== $t, built for $arch"
    "$out/tests/$t"
done
echo "ok: the kernels built for $arch give the walker's results"
