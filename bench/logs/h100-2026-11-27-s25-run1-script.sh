#!/usr/bin/env bash
# Session 25, device run 1: build the working tree (new) and c577b40 (old),
# GPU meshes new(warp) vs new(vertices) vs old, equivalence, benchmarks, ncu.
set -uo pipefail
R=$PWD; O=${OUT:-/tmp/o}; L=/tmp/L; mkdir -p $O $L
export PATH=/usr/local/cuda/bin:$PATH
mkdir -p ~/.cache/nbmc/src && cp -r out/dev/kk/* ~/.cache/nbmc/src/
D=$R/out/dev/data; BIG=$D/xyz/cbd1654k_t040_1654104.xyz; MID=$D/xyz/cbd292k_t040_292008.xyz
t0=$(date +%s)
NBMC_GPU_CHECK_STEPS=build scripts/gpu_check.sh $D $L/gc > $L/build.txt 2>&1 || { tail -40 $L/build.txt $L/gc/build.log; cp $L/gc/build.log $O/; exit 1; }
echo "new built in $(( $(date +%s) - t0 )) s"
mkdir -p /tmp/old && tar -xf out/dev/old.tar -C /tmp/old
(cd /tmp/old && NBMC_CUDA_CMAKE_ARGS="-DNBMC_BUILD_TESTS=OFF" NBMC_JOBS=8 scripts/setup.sh --cuda-only > $L/old-build.txt 2>&1; echo "old build rc $?") &
OLDPID=$!
N=$R/build-cuda; OB=/tmp/old/build-cuda
{ echo "== equivalence (new, warp gather)"; NBMC_CHECK_BAND=1 $N/tests/gpu/nbmc_cuda_equivalence $D 2>&1 | tail -25; } > $O/equivalence.txt
wait $OLDPID; tail -3 $L/old-build.txt
{
echo "== GPU meshes: warp vs vertices (new) vs old, byte for byte"
for spec in "$MID 0.0086" "$BIG 0.00484"; do set -- $spec
  for m in ssp07 zb05 sph yt10; do for c in 1 0.5; do
    [ $1 = $BIG ] && [ $m != ssp07 ] && [ $c = 1 ] && continue
    $N/install/bin/nbmc reconstruct $1 --spacing $2 --cell-size $c --method $m --backend cuda -o $L/w.ply -q
    NBMC_GPU_GATHER=vertices $N/install/bin/nbmc reconstruct $1 --spacing $2 --cell-size $c --method $m --backend cuda -o $L/v.ply -q
    $OB/install/bin/nbmc reconstruct $1 --spacing $2 --cell-size $c --method $m --backend cuda -o $L/o.ply -q
    echo "$(basename $1) $m c$c: warp/vertices $(cmp -s $L/w.ply $L/v.ply && echo same || echo DIFFERENT), warp/old $(cmp -s $L/w.ply $L/o.ply && echo same || echo DIFFERENT) $(md5sum < $L/w.ply | cut -c1-8)"
  done; done
done
} 2>&1 | tee $O/meshes.txt
NBMC_GPU_CHECK_STEPS="pointers subdomains" scripts/gpu_check.sh $D $L/gc2 > $O/pointers-subdomains.txt 2>&1; echo "pointers+subdomains rc $?"
{
for round in 1 2 3; do
  for v in old vertices warp; do
    B=$N; E=""; [ $v = old ] && B=$OB; [ $v = vertices ] && E="NBMC_GPU_GATHER=vertices"
    for args in "--no-cleanup" "--no-cleanup --device-resident" "" "--no-cleanup --tile 2" "--no-cleanup --method zb05" "--no-cleanup --method sph" "--no-cleanup --method yt10" "--cell-size 1"; do
      echo "# $v r$round $args"; env $E $B/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda $args 2>&1 | grep RESULT
    done
  done
done
} > $O/bench.txt 2>&1
grep -c RESULT $O/bench.txt
for k in vertices warp; do
  NBMC_GPU_GATHER=$k timeout 200 ncu --section SpeedOfLight --section Occupancy --section LaunchStats --section WarpStateStats \
    --metrics smsp__inst_executed.sum,smsp__thread_inst_executed_per_inst_executed.ratio \
    --kernel-name-base demangled -k regex:gather_$k --launch-count 1 $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --no-cleanup > $O/ncu-$k.txt 2>&1
  echo "ncu $k:"; grep -E "Duration|Registers Per|Achieved Occupancy|inst_executed|Avg. Active" $O/ncu-$k.txt | head -8
done
echo "total $(( $(date +%s) - t0 )) s"
