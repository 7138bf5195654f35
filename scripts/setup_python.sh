#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Installs the nbmc Python package (python/) for Debian's python3, offline,
# so that `python3 -c "import nbmc"` works without environment variables.
#
#   scripts/setup_python.sh [PREFIX]
#
# PREFIX is the install prefix of the C library (PREFIX/lib/libnbmc.so,
# PREFIX/include/nbmc.h); default <repo>/build/install, where scripts/setup.sh
# puts it. The package records PREFIX/lib to find the library later, and takes
# its version from PREFIX/include/nbmc.h (the build stops if the library says
# otherwise).
#
# Environment:
#   NBMC_PYTHON     interpreter to install for (default /usr/bin/python3, Debian's;
#                   it needs numpy, pip, setuptools and wheel)
#   NBMC_SKIP_APT   1: do not install Debian packages
#
# Debian packages (installed only if missing): python3-numpy (the only runtime
# dependency), python3-pip, python3-setuptools, python3-wheel (to build), and
# python3-pytest, python3-h5py (for scripts/test_python.sh). Nothing comes from
# PyPI: pip runs with --no-index --no-build-isolation --no-deps.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
PREFIX=${1:-$ROOT/build/install}
PY=${NBMC_PYTHON:-/usr/bin/python3}
SKIP_APT=${NBMC_SKIP_APT:-0}

say() { printf '\033[1m[setup_python]\033[0m %s\n' "$*"; }
die() { echo "setup_python.sh: $*" >&2; exit 1; }

case "${1:-}" in -h|--help) sed -n '2,23p' "$0"; exit 0 ;; esac
[ -d "$PREFIX" ] || die "no install prefix at $PREFIX (run scripts/setup.sh first, or pass the prefix)"
PREFIX=$(cd "$PREFIX" && pwd)
ls "$PREFIX"/lib/libnbmc.so* >/dev/null 2>&1 || die "$PREFIX/lib has no libnbmc.so"
[ -f "$PREFIX/include/nbmc.h" ] || die "$PREFIX/include has no nbmc.h"

as_root() {
  if [ "$(id -u)" = 0 ]; then "$@"; elif command -v sudo >/dev/null; then sudo "$@"; else
    die "need root (or sudo) to run: $*"; fi
}

APT_PACKAGES=(python3 python3-numpy python3-pip python3-setuptools python3-wheel python3-pytest python3-h5py)
if [ "$SKIP_APT" != 1 ] && command -v dpkg-query >/dev/null; then
  missing=()
  for p in "${APT_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if [ ${#missing[@]} -gt 0 ]; then
    say "installing Debian packages: ${missing[*]}"
    as_root apt-get update -qq
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}"
  fi
fi

command -v "$PY" >/dev/null || die "no interpreter $PY (set NBMC_PYTHON)"
{ "$PY" -c "import setuptools, wheel, numpy" && "$PY" -m pip --version; } >/dev/null 2>&1 ||
  die "$PY lacks numpy, pip, setuptools or wheel (Debian: apt-get install python3-numpy python3-pip python3-setuptools python3-wheel)"

say "installing python/ for $PY (library: $PREFIX/lib)"
# pip >= 23 on Debian 12 refuses to touch the system interpreter without
# --break-system-packages (PEP 668); as root the package goes to
# /usr/local/lib/python3.X/dist-packages, which Debian's python3 reads and apt
# never writes; otherwise pip falls back to the user's site-packages.
rm -rf "$ROOT/python/build" "$ROOT/python/nbmc.egg-info"
NBMC_PREFIX="$PREFIX" PIP_ROOT_USER_ACTION=ignore "$PY" -m pip install --quiet --no-index \
  --no-build-isolation --no-deps --no-cache-dir --force-reinstall --break-system-packages \
  "$ROOT/python"
rm -rf "$ROOT/python/build" "$ROOT/python/nbmc.egg-info"

# The check runs from another folder and without NBMC_LIBRARY, as a user would.
(cd / && env -u NBMC_LIBRARY -u PYTHONPATH "$PY" -c \
  'import nbmc; print("nbmc", nbmc.__version__, "from", nbmc.__file__, "with", nbmc.library_path)') ||
  die "the installed package does not import"
