#!/usr/bin/env bash
# Session 29: CPU scaling on a larger host (1..64 threads), the host's clock under load.
set -uo pipefail
R=$PWD; O=${OUT:-/tmp/o}; L=/tmp/L; mkdir -p $O $L
export PATH=/usr/local/cuda/bin:$PATH
mkdir -p ~/.cache/nbmc/src && cp -rn out/dev/kk/* ~/.cache/nbmc/src/ 2>/dev/null
D=$R/out/dev/data; BIG=$D/xyz/cbd1654k_t040_1654104.xyz
t0=$(date +%s)
(lscpu; nproc; free -g; nvidia-smi -L) > $O/lscpu.txt 2>&1
grep -E "Model name|^CPU\(s\)|Thread|Socket|NUMA node" $O/lscpu.txt
cc -O2 -march=native -pthread bench/clock_probe.c -o /tmp/clock_probe && /tmp/clock_probe 2 1 2 4 8 16 32 64 1 > $O/clock-before.txt 2>&1
NBMC_CUDA_CMAKE_ARGS="-DNBMC_BUILD_TESTS=OFF" NBMC_JOBS=${JOBS:-40} scripts/setup.sh --cuda-only > $L/build.txt 2>&1 || { tail -n 30 $L/build.txt; exit 1; }
echo "built in $(( $(date +%s) - t0 )) s"
N=$R/build-cuda
{
for round in 1 2; do
  for t in ${THREADS:-1 2 4 8 16 32 64}; do
    echo "# ssp07 r/2 defaults openmp $t threads round $round"
    OMP_PROC_BIND=spread OMP_PLACES=cores $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend openmp --threads $t --repeat 2 2>&1 | grep RESULT
  done
done
} > $O/scaling.txt 2>&1
/tmp/clock_probe 1 1 16 32 64 1 > $O/clock-after.txt 2>&1
grep -A1 "^# " $O/scaling.txt | grep -o "^# .*\|total=[0-9.]*\| t[1-5]=[0-9.]*\|postprocess=[0-9.]*" | paste -sd' ' | sed 's/# ssp07 r\/2 defaults openmp /\n/g'
echo; cat $O/clock-before.txt; cat $O/clock-after.txt
OMP_PROC_BIND=spread OMP_PLACES=cores NBMC_TRACE=1 $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend openmp --threads 16 > $O/trace-cpu16.txt 2>&1
echo "total $(( $(date +%s) - t0 )) s"
