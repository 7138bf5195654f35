#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# libFuzzer run of the C API target fuzz/fuzz_api.cpp (see fuzz/README_api.md).
#
#   scripts/fuzz_api.sh [SECONDS] [-- LIBFUZZER_ARGS...]
#                                      build, then fuzz for SECONDS (default 120)
#   scripts/fuzz_api.sh --build-only   build only (prints the binary's path)
#   scripts/fuzz_api.sh --replay       build, then run the corpus once (no fuzzing)
#
# Steps:
#  1. scripts/setup.sh --kokkos-only --no-example fetches (and patches) the
#     Kokkos 3.4 source from Debian's trilinos package into the cache.
#  2. A Serial-only Kokkos is built with clang-14 into
#     $NBMC_CACHE/kokkos-3.4.01-<patch hash>-serial-clang. The GCC builds use
#     Kokkos' OpenMP space and libgomp, which must not be mixed with clang's
#     OpenMP runtime in one process; the fuzzer runs the serial backend only.
#  3. fuzz/api/CMakeLists.txt builds the nbmc library sources with
#     -fsanitize=fuzzer-no-link,address,undefined and links fuzz_api with
#     -fsanitize=fuzzer,address,undefined (in $NBMC_FUZZ_API_BUILD, default
#     /tmp/nbmc-fuzz-api-build).
#  4. The fuzzer runs (one process, nice 19) on fuzz/corpus/api: new inputs go
#     to a work corpus in a temp dir (the checked-in corpus is only read),
#     crashes to <temp dir>/crashes/. Both paths are printed at the end.
#
# Environment: NBMC_CACHE (default ~/.cache/nbmc), NBMC_JOBS (default 2),
# NBMC_FUZZ_API_BUILD, NBMC_FUZZ_API_WORK (temp dir to use), NBMC_FUZZ_API_MERGE=1
# (merge new coverage back into fuzz/corpus/api after the run), NBMC_SKIP_APT=1
# (passed to setup.sh). The target prints one line per input with
# NBMC_FUZZ_API_VERBOSE=1.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
CACHE=${NBMC_CACHE:-$HOME/.cache/nbmc}
JOBS=${NBMC_JOBS:-2}
BUILD=${NBMC_FUZZ_API_BUILD:-/tmp/nbmc-fuzz-api-build}
KOKKOS_VERSION=3.4.01
CXX_CLANG=${NBMC_CLANGXX:-clang++-14}
CC_CLANG=${NBMC_CLANG:-clang-14}

SECONDS_TO_RUN=120
MODE=fuzz
EXTRA=()
while [ $# -gt 0 ]; do
  case "$1" in
    --build-only) MODE=build ;;
    --replay) MODE=replay ;;
    --) shift; EXTRA=("$@"); break ;;
    -h|--help) sed -n '3,29p' "$0"; exit 0 ;;
    *[!0-9]*|'') echo "fuzz_api.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
    *) SECONDS_TO_RUN=$1 ;;
  esac
  shift
done

say() { printf '\033[1m[fuzz_api]\033[0m %s\n' "$*"; }

command -v "$CXX_CLANG" >/dev/null || {
  echo "fuzz_api.sh: $CXX_CLANG not found (Debian: apt-get install clang-14 libclang-rt-14-dev)" >&2; exit 1; }

