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
# pointers sanitizers ncu bench"; also "zb05" (the field methods
# side by side, ZB05's band growth traced, ncu on the gather), "limits" (106 M tiled at r/4 and r/8:
# clear errors), "subdomains" (split frames on the GPU
# equal the whole frame and the CPU's, device-resident too), "mpi" (the CLI
# under mpirun, ranks sharing or spreading over the GPUs), "python" (the
# Python package's device arrays), "scale" (13.2 M and 106 M tiled frames,
# whole and out-of-core)), e.g. two calls on one machine:
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
  step "particle attributes on the GPU (device uploads, device meshes, subdomains)"
  "$B/tests/gpu/nbmc_cuda_attributes" 2>&1 | tee "$OUT/attributes.txt" || status=1
  step "per-particle radii on the GPU (OpenMP vs CUDA, device radii, subdomains)"
  "$B/tests/gpu/nbmc_cuda_radii" 2>&1 | tee "$OUT/radii.txt" || status=1
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
CLI="$B/install/bin/nbmc"
MESHES=$(mktemp -d)  # meshes compared here, not copied to OUT
trap 'rm -rf "$MESHES"' EXIT
if want subdomains; then
  step "subdomains on the GPU: the same file as the whole frame and as the CPU (292k frame, r and r/2)"
  F="$DATA/xyz/cbd292k_t040_292008.xyz"
  for cell in 1 0.5; do
    "$CLI" reconstruct "$F" --spacing 0.0086 --cell-size $cell --backend cuda -o "$MESHES/g-whole.ply" -q || status=1
    for s in 2x1x1 3x3x3 auto; do
      extra=""; [ $s = auto ] && extra="--memory-budget 64M"
      "$CLI" reconstruct "$F" --spacing 0.0086 --cell-size $cell --backend cuda -o "$MESHES/g-split.ply" \
        --subdomains $s $extra --json "$OUT/g-split-$s-$cell.json" -q || status=1
      if cmp -s "$MESHES/g-whole.ply" "$MESHES/g-split.ply"; then echo "cell $cell $s: identical"; else echo "cell $cell $s: DIFFERENT"; status=1; fi
    done
    "$B/install/bin/nbmc" reconstruct "$F" --spacing 0.0086 --cell-size $cell --backend openmp -o "$MESHES/c-split.ply" \
      --subdomains 2x2x2 -q || status=1
    python3 - "$MESHES/g-whole.ply" "$MESHES/c-split.ply" <<'PY' || status=1
import sys, struct
def load(p):
    b = open(p, 'rb').read(); h = b.index(b'end_header\n') + 11
    head = b[:h].decode(); nv = int(head.split('element vertex ')[1].split()[0]); nf = int(head.split('element face ')[1].split()[0])
    return nv, nf
a, c = load(sys.argv[1]), load(sys.argv[2])
print("GPU whole vs CPU split: vertices/triangles", a, c, "same topology counts" if a == c else "DIFFERENT")
sys.exit(0 if a == c else 1)
PY
  done
  step "device-resident particles and mesh with subdomains (1.65 M, r/2)"
  "$B/bench/nbmc_bench" "$BIG" --spacing 0.00484 --backend cuda --device-resident --repeat 2 2>&1 | tee "$OUT/dr-whole.txt"
  "$B/bench/nbmc_bench" "$BIG" --spacing 0.00484 --backend cuda --device-resident --repeat 2 --subdomains 2x2x2 2>&1 | tee "$OUT/dr-split.txt"
  python3 - "$OUT/dr-whole.txt" "$OUT/dr-split.txt" <<'PY' || status=1
import sys, re
v = [dict(re.findall(r"(\w+)=([\w.x]+)", open(p).read())) for p in sys.argv[1:]]
ok = all(v[0].get(k) == v[1].get(k) for k in ("vertices", "triangles"))
print("device-resident whole vs 2x2x2:", v[0].get("triangles"), v[1].get("triangles"), "same" if ok else "DIFFERENT")
sys.exit(0 if ok else 1)
PY
fi

if want mpi && [ -x "$CLI" ] && command -v mpirun >/dev/null; then
  step "the CLI under mpirun on $(nvidia-smi -L | wc -l) GPU(s) (1.65 M frame, r/2)"
  MF="$DATA/xyz/cbd1654k_t040_1654104.xyz"
  flags="--oversubscribe"; [ "$(id -u)" = 0 ] && flags="$flags --allow-run-as-root"
  "$CLI" reconstruct "$MF" --spacing 0.00484 --backend cuda -o "$MESHES/m1.ply" --json "$OUT/mpi-1.json" -q || status=1
  for n in 2 4; do
    mpirun $flags -n $n "$CLI" reconstruct "$MF" --spacing 0.00484 --backend cuda -o "$MESHES/m$n.ply" \
      --json "$OUT/mpi-$n.json" -q || status=1
    if cmp -s "$MESHES/m1.ply" "$MESHES/m$n.ply"; then echo "mpirun -n $n: identical to one process"; else echo "mpirun -n $n: DIFFERENT"; status=1; fi
    grep -o '"total_seconds": [0-9.]*' "$OUT/mpi-$n.json" | head -1
  done
fi

if want mpibench && [ -x "$CLI" ] && command -v mpirun >/dev/null; then
  step "MPI on the CPU cores: 4 ranks x 4 threads vs 1 rank x 16 threads (13.2 M frame, r/2), and a 64-frame sequence on 4 ranks vs 1"
  flags="--oversubscribe --bind-to none"; [ "$(id -u)" = 0 ] && flags="$flags --allow-run-as-root"
  T="$MESHES/tiled.xyz"
  python3 - "$BIG" "$T" <<'PY'
