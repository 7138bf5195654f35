#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Runs the whole test suite: brings the build up to date (scripts/setup.sh,
# seconds when cached), runs ctest, then builds and runs the C, Rust and
# Fortran consumers against the installed library (scripts/run_examples.sh).
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
BUILD=${NBMC_BUILD_DIR:-$ROOT/build}
"$ROOT/scripts/setup.sh" --no-example
echo "== ctest"
ctest --test-dir "$BUILD" --output-on-failure -j "${NBMC_TEST_JOBS:-2}" --timeout 900
if [ -x "$ROOT/scripts/run_examples.sh" ]; then
  echo "== consumers (C, Rust, Fortran)"
  "$ROOT/scripts/run_examples.sh" "$BUILD/install"
fi
echo "== Python package (pytest)"
"$ROOT/scripts/test_python.sh" "$BUILD/install"

