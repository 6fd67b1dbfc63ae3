#!/usr/bin/env bash
# Installs the Debian packages drender needs to build, test and benchmark.
# Only what is missing is installed; uses sudo when not root. Idempotent.
# With --fuzz, only the fuzzing toolchain of `make fuzz` (clang, libFuzzer and
# the sanitizer runtimes) is checked; `make test` needs clang only for its
# syntax check (tests/cli_clang_syntax.sh), not libFuzzer.
set -euo pipefail

pkgs=(build-essential pkg-config
      libembree-dev libopenimageio-dev openimageio-tools
      libtinygltf-dev nlohmann-json3-dev libstb-dev
      libdraco-dev   # KHR_draco_mesh_compression (core/draco_decode.cpp)
      libmeshoptimizer-dev   # EXT_meshopt_compression (core/meshopt_decode.cpp)
      libzstd-dev zlib1g-dev   # KTX2 textures' supercompression (core/ktx2.c)
      gnuplot-nox python3
      valgrind    # scripts/no-media-overhead.sh counts instructions with callgrind
      python3-openvdb   # tests/data/media/make_vdb.py writes the test .vdb files
      strace   # tests/cli_write_failures.sh: outputs are fsync'ed before their rename
      clang)   # tests/cli_clang_syntax.sh: every source compiles with clang (as make fuzz builds)
# Node.js runs the Khronos glTF validator (tests/cli_gltf_validate.sh). Any node
# on PATH will do (e.g. NodeSource's nodejs, which bundles npm and conflicts with
# Debian's npm), so Debian's packages are added only when there is none.
command -v node >/dev/null 2>&1 || pkgs+=(nodejs npm)
# `make fuzz`: Debian 12's clang 14 ships libFuzzer in libclang-rt-14-dev.
[ "${1:-}" = "--fuzz" ] && pkgs=(clang libclang-rt-14-dev)

missing=()
for p in "${pkgs[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0

echo "install-deps: installing ${missing[*]}" >&2
SUDO=""
[ "$(id -u)" -ne 0 ] && SUDO="sudo"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >&2
