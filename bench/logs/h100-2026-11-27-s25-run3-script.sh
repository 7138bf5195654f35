#!/usr/bin/env bash
# Session 25, device run 3: the mesh's host pages faulted in while the GPU
# computes it (NBMC_PREFAULT_MESH=0: as before), alternated; equivalence.
set -uo pipefail
R=$PWD; O=${OUT:-/tmp/o}; L=/tmp/L; mkdir -p $O $L
export PATH=/usr/local/cuda/bin:$PATH
mkdir -p ~/.cache/nbmc/src && cp -r out/dev/kk/* ~/.cache/nbmc/src/
D=$R/out/dev/data; BIG=$D/xyz/cbd1654k_t040_1654104.xyz
t0=$(date +%s)
NBMC_GPU_CHECK_STEPS=build scripts/gpu_check.sh $D $L/gc > $L/build.txt 2>&1 || { tail -40 $L/build.txt; exit 1; }
echo "built in $(( $(date +%s) - t0 )) s"
N=$R/build-cuda
{
for round in 1 2 3 4; do
  for v in off on; do
    E="NBMC_PREFAULT_MESH=1"; [ $v = off ] && E="NBMC_PREFAULT_MESH=0"
    for args in "--no-cleanup --tile 2" "--no-cleanup" "" "--cell-size 1 --no-cleanup"; do
      echo "# prefault $v r$round $args"; env $E $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda $args 2>&1 | grep RESULT
    done
  done
done
} > $O/bench.txt 2>&1
grep -A1 "^# prefault" $O/bench.txt | grep -o "^# .*\|total=[0-9.]*\|t5=[0-9.]*\|t6=[0-9.]*" | paste -sd' ' | sed 's/# /\n/g'
for v in 0 1; do NBMC_PREFAULT_MESH=$v $N/install/bin/nbmc reconstruct $BIG --spacing 0.00484 --backend cuda -o $L/m$v.ply -q; done
cmp $L/m0.ply $L/m1.ply && echo "meshes: same file with and without"
{ echo "== equivalence"; NBMC_CHECK_BAND=1 $N/tests/gpu/nbmc_cuda_equivalence $D 2>&1 | tail -4; } > $O/equivalence.txt; tail -2 $O/equivalence.txt
NBMC_GPU_CHECK_STEPS="pointers subdomains" scripts/gpu_check.sh $D $L/gc2 > $O/pointers-subdomains.txt 2>&1; echo "pointers+subdomains rc $?"
echo "total $(( $(date +%s) - t0 )) s"
