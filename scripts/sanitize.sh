#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Builds the library and the tests with AddressSanitizer and
# UndefinedBehaviorSanitizer (GCC) in build-asan/ and runs the test suite
# under them. Needs scripts/setup.sh to have run (Kokkos in the cache).
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
CACHE=${NBMC_CACHE:-$HOME/.cache/nbmc}
B=${NBMC_ASAN_BUILD_DIR:-$ROOT/build-asan}
KOKKOS=$(ls -d "$CACHE"/kokkos-3.4.01-*-openmp | head -n1)
FLAGS="-fsanitize=address,undefined -fno-sanitize-recover=undefined -fno-omit-frame-pointer -g -O1"
cmake -G Ninja -S "$ROOT" -B "$B" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DKokkos_ROOT="$KOKKOS" \
  -DCMAKE_CXX_FLAGS="$FLAGS" -DCMAKE_C_FLAGS="$FLAGS" -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=address,undefined" \
  -DCMAKE_SHARED_LINKER_FLAGS="-fsanitize=address,undefined" -DNBMC_BUILD_BENCH=OFF >/dev/null
cmake --build "$B" -j "${NBMC_JOBS:-$(nproc)}"
# Kokkos' OpenMP pool and libgomp keep thread-local buffers until exit.
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1:strict_string_checks=1}
export LSAN_OPTIONS=${LSAN_OPTIONS:-suppressions=$ROOT/scripts/lsan.supp:print_suppressions=0}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
ctest --test-dir "$B" --output-on-failure -j "${NBMC_TEST_JOBS:-2}" --timeout 1800 "$@"
