#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# On a machine with an NVIDIA GPU (Hopper by default; NBMC_CUDA_ARCH=AMPERE80
# etc. for others): builds the CUDA variant, then runs the CPU/GPU
# equivalence check, compute-sanitizer (memcheck, racecheck) on a small frame,
# and the benchmarks on the largest frame, GPU and all CPU cores.
#
#   scripts/gpu_check.sh [DATA_DIR] [OUT_DIR]
#
# NBMC_GPU_CHECK_STEPS picks steps (default: all of "build equivalence
# pointers sanitizers ncu bench"), e.g. two calls on one machine:
# "build equivalence pointers sanitizers", then "bench".
#
# DATA_DIR holds xyz/*.xyz (default ../shared/data); logs go to OUT_DIR
# (default out/gpu). Needs nvcc, cmake, ninja and a C++17 compiler; the
# Kokkos source comes from scripts/setup.sh's cache (NBMC_CACHE), which a
# machine without Debian's archive must be given (copy ~/.cache/nbmc/src).
set -uo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
DATA=${1:-$ROOT/../shared/data}
OUT=${2:-$ROOT/out/gpu}
mkdir -p "$OUT"
export PATH=/usr/local/cuda/bin:$PATH
B=${NBMC_CUDA_BUILD_DIR:-$ROOT/build-cuda}
status=0
STEPS=" ${NBMC_GPU_CHECK_STEPS:-build equivalence pointers sanitizers ncu bench} "
want() { [[ "$STEPS" == *" $1 "* ]]; }
step() { echo; echo "== $*"; }

if want build; then
  step "build (Kokkos CUDA + nbmc CUDA variant)"
  t0=$(date +%s)
  NBMC_CUDA_CMAKE_ARGS="-DNBMC_BUILD_TESTS=OFF ${NBMC_CUDA_CMAKE_ARGS:-}" \
    NBMC_JOBS=${NBMC_JOBS:-$(nproc)} "$ROOT/scripts/setup.sh" --cuda-only >"$OUT/build.log" 2>&1 ||
    { tail -50 "$OUT/build.log"; exit 1; }
  echo "built in $(( $(date +%s) - t0 )) s"
fi
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader | tee "$OUT/device.txt"

if want equivalence; then
  step "CPU (OpenMP) vs GPU (CUDA) equivalence"
  NBMC_CHECK_BAND=1 "$B/tests/gpu/nbmc_cuda_equivalence" "$DATA" 2>&1 | tee "$OUT/equivalence.txt" || status=1
fi

if want pointers; then
  step "device pointers in the C API"
  "$B/tests/gpu/nbmc_cuda_device_pointers" "$DATA" 2>&1 | tee "$OUT/device-pointers.txt" || status=1
fi

SMALL="$DATA/xyz/splashsurf_doubledambreak_f26_4732.xyz"
want sanitizers && for tool in memcheck racecheck; do
  step "compute-sanitizer --tool $tool (4,732 particles, cell r)"
  # racecheck exits non-zero on warnings too; what counts is "0 errors"
  compute-sanitizer --tool $tool --print-level warn "$B/bench/nbmc_bench" "$SMALL" --spacing 0.05 \
    --cell-size 1 --backend cuda >"$OUT/sanitizer-$tool.txt" 2>&1
  tail -2 "$OUT/sanitizer-$tool.txt"
  grep -qE "ERROR SUMMARY: 0 errors|\(0 errors," "$OUT/sanitizer-$tool.txt" || status=1
done
if want sanitizers; then
  step "racecheck hazards by kernel (all inside Kokkos' ParallelReduce so far)"
  grep "Race reported" "$OUT/sanitizer-racecheck.txt" | grep -oE "Parallel(Reduce|For|Scan)<Kokkos::Impl::CudaFunctorAdapter<[^:]*nbmc::Details::[a-z_]+" |
    sed -E "s/<Kokkos::Impl::CudaFunctorAdapter<[^:]*nbmc::Details::/ /" | sort | uniq -c
  step "compute-sanitizer --tool memcheck on the device-pointer test (shapes only)"
  compute-sanitizer --tool memcheck --error-exitcode 3 "$B/tests/gpu/nbmc_cuda_device_pointers" /nonexistent \
    >"$OUT/sanitizer-memcheck-device-pointers.txt" 2>&1 || status=1
  tail -2 "$OUT/sanitizer-memcheck-device-pointers.txt"
fi

if want ncu && command -v ncu >/dev/null; then
  step "ncu: the team-tiled gather (NBMC_GPU_GATHER=team) against the direct one, 46k frame, cell r"
  for k in team direct; do
    NBMC_GPU_GATHER=$k timeout 180 ncu --section SpeedOfLight --section Occupancy --section LaunchStats \
      --kernel-name-base demangled -k regex:gather --launch-count 1 "$B/bench/nbmc_bench" "$DATA/xyz/cbd46k_t050_46250.xyz" \
      --spacing 0.0156 --cell-size 1 --backend cuda >"$OUT/ncu-$k.txt" 2>&1
    grep -E "Duration|Throughput|Registers|Achieved Occupancy|Theoretical Occupancy|Block Size|Shared Memory|Local" \
      "$OUT/ncu-$k.txt" | head -20
  done
fi

BIG="$DATA/xyz/cbd1654k_t040_1654104.xyz"
want bench && step "benchmarks: $BIG"
want bench && for cell in 1 0.5; do
  "$B/bench/nbmc_bench" "$BIG" --spacing 0.00484 --cell-size $cell --backend cuda --repeat 5 2>&1 | tee -a "$OUT/bench.txt"
  "$B/bench/nbmc_bench" "$BIG" --spacing 0.00484 --cell-size $cell --backend cuda --repeat 5 --device-resident 2>&1 | tee -a "$OUT/bench.txt"
  "$B/bench/nbmc_bench" "$BIG" --spacing 0.00484 --cell-size $cell --backend openmp --threads "$(nproc)" --repeat 3 2>&1 | tee -a "$OUT/bench.txt"
done
exit $status
