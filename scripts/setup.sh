#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Brings a fresh Debian 12 machine to a working nbmc build, then (by default)
# reconstructs the included example frame.
#
#   scripts/setup.sh                 deps + Kokkos (OpenMP+Serial) + nbmc + example mesh
#   scripts/setup.sh --no-example    same, without running the example
#   scripts/setup.sh --cuda          also build Kokkos with CUDA (+OpenMP host) for
#                                    Hopper (sm_90) and an nbmc variant in build-cuda/
#   scripts/setup.sh --kokkos-only   stop after Kokkos
#   scripts/setup.sh --cuda-only     only the CUDA build (GPU machines without the
#                                    Debian packages; see scripts/gpu_check.sh)
#
# Environment:
#   NBMC_CACHE        where the Kokkos source and builds are cached
#                     (default: ~/.cache/nbmc); a second run takes seconds.
#   NBMC_BUILD_DIR    nbmc build directory (default: <repo>/build)
#   NBMC_JOBS         parallel build jobs (default: nproc)
#   NBMC_CUDA_ARCH    Kokkos architecture for the CUDA build (default: HOPPER90)
#   CXX               the C++ compiler (default: c++, i.e. GCC on Debian). Kokkos
#                     and nbmc are built by the same one (their OpenMP runtimes
#                     must match); a Clang build keeps its own Kokkos
#                     (<cache>/kokkos-...-openmp-clang) and needs libomp-dev.
#
# Kokkos comes from the source of Debian's `trilinos` package (packages/kokkos,
# Kokkos 3.4.01); the patches in scripts/kokkos-patches/ make it build with
# CUDA 13 and run on Hopper. Nothing is downloaded from outside Debian's archive.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
CACHE=${NBMC_CACHE:-$HOME/.cache/nbmc}
BUILD=${NBMC_BUILD_DIR:-$ROOT/build}
JOBS=${NBMC_JOBS:-$(nproc)}
CUDA_ARCH=${NBMC_CUDA_ARCH:-HOPPER90}
KOKKOS_VERSION=3.4.01
WITH_CUDA=0
CUDA_ONLY=0
RUN_EXAMPLE=1
KOKKOS_ONLY=0
SKIP_APT=${NBMC_SKIP_APT:-0}

for arg in "$@"; do
  case "$arg" in
    --cuda) WITH_CUDA=1 ;;
    --cuda-only) WITH_CUDA=1; CUDA_ONLY=1; RUN_EXAMPLE=0; SKIP_APT=1 ;;
    --no-example) RUN_EXAMPLE=0 ;;
    --kokkos-only) KOKKOS_ONLY=1; RUN_EXAMPLE=0 ;;
    --skip-apt) SKIP_APT=1 ;;
    -h|--help) sed -n '2,22p' "$0"; exit 0 ;;
    *) echo "setup.sh: unknown option '$arg' (see --help)" >&2; exit 2 ;;
  esac
done

say() { printf '\033[1m[setup]\033[0m %s\n' "$*"; }

as_root() {
  if [ "$(id -u)" = 0 ]; then "$@"; elif command -v sudo >/dev/null; then sudo "$@"; else
    echo "setup.sh: need root (or sudo) to run: $*" >&2; exit 1; fi
}

# ---------------------------------------------------------------- 1. packages
# python3-paraview: the test that opens nbmc's .xdmf meshes with ParaView's
# XDMF readers (tests/xdmf/check_xdmf.py; skipped without it).
APT_PACKAGES=(build-essential cmake ninja-build pkg-config zlib1g-dev libhdf5-dev
              libgtest-dev libcli11-dev gfortran patch xz-utils
              libopenmpi-dev openmpi-bin cargo python3-paraview)
# The host compiler's family: Kokkos' OpenMP build is kept per family (GCC's
# under the old name), since Kokkos and nbmc must share one OpenMP runtime.
CXX_TAG=""
if "${CXX:-c++}" --version 2>/dev/null | head -n1 | grep -qi clang; then
  CXX_TAG=-clang
  APT_PACKAGES+=(clang libomp-dev)
fi
install_packages() {
  [ "$SKIP_APT" = 1 ] && return 0
  command -v dpkg-query >/dev/null || { say "not a Debian system: skipping apt"; return 0; }
  local missing=()
  for p in "${APT_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if [ ${#missing[@]} -gt 0 ]; then
    say "installing Debian packages: ${missing[*]}"
    # Without a reachable archive (GPU machines): go on with what is there;
    # the build says what is missing (CLI11 and MPI are optional).
    if ! as_root apt-get update -qq || ! as_root env DEBIAN_FRONTEND=noninteractive \
         apt-get install -y -qq --no-install-recommends "${missing[@]}"; then
      say "could not install ${missing[*]}: continuing with the packages already installed"
    fi
  fi
}

