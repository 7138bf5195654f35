#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Runs the Python package's tests (python/tests, pytest) against an installed
# C library; exits non-zero when any test fails.
#
#   scripts/test_python.sh [PREFIX] [PYTEST ARGS...]
#
# PREFIX: install prefix of the C library (default <repo>/build/install); its
# lib/libnbmc.so is loaded, its bin/nbmc is the CLI the meshes are compared
# with bit for bit, and its include/nbmc.h is checked against the ctypes
# declarations. The package under test is this checkout's python/nbmc; the
# pip-installed copy (scripts/setup_python.sh) is checked too when present.
# NBMC_PYTHON chooses the interpreter (default /usr/bin/python3).
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
PREFIX=${1:-$ROOT/build/install}
[ $# -gt 0 ] && shift
PY=${NBMC_PYTHON:-/usr/bin/python3}

[ -d "$PREFIX" ] || { echo "test_python.sh: no install prefix at $PREFIX" >&2; exit 1; }
PREFIX=$(cd "$PREFIX" && pwd)
"$PY" -c "import numpy, pytest" 2>/dev/null || {
  echo "test_python.sh: $PY lacks numpy or pytest (run scripts/setup_python.sh)" >&2; exit 1; }

echo "== python tests ($PY, library $PREFIX)"
cd "$ROOT/python"
NBMC_PREFIX="$PREFIX" NBMC_LIBRARY="$PREFIX/lib/libnbmc.so" \
  "$PY" -m pytest -q -p no:cacheprovider tests "$@"
