#!/usr/bin/env bash
# Session 29: 16-64 threads on the 64-vCPU host: OpenMP wait policy and binding.
set -uo pipefail
R=$PWD; O=${OUT:-/tmp/o}; L=/tmp/L; mkdir -p $O $L
export PATH=/usr/local/cuda/bin:$PATH
mkdir -p ~/.cache/nbmc/src && cp -rn out/dev/kk/* ~/.cache/nbmc/src/ 2>/dev/null
D=$R/out/dev/data; BIG=$D/xyz/cbd1654k_t040_1654104.xyz
t0=$(date +%s)
nproc; grep -m1 "model name" /proc/cpuinfo
NBMC_CUDA_CMAKE_ARGS="-DNBMC_BUILD_TESTS=OFF" NBMC_JOBS=48 scripts/setup.sh --cuda-only > $L/build.txt 2>&1 || { tail -n 30 $L/build.txt; exit 1; }
echo "built in $(( $(date +%s) - t0 )) s"
N=$R/build-cuda
{
for round in 1 2; do
  for t in 1 16 32 64; do
    for v in active passive unbound-active unbound-passive; do
      [ $t = 1 ] && [ $v != active ] && continue
      case $v in
        active) E="OMP_PROC_BIND=spread OMP_PLACES=cores OMP_WAIT_POLICY=active" ;;
        passive) E="OMP_PROC_BIND=spread OMP_PLACES=cores OMP_WAIT_POLICY=passive" ;;
        unbound-active) E="OMP_WAIT_POLICY=active" ;;
        unbound-passive) E="OMP_WAIT_POLICY=passive" ;;
      esac
      echo "# $t $v round $round"
      env $E $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend openmp --threads $t --repeat 2 2>&1 | grep RESULT
    done
  done
done
echo "# default environment (no OMP_* set), 64 threads"
$N/bench/nbmc_bench $BIG --spacing 0.00484 --backend openmp --repeat 2 2>&1 | grep RESULT
} > $O/policy.txt 2>&1
grep -A1 "^# " $O/policy.txt | grep -o "^# .*\|total=[0-9.]*\| t4=[0-9.]*\|postprocess=[0-9.]*" | paste -sd' ' | sed 's/# /\n/g'
OMP_WAIT_POLICY=passive NBMC_TRACE=1 $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend openmp --threads 64 > $O/trace-cpu64-passive.txt 2>&1
OMP_WAIT_POLICY=active NBMC_TRACE=1 $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend openmp --threads 64 > $O/trace-cpu64-active.txt 2>&1
echo "total $(( $(date +%s) - t0 )) s"
