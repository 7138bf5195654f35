#!/usr/bin/env bash
# Session 36 device runs. new = working tree, old = out/dev/old.tar (e8312a8).
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
sanit)
  NBMC_GPU_CHECK_STEPS="sanitizers" scripts/gpu_check.sh $D $L/gc3 > $O/sanitizers.txt 2>&1; echo "sanitizers rc $?"
  grep -iE "error summary|errors|hazard" $O/sanitizers.txt | head -12
  echo "sanitizers done at $(( $(date +%s) - t0 )) s" ;;
mpi)
  NBMC_GPU_CHECK_STEPS="mpi" scripts/gpu_check.sh $D $L/gc4 > $O/mpi.txt 2>&1; echo "mpi rc $?"
  grep -iE "identical|DIFFERENT|total_seconds" $O/mpi.txt | head -12
  echo "mpi done at $(( $(date +%s) - t0 )) s" ;;
tracenew)
  for a in "" "--device-resident"; do
    NBMC_TRACE=1 $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda $a --repeat 3 > $O/trace-new$a.txt 2>&1
    echo "# new $a"; grep -h "incidence\|clean-up: \|download\|upload\|post-processing\|stage done .*n=6" $O/trace-new$a.txt | tail -12 | cut -c1-160
  done
  for r in 1 2 3; do for a in "" "--device-resident"; do
    echo "# new $a r$r $(($N/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda $a --repeat 5 2>&1 | grep RESULT) | grep -o 'total=[0-9.]*\| postprocess=[0-9.]*' | paste -sd' ')"
  done; done | tee $O/bench-new.txt
  echo "tracenew done at $(( $(date +%s) - t0 )) s" ;;
trace)
  for v in new old; do B=$N; [ $v = old ] && B=$R/out/oldsrc/build-cuda
    NBMC_TRACE=1 $B/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --device-resident --repeat 3 > $O/trace-dev-$v.txt 2>&1
    echo "# $v"; grep -h "incidence\|clean-up: \|download\|upload\|post-processing\|RESULT" $O/trace-dev-$v.txt | tail -14 | cut -c1-200
  done
  echo "trace done at $(( $(date +%s) - t0 )) s" ;;
split)
  [ -n "${OLDPID:-}" ] && wait $OLDPID; OLDPID=""
  for round in 1 2; do for v in old new; do B=$N; [ $v = old ] && B=$R/out/oldsrc/build-cuda
    echo "# split-dr $v r$round $($B/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --device-resident --subdomains 2x2x2 --repeat 3 2>&1 | grep RESULT | grep -o 'total=[0-9.]*\| postprocess=[0-9.]*\|triangles=[0-9]*\|vertices=[0-9]*' | paste -sd' ')"
  done; done | tee $O/split.txt
  NBMC_TRACE=1 $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --device-resident --subdomains 2x2x2 --repeat 2 > $O/trace-split-new.txt 2>&1
  grep -h "upload\|post-processing" $O/trace-split-new.txt | tail -6 | cut -c1-160
  echo "split done at $(( $(date +%s) - t0 )) s" ;;
trace8)
  [ -n "${OLDPID:-}" ] && wait $OLDPID; OLDPID=""
  for v in new old; do B=$N; [ $v = old ] && B=$R/out/oldsrc/build-cuda
    NBMC_TRACE=1 $B/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --device-resident --repeat 8 > $O/trace8-dev-$v.txt 2>&1
    echo "# $v"; grep -h "upload\|compaction\|clean-up rounds" $O/trace8-dev-$v.txt | grep -v "upload: " | awk '{printf "%s ", $0; if (/upload/ && !/buffers/) print ""}' | grep -o "rounds:.*merge [0-9.]*\|compaction  *n=[0-9]* *[0-9.]* ms\|device buffers n=[0-9]* *[0-9.]* ms\|upload[^n]*n=[0-9]* *[0-9.]* ms\|on the device n=[0-9]* *[0-9.]* ms" | paste -sd' ' | sed 's/ rounds/\nrounds/g' | cut -c1-330
    grep RESULT $O/trace8-dev-$v.txt | grep -o "total=[0-9.]*\| postprocess=[0-9.]*" | paste -sd' '
  done
  echo "trace8 done at $(( $(date +%s) - t0 )) s" ;;
waitold)
  [ -n "${OLDPID:-}" ] && wait $OLDPID; OLDPID=""
  echo "old waited at $(( $(date +%s) - t0 )) s" ;;
bench)
  [ -n "${OLDPID:-}" ] && wait $OLDPID
  OB=$R/out/oldsrc/build-cuda
  {
  for round in 1 2 3; do
    for v in old new; do B=$N; [ $v = old ] && B=$OB
      for args in "--backend cuda --device-resident --repeat 5" "--backend cuda --repeat 5" "--backend cuda --device-resident --no-cleanup --repeat 5"; do
        echo "# ${args// /_} $v r$round"; $B/bench/nbmc_bench $BIG --spacing 0.00484 $args 2>&1 | grep RESULT
      done
    done
    args="--backend openmp --repeat 2"; echo "# ${args// /_} new r$round"; $N/bench/nbmc_bench $BIG --spacing 0.00484 $args 2>&1 | grep RESULT
  done
  } > $O/bench.txt 2>&1
  grep -A1 "^# " $O/bench.txt | grep -o "^# .*\|total=[0-9.]*\| postprocess=[0-9.]*" | paste -sd' ' | sed 's/# /\n/g'
  echo "bench done at $(( $(date +%s) - t0 )) s" ;;
esac; done
echo "total $(( $(date +%s) - t0 )) s"
