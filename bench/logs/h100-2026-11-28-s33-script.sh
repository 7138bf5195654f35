#!/usr/bin/env bash
# Session 33 device runs. new = working tree, old = out/dev/old.tar (41a38d8).
set -uo pipefail
R=$PWD; O=${OUT:-/tmp/o}; L=/tmp/L; mkdir -p $O $L
export PATH=/usr/local/cuda/bin:$PATH
mkdir -p ~/.cache/nbmc/src && cp -rn out/dev/kk/* ~/.cache/nbmc/src/
D=$R/out/dev/data; BIG=$D/xyz/cbd1654k_t040_1654104.xyz
N=$R/build-cuda
t0=$(date +%s)
for step in "$@"; do case $step in
build)
  NBMC_GPU_CHECK_STEPS=build scripts/gpu_check.sh $D $L/gc > $L/build.txt 2>&1 || { tail -40 $L/build.txt $L/gc/build.log | grep -v "^ *$" | tail -40; exit 1; }
  echo "new built in $(( $(date +%s) - t0 )) s" ;;
oldbg)  # after build: Kokkos is in the cache
  mkdir -p out/oldsrc && tar -xf out/dev/old.tar -C out/oldsrc
  (cd out/oldsrc && NBMC_CUDA_CMAKE_ARGS="-DNBMC_BUILD_TESTS=OFF" NBMC_JOBS=6 scripts/setup.sh --cuda-only > $L/old-build.txt 2>&1; echo "old build rc $? at $(( $(date +%s) - t0 )) s") &
  OLDPID=$! ;;
check)
  { echo "== equivalence (new)"; NBMC_CHECK_BAND=1 $N/tests/gpu/nbmc_cuda_equivalence $D 2>&1 | tail -80; } > $O/equivalence.txt
  tail -1 $O/equivalence.txt; grep FAIL $O/equivalence.txt | head
  NBMC_GPU_CHECK_STEPS="pointers subdomains" scripts/gpu_check.sh $D $L/gc2 > $O/pointers-subdomains.txt 2>&1; echo "pointers+subdomains rc $?"
  grep -i "fail\|DIFFERENT" $O/pointers-subdomains.txt | head
  echo "check done at $(( $(date +%s) - t0 )) s" ;;
trace)
  for b in cuda openmp; do
    NBMC_TRACE=1 $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend $b --threads 16 --repeat 2 > $O/trace-$b.txt 2>&1
  done
  grep -h "clean-up\|post-processing\|RESULT" $O/trace-cuda.txt | tail -24 | cut -c1-260
  echo "trace done at $(( $(date +%s) - t0 )) s" ;;
waitold)
  [ -n "${OLDPID:-}" ] && wait $OLDPID; OLDPID=""
  echo "old waited at $(( $(date +%s) - t0 )) s" ;;
cleanbench)
  $N/src/cli/nbmc reconstruct $BIG --spacing 0.00484 --cell-size 0.5 --no-cleanup -o $L/raw.ply > /dev/null 2>&1
  for t in 1 2 4 8 16; do echo "# threads $t"; NBMC_TRACE=1 stdbuf -oL $N/bench/nbmc_cleanup_bench $L/raw.ply 0.00242 $t 4 2>&1 | awk '/^CLEANUP/{n++} n>=3' | grep -E "CLEANUP|rounds|items=9772|clean-up: "; done > $O/cleanbench.txt 2>&1
  grep -E "^#|CLEANUP|rounds" $O/cleanbench.txt | cut -c1-230
  echo "cleanbench done at $(( $(date +%s) - t0 )) s" ;;
sphbench)
  [ -n "${OLDPID:-}" ] && wait $OLDPID
  OB=$R/out/oldsrc/build-cuda
  {
  for round in 1 2 3; do
    for v in old new; do B=$N; [ $v = old ] && B=$OB
      for m in sph yt10; do
        args="--backend openmp --threads 16 --no-cleanup --repeat 2"
        echo "# $m $v r$round $args"; $B/bench/nbmc_bench $BIG --spacing 0.00484 --method $m $args 2>&1 | grep RESULT
      done
      args="--backend cuda --repeat 5"; echo "# ssp07 $v r$round $args"; $B/bench/nbmc_bench $BIG --spacing 0.00484 $args 2>&1 | grep RESULT
      args="--backend cuda --no-cleanup --repeat 5"; echo "# yt10 $v r$round $args"; $B/bench/nbmc_bench $BIG --spacing 0.00484 --method yt10 $args 2>&1 | grep RESULT
    done
  done
  } > $O/sphbench.txt 2>&1
  grep -A1 "^# " $O/sphbench.txt | grep -o "^# .*\|total=[0-9.]*\| t4=[0-9.]*\| postprocess=[0-9.]*" | paste -sd' ' | sed 's/# /\n/g'
  echo "sphbench done at $(( $(date +%s) - t0 )) s" ;;
esac; done
echo "total $(( $(date +%s) - t0 )) s"
