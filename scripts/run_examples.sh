#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Builds and runs every embedding example against an INSTALLED nbmc:
#
#   scripts/run_examples.sh [PREFIX]        PREFIX defaults to build/install
#
#  1. C, CMake:       examples/c with find_package(nbmc)
#  2. C, pkg-config:  examples/c/Makefile
#  3. Rust:           cargo test --offline (nbmc-sys layout test + safe API)
#  4. Rust:           the reconstruct example
#  5. Fortran, CMake: examples/fortran with find_package(nbmc)
#  6. Fortran, make:  examples/fortran/Makefile with pkg-config
#  7. consistency:    the C (both builds) and Rust meshes of the sample frame agree
#
# Everything is written under a fresh temporary directory (NBMC_EXAMPLES_OUT
# chooses another). Exits non-zero if any step fails; a summary comes last.
# Needs cmake, a C compiler, pkg-config, gfortran and cargo (Rust 1.63 or newer,
# e.g. Debian 12's `cargo` package; the crates use std only).
set -uo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
PREFIX=${1:-$ROOT/build/install}
case "$PREFIX" in -h|--help) sed -n '3,18p' "$0"; exit 0 ;; esac
PREFIX=$(cd "$PREFIX" 2>/dev/null && pwd) || { echo "run_examples.sh: no such prefix: ${1:-$ROOT/build/install} (run scripts/setup.sh first)" >&2; exit 2; }
JOBS=${NBMC_JOBS:-2}
DATA=$ROOT/examples/data/double_dam_break_4732.xyz
SPACING=0.05

OUT=${NBMC_EXAMPLES_OUT:-$(mktemp -d "${TMPDIR:-/tmp}/nbmc-examples.XXXXXX")}
mkdir -p "$OUT/logs"

bold() { printf '\033[1m%s\033[0m\n' "$*"; }
NAMES=()
RESULTS=()
FAILED=0

# step NAME FUNCTION: runs FUNCTION with its output in $OUT/logs/NAME.log.
step() {
  local name=$1 fn=$2 log=$OUT/logs/$1.log
  bold "== $name"
  # Not inside "if": errexit would be ignored in the subshell.
  ( set -e; "$fn" ) >"$log" 2>&1
  local rc=$?
  if [ "$rc" = 0 ]; then
    NAMES+=("$name"); RESULTS+=("PASS")
    tail -n 4 "$log" | sed 's/^/   /'
  else
    NAMES+=("$name"); RESULTS+=("FAIL"); FAILED=1
    echo "   FAILED; last lines of $log:"
    tail -n 30 "$log" | sed 's/^/   | /'
  fi
}

need() { # need TOOL WHAT
  command -v "$1" >/dev/null 2>&1 || { echo "'$1' is not installed: $2" >&2; return 1; }
}

# The lib directory of the prefix (lib, lib64 or a multiarch one).
LIBDIR=
for d in lib lib64 lib/x86_64-linux-gnu lib/aarch64-linux-gnu; do
  if [ -e "$PREFIX/$d/libnbmc.so" ]; then LIBDIR=$PREFIX/$d; break; fi
done

check_ply() { # check_ply FILE: a binary PLY with at least one face
  head -c 16 "$1" | grep -q '^ply' || { echo "$1 is not a PLY file" >&2; return 1; }
  local faces; faces=$(head -c 2000 "$1" | grep -a '^element face' | awk '{print $3}' || true)
  [ "${faces:-0}" -gt 0 ] || { echo "$1 has no faces" >&2; return 1; }
  echo "$1: $faces triangles"
}

# ------------------------------------------------------------------ steps
install_ok() {
  echo "prefix $PREFIX"
  [ -n "$LIBDIR" ] || { echo "no libnbmc.so under $PREFIX/lib*" >&2; return 1; }
  for f in include/nbmc.h; do [ -f "$PREFIX/$f" ] || { echo "missing $PREFIX/$f" >&2; return 1; }; done
  [ -f "$LIBDIR/cmake/nbmc/nbmcConfig.cmake" ] || { echo "missing $LIBDIR/cmake/nbmc/nbmcConfig.cmake" >&2; return 1; }
  [ -f "$LIBDIR/pkgconfig/nbmc.pc" ] || { echo "missing $LIBDIR/pkgconfig/nbmc.pc" >&2; return 1; }
  "$PREFIX/bin/nbmc" --version 2>/dev/null || true
  echo "install complete: $LIBDIR"
}

c_cmake() {
  need cmake "needed for the CMake builds"
  cmake -S "$ROOT/examples/c" -B "$OUT/c-cmake" -DCMAKE_PREFIX_PATH="$PREFIX" -DCMAKE_BUILD_TYPE=Release
  cmake --build "$OUT/c-cmake" -j "$JOBS"
  "$OUT/c-cmake/reconstruct" "$DATA" "$SPACING" "$OUT/c-cmake.ply"
  check_ply "$OUT/c-cmake.ply"
}

c_pkgconfig() {
  need pkg-config "needed for the Makefile builds"
  export PKG_CONFIG_PATH=$LIBDIR/pkgconfig${PKG_CONFIG_PATH:+:$PKG_CONFIG_PATH}
  echo "pkg-config nbmc: $(pkg-config --modversion nbmc) $(pkg-config --cflags --libs nbmc)"
  mkdir -p "$OUT/c-make"
  make -f "$ROOT/examples/c/Makefile" O="$OUT/c-make"
  "$OUT/c-make/reconstruct" "$DATA" "$SPACING" "$OUT/c-make.ply"
  check_ply "$OUT/c-make.ply"
}

