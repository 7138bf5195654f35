#!/usr/bin/env bash
# Session 25, device run 2: the host's clock under load (bench/clock_probe.c),
# CPU scaling per stage (1..16 threads), traces at 1 and 16 threads, GPU traces.
set -uo pipefail
R=$PWD; O=${OUT:-/tmp/o}; L=/tmp/L; mkdir -p $O $L
export PATH=/usr/local/cuda/bin:$PATH
mkdir -p ~/.cache/nbmc/src && cp -r out/dev/kk/* ~/.cache/nbmc/src/
D=$R/out/dev/data; BIG=$D/xyz/cbd1654k_t040_1654104.xyz
t0=$(date +%s)
(lscpu; nproc; cat /proc/cpuinfo | grep -m1 flags | tr ' ' '\n' | grep -c avx512) > $O/lscpu.txt 2>&1
cc -O2 -march=native -pthread bench/clock_probe.c -o /tmp/clock_probe && /tmp/clock_probe 3 | tee $O/clock.txt
NBMC_GPU_CHECK_STEPS=build scripts/gpu_check.sh $D $L/gc > $L/build.txt 2>&1 || { tail -40 $L/build.txt; exit 1; }
echo "built in $(( $(date +%s) - t0 )) s"
N=$R/build-cuda
{
for round in 1 2; do
  for t in 1 2 4 8 16; do
    [ $t = 1 ] && [ $round = 2 ] && continue
    echo "# ssp07 r/2 defaults openmp $t threads round $round"
    $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend openmp --threads $t 2>&1 | grep RESULT
  done
done
echo "# clock probe again"; /tmp/clock_probe 1
for round in 1 2 3; do
  echo "# gpu no-cleanup round $round"; $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --no-cleanup 2>&1 | grep RESULT
  echo "# gpu device-resident no-cleanup round $round"; $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --no-cleanup --device-resident 2>&1 | grep RESULT
  echo "# gpu defaults round $round"; $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda 2>&1 | grep RESULT
done
} > $O/scaling.txt 2>&1
cat $O/scaling.txt | sed 's/particles=.*total=/total=/' | cut -c1-200
NBMC_TRACE=1 $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend openmp --threads 1 > $O/trace-cpu1.txt 2>&1
NBMC_TRACE=1 $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend openmp --threads 16 > $O/trace-cpu16.txt 2>&1
NBMC_TRACE=1 $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --no-cleanup --device-resident --repeat 2 > $O/trace-gpu-dr.txt 2>&1
echo "total $(( $(date +%s) - t0 )) s"