import sys, numpy as np
p = np.fromfile(sys.argv[1], dtype="<f4").reshape(-1, 3)
lo, hi = p.min(0), p.max(0)
tiles = [p + np.array([x, y, z], dtype="f4") * 1.1 * (hi - lo) for z in range(2) for y in range(2) for x in range(2)]
np.concatenate(tiles).astype("<f4").tofile(sys.argv[2])
PY
  TIMEFORMAT="%R s"
  echo "1 rank x 16 threads:"; time "$CLI" reconstruct "$T" --spacing 0.00484 --backend openmp --threads 16 -o "$MESHES/t1.ply" -q --no-cleanup
  echo "4 ranks x 4 threads:"; time mpirun $flags -n 4 "$CLI" reconstruct "$T" --spacing 0.00484 --backend openmp --threads 4 -o "$MESHES/t4.ply" -q --no-cleanup
  if cmp -s "$MESHES/t1.ply" "$MESHES/t4.ply"; then echo "identical files"; else echo "DIFFERENT files"; status=1; fi
  mkdir -p "$MESHES/seq"
  for i in $(seq 1 64); do ln -sf "$DATA/xyz/cbd292k_t040_292008.xyz" "$MESHES/seq/f_$i.xyz"; done
  echo "64 frames, 1 rank x 4 threads:"; time "$CLI" reconstruct "$MESHES/seq/f_{}.xyz" --spacing 0.0086 --backend openmp --threads 4 -o "$MESHES/o1/s_{}.ply" -q
  echo "64 frames, 4 ranks x 4 threads:"; time mpirun $flags -n 4 "$CLI" reconstruct "$MESHES/seq/f_{}.xyz" --spacing 0.0086 --backend openmp --threads 4 -o "$MESHES/o4/s_{}.ply" -q
  n=$(ls "$MESHES/o4" | wc -l); echo "$n meshes written by 4 ranks"; [ "$n" = 64 ] || status=1
  cmp -s "$MESHES/o1/s_17.ply" "$MESHES/o4/s_17.ply" && echo "frame 17 identical" || { echo "frame 17 DIFFERENT"; status=1; }
fi

if want python; then
  step "the Python package's GPU paths"
  NBMC_LIBRARY="$B/install/lib/libnbmc.so" python3 "$ROOT/python/tests/gpu_check.py" 2>&1 | tee "$OUT/python-gpu.txt" || status=1
fi

if want scale; then
  step "scale: tiled frames, whole and in subdomains (GPU)"
  for t in 2 4; do
    "$B/bench/nbmc_bench" "$BIG" --spacing 0.00484 --backend cuda --tile $t 2>&1 | tee -a "$OUT/scale.txt"
    "$B/bench/nbmc_bench" "$BIG" --spacing 0.00484 --backend cuda --tile $t --subdomains auto --memory-budget 4096 2>&1 | tee -a "$OUT/scale.txt"
  done
fi
if want zb05; then
  step "field methods (1.65 M frame, r/2): SSP07, ZB05, SPH, YT10 on the GPU and all CPU cores; ZB05's band growth traced; ncu on the gather"
  for m in ssp07 zb05 sph yt10; do
    for be in cuda openmp; do
      "$B/bench/nbmc_bench" "$BIG" --spacing 0.00484 --backend $be --method $m --repeat 3 2>&1 | grep RESULT | tail -1 |
        sed "s/^/$m /" | tee -a "$OUT/methods.txt"
    done
  done
  NBMC_TRACE=1 "$B/bench/nbmc_bench" "$BIG" --spacing 0.00484 --backend cuda --method zb05 >"$OUT/zb05-trace.txt" 2>&1
  if command -v ncu >/dev/null; then
    for m in ssp07 zb05; do
      timeout 240 ncu --section SpeedOfLight --section Occupancy --section LaunchStats --section MemoryWorkloadAnalysis \
        --kernel-name-base demangled -k regex:gather --launch-count 2 "$B/bench/nbmc_bench" "$BIG" --spacing 0.00484 \
        --backend cuda --method $m >"$OUT/ncu-$m.txt" 2>&1
      echo "ncu $m:"; grep -E "Duration|Registers Per|Achieved Occupancy" "$OUT/ncu-$m.txt" | head -6
    done
  fi
fi

if want limits; then
  step "size limits: the 1.65 M frame tiled 4x4x4 (106 M) at r/4 and r/8 on the GPU (clear errors, no internal error)"
  for cell in 0.25 0.125; do
    for s in 1x1x1 auto; do
      [ $cell = 0.125 ] && [ $s = auto ] && continue  # works, but takes minutes
      timeout 200 "$B/bench/nbmc_bench" "$BIG" --spacing 0.00484 --backend cuda --tile 4 --cell-size $cell --subdomains $s --no-cleanup >"$MESHES/limit.txt" 2>&1
      rc=$?
      tail -3 "$MESHES/limit.txt" | cut -c1-600 | tee -a "$OUT/limits.txt"
      echo "rc=$rc cell=$cell subdomains=$s" | tee -a "$OUT/limits.txt"
    done
  done
fi

want bench && step "benchmarks: $BIG"
want bench && for cell in 1 0.5; do
  "$B/bench/nbmc_bench" "$BIG" --spacing 0.00484 --cell-size $cell --backend cuda --repeat 5 2>&1 | tee -a "$OUT/bench.txt"
  "$B/bench/nbmc_bench" "$BIG" --spacing 0.00484 --cell-size $cell --backend cuda --repeat 5 --device-resident 2>&1 | tee -a "$OUT/bench.txt"
  "$B/bench/nbmc_bench" "$BIG" --spacing 0.00484 --cell-size $cell --backend openmp --threads "$(nproc)" --repeat 3 2>&1 | tee -a "$OUT/bench.txt"
done
exit $status