# "1.63.0" from "rustc 1.63.0 (...)" / "cargo 1.65.0 (...)" -> 1063
minor_of() { "$1" --version 2>/dev/null | awk '{split($2, v, "."); print v[1] * 1000 + v[2]}'; }

need_cargo() {
  # The crates need rustc >= 1.63 and cargo >= 1.64 (workspace inheritance):
  # Debian 12's `cargo` package (cargo 1.65, rustc 1.63) is enough.
  if ! command -v cargo >/dev/null 2>&1 || ! command -v rustc >/dev/null 2>&1; then
    echo "cargo is not installed: the Rust examples (examples/rust) need cargo and rustc;" >&2
    echo "install Debian's 'cargo' package (or any Rust 1.63 or newer) and run this script again." >&2
    return 1
  fi
  local rc cg
  rc=$(minor_of rustc); cg=$(minor_of cargo)
  if [ "${rc:-0}" -lt 1063 ] || [ "${cg:-0}" -lt 1064 ]; then
    echo "the Rust examples need rustc 1.63 and cargo 1.64 or newer; found: $(rustc --version), $(cargo --version)" >&2
    return 1
  fi
  export NBMC_DIR=$PREFIX CARGO_TARGET_DIR=$OUT/cargo-target NBMC_SYS_VERBOSE=1
  cd "$ROOT/examples/rust"
}

rust_tests() {
  need_cargo
  cargo --version; rustc --version
  cargo test --offline --locked --workspace --no-fail-fast
  # nbmc-sys's MPI declarations link against libnbmc_mpi where it was built.
  if ls "$LIBDIR"/libnbmc_mpi.so >/dev/null 2>&1; then
    cargo test --offline --locked -p nbmc-sys --features mpi --no-fail-fast
  fi
}

rust_example() {
  need_cargo
  cargo run --offline --locked --example reconstruct -- "$DATA" "$SPACING" "$OUT/rust.ply"
  check_ply "$OUT/rust.ply"
}

fortran_cmake() {
  need gfortran "needed for the Fortran example"
  need cmake "needed for the CMake builds"
  cmake -S "$ROOT/examples/fortran" -B "$OUT/fortran-cmake" -DCMAKE_PREFIX_PATH="$PREFIX" -DCMAKE_BUILD_TYPE=Release
  cmake --build "$OUT/fortran-cmake" -j "$JOBS"
  mkdir -p "$OUT/fortran-cmake-frames"
  "$OUT/fortran-cmake/example" "$OUT/fortran-cmake-frames"
  local n; n=$(ls "$OUT/fortran-cmake-frames"/frame_*.obj | wc -l)
  [ "$n" -ge 2 ] || { echo "expected several OBJ frames, found $n" >&2; return 1; }
  grep -c '^f ' "$OUT/fortran-cmake-frames"/frame_*.obj
  # In situ over MPI (mpi_f08), when nbmc and the MPI Fortran compiler have it.
  if [ -x "$OUT/fortran-cmake/example_mpi" ] && command -v mpirun >/dev/null 2>&1; then
    local flags=(--oversubscribe)
    [ "$(id -u)" = 0 ] && flags+=(--allow-run-as-root)
    OMP_NUM_THREADS=1 mpirun "${flags[@]}" -n 3 "$OUT/fortran-cmake/example_mpi"
  else
    echo "Fortran MPI example not built (no libnbmc_mpi or no mpi_f08): skipped"
  fi
}

fortran_make() {
  need gfortran "needed for the Fortran example"
  need pkg-config "needed for the Makefile builds"
  export PKG_CONFIG_PATH=$LIBDIR/pkgconfig${PKG_CONFIG_PATH:+:$PKG_CONFIG_PATH}
  mkdir -p "$OUT/fortran-make" "$OUT/fortran-make-frames"
  make -f "$ROOT/examples/fortran/Makefile" FC=gfortran O="$OUT/fortran-make"
  "$OUT/fortran-make/example" "$OUT/fortran-make-frames"
  # Same solver, same library: the same meshes as the CMake build.
  for f in "$OUT/fortran-cmake-frames"/frame_*.obj; do
    [ -f "$f" ] || continue
    cmp "$f" "$OUT/fortran-make-frames/$(basename "$f")"
  done
  echo "Fortran meshes identical between the CMake and Makefile builds"
}

consistency() {
  # The three meshes of the sample frame have the same counts; the two C
  # builds write identical files.
  local counts=()
  for f in c-cmake c-make rust; do
    [ -f "$OUT/$f.ply" ] || { echo "missing $OUT/$f.ply (its step failed)" >&2; return 1; }
    counts+=("$(head -c 2000 "$OUT/$f.ply" | grep -a '^element' | tr '\n' ' ')")
    echo "$f: ${counts[-1]}"
  done
  [ "${counts[0]}" = "${counts[1]}" ] && [ "${counts[0]}" = "${counts[2]}" ] || { echo "vertex/face counts differ" >&2; return 1; }
  cmp "$OUT/c-cmake.ply" "$OUT/c-make.ply"
  echo "C and Rust meshes agree"
}

# ------------------------------------------------------------------- run
bold "nbmc examples against $PREFIX (outputs in $OUT)"
step install install_ok
step c-cmake c_cmake
step c-pkgconfig c_pkgconfig
step rust-tests rust_tests
step rust-example rust_example
step fortran-cmake fortran_cmake
step fortran-make fortran_make
step consistency consistency

echo
bold "Summary (logs and outputs: $OUT)"
for i in "${!NAMES[@]}"; do
  printf '  %-14s %s\n' "${NAMES[$i]}" "${RESULTS[$i]}"
done
if [ "$FAILED" != 0 ]; then
  bold "run_examples.sh: FAILED"
  exit 1
fi
bold "run_examples.sh: all examples passed"