# ------------------------------------------------------ 1. Kokkos source
"$ROOT/scripts/setup.sh" --kokkos-only --no-example
PATCH_HASH=$(cat "$ROOT"/scripts/kokkos-patches/*.patch | sha256sum | cut -c1-10)
KOKKOS_SRC=$CACHE/src/kokkos-$KOKKOS_VERSION-$PATCH_HASH
[ -f "$KOKKOS_SRC/.nbmc-ready" ] || { echo "fuzz_api.sh: no Kokkos source in $KOKKOS_SRC" >&2; exit 1; }

# ------------------------------------------- 2. Serial Kokkos with clang
KOKKOS_PREFIX=$CACHE/kokkos-$KOKKOS_VERSION-$PATCH_HASH-serial-clang
if [ ! -f "$KOKKOS_PREFIX/.nbmc-ready" ]; then
  kb=$CACHE/build/kokkos-serial-clang
  rm -rf "$kb" "$KOKKOS_PREFIX"
  say "building Kokkos $KOKKOS_VERSION (Serial only, $CXX_CLANG) into $KOKKOS_PREFIX"
  cmake -G Ninja -S "$KOKKOS_SRC" -B "$kb" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
        -DCMAKE_CXX_COMPILER="$CXX_CLANG" -DCMAKE_C_COMPILER="$CC_CLANG" \
        -DCMAKE_INSTALL_PREFIX="$KOKKOS_PREFIX" -DBUILD_SHARED_LIBS=OFF \
        -DCMAKE_POSITION_INDEPENDENT_CODE=ON -DCMAKE_CXX_STANDARD=17 \
        -DKokkos_ENABLE_SERIAL=ON -DKokkos_ENABLE_OPENMP=OFF -DKokkos_ENABLE_THREADS=OFF \
        -DKokkos_ENABLE_TESTS=OFF -DKokkos_ENABLE_EXAMPLES=OFF \
        >"$CACHE/kokkos-serial-clang-configure.log" 2>&1 ||
    { tail -40 "$CACHE/kokkos-serial-clang-configure.log"; exit 1; }
  cmake --build "$kb" -j "$JOBS" >"$CACHE/kokkos-serial-clang-build.log" 2>&1 ||
    { tail -40 "$CACHE/kokkos-serial-clang-build.log"; exit 1; }
  cmake --install "$kb" >/dev/null
  rm -rf "$kb"
  touch "$KOKKOS_PREFIX/.nbmc-ready"
fi

# --------------------------------------------------- 3. the fuzz target
say "building fuzz_api in $BUILD"
cmake -G Ninja -S "$ROOT/fuzz/api" -B "$BUILD" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
      -DCMAKE_CXX_COMPILER="$CXX_CLANG" -DCMAKE_C_COMPILER="$CC_CLANG" \
      -DKokkos_ROOT="$KOKKOS_PREFIX" >/dev/null
cmake --build "$BUILD" -j "$JOBS"
BIN=$BUILD/fuzz_api
if [ "$MODE" = build ]; then echo "$BIN"; exit 0; fi

export ASAN_OPTIONS=${ASAN_OPTIONS:-abort_on_error=1:detect_leaks=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
CORPUS=$ROOT/fuzz/corpus/api
if [ "$MODE" = replay ]; then
  "$BIN" -runs=0 "$CORPUS"
  exit 0
fi

# -------------------------------------------------------------- 4. fuzz
WORK=${NBMC_FUZZ_API_WORK:-$(mktemp -d /tmp/nbmc-fuzz-api.XXXXXX)}
mkdir -p "$WORK/corpus" "$WORK/crashes"
say "fuzzing for $SECONDS_TO_RUN s: work corpus $WORK/corpus, crashes in $WORK/crashes"
set +e
nice -n 19 "$BIN" -max_total_time="$SECONDS_TO_RUN" -timeout=10 -rss_limit_mb=2048 -max_len=512 \
  -print_final_stats=1 -artifact_prefix="$WORK/crashes/" "${EXTRA[@]}" \
  "$WORK/corpus" "$CORPUS" 2>&1 | tee "$WORK/fuzz.log"
rc=${PIPESTATUS[0]}
set -e
if [ "${NBMC_FUZZ_API_MERGE:-0}" = 1 ]; then
  say "merging new coverage into $CORPUS"
  "$BIN" -merge=1 "$CORPUS" "$WORK/corpus" >"$WORK/merge.log" 2>&1
fi
say "log: $WORK/fuzz.log; work corpus: $WORK/corpus ($(ls "$WORK/corpus" | wc -l) inputs)"
say "crashes: $WORK/crashes ($(ls "$WORK/crashes" | wc -l) files); exit status $rc"
exit "$rc"