# ------------------------------------------------------- 2. Kokkos source
# A deb-src entry is derived from the machine's own apt sources (no host name
# is written here): every "Types: deb" stanza of the deb822 files, or every
# "deb " line of the one-line format, is repeated as deb-src.
ensure_deb_src() {
  if grep -rqsE '^(deb-src|Types:.*deb-src)' /etc/apt/sources.list /etc/apt/sources.list.d/; then return 0; fi
  say "adding deb-src entries derived from the existing apt sources"
  local tmp; tmp=$(mktemp)
  for f in /etc/apt/sources.list.d/*.sources; do
    [ -f "$f" ] || continue
    awk 'BEGIN{RS=""; ORS="\n\n"} /(^|\n)Types:[ \t]*deb([ \t]|\n|$)/ { sub(/Types:[ \t]*deb/, "Types: deb-src"); print }' "$f" >>"$tmp"
  done
  if [ -s "$tmp" ]; then
    as_root cp "$tmp" /etc/apt/sources.list.d/nbmc-deb-src.sources
  else
    grep -hE '^deb ' /etc/apt/sources.list /etc/apt/sources.list.d/*.list 2>/dev/null | sed 's/^deb /deb-src /' >"$tmp" || true
    [ -s "$tmp" ] || { echo "setup.sh: no apt source found to derive deb-src from" >&2; exit 1; }
    as_root cp "$tmp" /etc/apt/sources.list.d/nbmc-deb-src.list
  fi
  rm -f "$tmp"
  as_root apt-get update -qq
}

PATCH_HASH=$(cat "$ROOT"/scripts/kokkos-patches/*.patch | sha256sum | cut -c1-10)
KOKKOS_SRC=$CACHE/src/kokkos-$KOKKOS_VERSION-$PATCH_HASH

fetch_kokkos() {
  [ -f "$KOKKOS_SRC/.nbmc-ready" ] && return 0
  ensure_deb_src
  local dl; dl=$(mktemp -d)
  say "fetching Debian's trilinos source package (contains Kokkos $KOKKOS_VERSION)"
  (cd "$dl" && apt-get source --download-only -q trilinos >/dev/null)
  local tarball; tarball=$(ls "$dl"/trilinos_*.orig.tar.* | head -n1)
  say "extracting packages/kokkos"
  tar -xf "$tarball" -C "$dl" --wildcards '*/packages/kokkos/*'
  rm -rf "$KOKKOS_SRC"; mkdir -p "$(dirname "$KOKKOS_SRC")"
  mv "$dl"/*/packages/kokkos "$KOKKOS_SRC"
  rm -rf "$dl"
  grep -q "set(Kokkos_VERSION_MINOR 4)" "$KOKKOS_SRC/CMakeLists.txt" ||
    { echo "setup.sh: unexpected Kokkos version in the trilinos source" >&2; exit 1; }
  for p in "$ROOT"/scripts/kokkos-patches/*.patch; do
    say "applying $(basename "$p")"
    patch -s -d "$KOKKOS_SRC" -p1 <"$p"
  done
  touch "$KOKKOS_SRC/.nbmc-ready"
}

# ------------------------------------------------------- 3. Kokkos builds
build_kokkos() { # $1 = variant (openmp|cuda)
  local variant=$1 prefix=$CACHE/kokkos-$KOKKOS_VERSION-$PATCH_HASH-$1
  if [ "$variant" = cuda ]; then prefix=$prefix-$CUDA_ARCH; else prefix=$prefix$CXX_TAG; fi
  KOKKOS_PREFIX=$prefix
  [ -f "$prefix/.nbmc-ready" ] && return 0
  local bdir=$CACHE/build/kokkos-$variant$CXX_TAG
  rm -rf "$bdir" "$prefix"
  local args=(-G Ninja -S "$KOKKOS_SRC" -B "$bdir" -DCMAKE_BUILD_TYPE=Release
              -DCMAKE_INSTALL_PREFIX="$prefix" -DBUILD_SHARED_LIBS=ON
              -DCMAKE_POSITION_INDEPENDENT_CODE=ON -DCMAKE_CXX_STANDARD=17
              -DKokkos_ENABLE_SERIAL=ON -DKokkos_ENABLE_OPENMP=ON
              -DKokkos_ENABLE_TESTS=OFF -DKokkos_ENABLE_EXAMPLES=OFF)
  if [ "$variant" = cuda ]; then
    command -v nvcc >/dev/null || export PATH=$PATH:/usr/local/cuda/bin
    command -v nvcc >/dev/null || { echo "setup.sh: --cuda needs nvcc on PATH" >&2; exit 1; }
    args+=(-DKokkos_ENABLE_CUDA=ON -DKokkos_ENABLE_CUDA_LAMBDA=ON
           -DKokkos_ENABLE_CUDA_CONSTEXPR=ON -DKokkos_ARCH_${CUDA_ARCH}=ON
           -DCMAKE_CXX_COMPILER="$KOKKOS_SRC/bin/nvcc_wrapper")
  else
    # GCC 13 (Ubuntu 24.04, the GPU machines) no longer includes <cstdint>
    # through <string>, which Kokkos 3.4's Kokkos_MemoryPool.cpp relied on.
    args+=(-DCMAKE_CXX_FLAGS="-include cstdint")
  fi
  say "building Kokkos $KOKKOS_VERSION ($variant) into $prefix"
  cmake "${args[@]}" >"$CACHE/kokkos-$variant-configure.log" 2>&1 ||
    { tail -40 "$CACHE/kokkos-$variant-configure.log"; exit 1; }
  cmake --build "$bdir" -j "$JOBS" >"$CACHE/kokkos-$variant-build.log" 2>&1 ||
    { tail -40 "$CACHE/kokkos-$variant-build.log"; exit 1; }
  cmake --install "$bdir" >/dev/null
  rm -rf "$bdir"
  touch "$prefix/.nbmc-ready"
}

# ------------------------------------------------------- 4. nbmc
build_nbmc() { # $1 = build dir, $2 = kokkos prefix, rest = extra cmake args
  local bdir=$1 kprefix=$2; shift 2
  say "building nbmc in $bdir"
  cmake -G Ninja -S "$ROOT" -B "$bdir" -DCMAKE_BUILD_TYPE=Release \
        -DKokkos_ROOT="$kprefix" -DCMAKE_INSTALL_PREFIX="$bdir/install" "$@" >/dev/null
  cmake --build "$bdir" -j "$JOBS"
  cmake --install "$bdir" >/dev/null
}

mkdir -p "$CACHE"
install_packages
fetch_kokkos
if [ "$CUDA_ONLY" = 0 ]; then build_kokkos openmp; KOKKOS_OPENMP=$KOKKOS_PREFIX; fi
if [ "$WITH_CUDA" = 1 ]; then build_kokkos cuda; KOKKOS_CUDA=$KOKKOS_PREFIX; fi
[ "$KOKKOS_ONLY" = 1 ] && { say "Kokkos ready in $KOKKOS_PREFIX"; exit 0; }

if [ "$CUDA_ONLY" = 0 ]; then
  build_nbmc "$BUILD" "$KOKKOS_OPENMP" -DNBMC_BUILD_CLI=ON -DNBMC_BUILD_TESTS=ON -DNBMC_BUILD_BENCH=ON
  say "nbmc installed in $BUILD/install (command: $BUILD/install/bin/nbmc)"
  # The Python package, for Debian's /usr/bin/python3 (offline: no downloads).
  if [ "${NBMC_SKIP_PYTHON:-0}" != 1 ]; then
    NBMC_SKIP_APT=$SKIP_APT "$ROOT/scripts/setup_python.sh" "$BUILD/install"
  fi
fi
if [ "$WITH_CUDA" = 1 ]; then
  # The CUDA variant: library, CLI (CLI11 from third_party/ when the system
  # has none), benchmark and GPU checks. Tests need Debian's GoogleTest, which
  # GPU machines may lack: NBMC_CUDA_CMAKE_ARGS=-DNBMC_BUILD_TESTS=OFF.
  build_nbmc "${NBMC_CUDA_BUILD_DIR:-$ROOT/build-cuda}" "$KOKKOS_CUDA" \
    -DCMAKE_CXX_COMPILER="$KOKKOS_SRC/bin/nvcc_wrapper" ${NBMC_CUDA_CMAKE_ARGS:-}
  say "CUDA variant built in ${NBMC_CUDA_BUILD_DIR:-$ROOT/build-cuda}"
fi

if [ "$RUN_EXAMPLE" = 1 ]; then
  mkdir -p "$ROOT/out"
  say "reconstructing the example frame examples/data/double_dam_break_4732.xyz"
  "$BUILD/install/bin/nbmc" reconstruct "$ROOT/examples/data/double_dam_break_4732.xyz" \
    --particle-radius 0.025 -o "$ROOT/out/double_dam_break.ply"
  say "mesh written to out/double_dam_break.ply"
fi
