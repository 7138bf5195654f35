#!/usr/bin/env bash
# Session 30 device runs. new = working tree, old = out/dev/old.tar (git archive of the session's base).
set -uo pipefail
R=$PWD; O=${OUT:-/tmp/o}; L=/tmp/L; mkdir -p $O $L
export PATH=/usr/local/cuda/bin:$PATH
mkdir -p ~/.cache/nbmc/src && cp -rn out/dev/kk/* ~/.cache/nbmc/src/
D=$R/out/dev/data; BIG=$D/xyz/cbd1654k_t040_1654104.xyz; MID=$D/xyz/cbd292k_t040_292008.xyz
N=$R/build-cuda; OB=$R/out/oldsrc/build-cuda
t0=$(date +%s)
for step in "$@"; do case $step in
build)
  NBMC_GPU_CHECK_STEPS=build scripts/gpu_check.sh $D $L/gc > $L/build.txt 2>&1 || { tail -40 $L/build.txt $L/gc/build.log | grep -v "^ *$" | tail -40; exit 1; }
  echo "new built in $(( $(date +%s) - t0 )) s" ;;
oldbg)  # after build: Kokkos is in the cache
  mkdir -p out/oldsrc && tar -xf out/dev/old.tar -C out/oldsrc
  (cd out/oldsrc && NBMC_CUDA_CMAKE_ARGS="-DNBMC_BUILD_TESTS=OFF" NBMC_JOBS=6 scripts/setup.sh --cuda-only > $L/old-build.txt 2>&1; echo "old build rc $? at $(( $(date +%s) - t0 )) s") &
  OLDPID=$! ;;
waitold)
  [ -n "${OLDPID:-}" ] && wait $OLDPID; ls $OB/bench/nbmc_bench ;;
variants)  # after build: old (base) and C (new with the eigenvalue not inlined) in the background
  mkdir -p out/oldsrc out/vc && tar -xf out/dev/old.tar -C out/oldsrc
  git ls-files -z | xargs -0 -I{} cp --parents {} out/vc/ 2>/dev/null
  sed -i 's/^KOKKOS_INLINE_FUNCTION float largest_eigenvalue_sym3/static KOKKOS_FUNCTION __attribute__((noinline)) float largest_eigenvalue_sym3/' out/vc/backends/kokkos/field_ssp07.hpp
  grep -n "largest_eigenvalue_sym3(float" out/vc/backends/kokkos/field_ssp07.hpp
  (cd out/oldsrc && NBMC_CUDA_CMAKE_ARGS="-DNBMC_BUILD_TESTS=OFF" NBMC_JOBS=8 scripts/setup.sh --cuda-only > $L/old-build.txt 2>&1; echo "old build rc $? at $(( $(date +%s) - t0 )) s") &
  P1=$!
  (cd out/vc && NBMC_CUDA_CMAKE_ARGS="-DNBMC_BUILD_TESTS=OFF" NBMC_JOBS=8 scripts/setup.sh --cuda-only > $L/vc-build.txt 2>&1; echo "vc build rc $? at $(( $(date +%s) - t0 )) s"; tail -5 $L/vc-build.txt) &
  P2=$!
  wait $P1 $P2 ;;
ncu3)
  for v in old new vc; do B=$N; [ $v = old ] && B=$OB; [ $v = vc ] && B=$R/out/vc/build-cuda
    ncu --kernel-name-base demangled --launch-count 1 -k regex:gather_vertices --section SpeedOfLight --section Occupancy --section LaunchStats --section InstructionStats --section WarpStateStats \
      $B/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --no-cleanup > $O/ncu-$v.txt 2>&1
    grep -E "Duration|Registers Per|Achieved Occupancy|Executed Instructions  |Issue Slots Busy|Local Memory|Stack Size|Warp Cycles Per Issued" $O/ncu-$v.txt | sed "s/^/$v /" | tr -s ' '
    cuobjdump -res-usage $B/src/CMakeFiles/nbmc.dir/__/backends/kokkos/pipeline_cuda.cpp.o 2>&1 | grep -A1 "gather_vertices" | grep -v "^--" | paste - - | grep "FieldSSP07TILb0E" | grep -o "REG:[0-9]*\|STACK:[0-9]*\|LOCAL:[0-9]*" | paste -sd' ' | sed "s/^/$v res /"
  done
  echo "ncu done at $(( $(date +%s) - t0 )) s" ;;
bench3)
  {
  for round in 1 2 3; do
    for v in old new vc; do B=$N; [ $v = old ] && B=$OB; [ $v = vc ] && B=$R/out/vc/build-cuda
      for args in "--no-cleanup --repeat 5" "--no-cleanup --device-resident --repeat 5"; do
        echo "# $v r$round $args"; $B/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda $args 2>&1 | grep RESULT
      done
    done
  done
  } > $O/bench3.txt 2>&1
  grep -A1 "^# " $O/bench3.txt | grep -o "^# .*\|total=[0-9.]*\| t4=[0-9.]*" | paste -sd' ' | sed 's/# /\n/g'
  echo "bench3 done at $(( $(date +%s) - t0 )) s" ;;
topo)  # the host's CPU topology and the thread scaling of the OpenMP backend
  { lscpu; echo; lscpu -e; echo; nproc; cat /sys/devices/system/cpu/smt/active 2>/dev/null; } > $O/lscpu.txt 2>&1
  grep -E "Model name|Thread\(s\) per core|Core\(s\) per socket|Socket\(s\)|NUMA node\(s\)|L3|Hypervisor|Flags" $O/lscpu.txt | cut -c1-160
  lscpu -e | head -20
  {
  for round in 1 2; do
    for t in 1 2 4 8 16; do
      echo "# t$t r$round"; $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend openmp --threads $t --no-cleanup --repeat 2 2>&1 | grep RESULT
    done
    for t in 8 16; do
      echo "# t$t cores-spread r$round"; OMP_PLACES=cores OMP_PROC_BIND=spread $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend openmp --threads $t --no-cleanup --repeat 2 2>&1 | grep RESULT
    done
  done
  } > $O/scaling.txt 2>&1
  grep -A1 "^# " $O/scaling.txt | grep -o "^# .*\|total=[0-9.]*\| t[1-5]=[0-9.]*" | paste -sd' ' | sed 's/# /\n/g'
  echo "topo done at $(( $(date +%s) - t0 )) s" ;;
check)
  { echo "== equivalence (new)"; NBMC_CHECK_BAND=1 $N/tests/gpu/nbmc_cuda_equivalence $D 2>&1 | tail -80; } > $O/equivalence.txt
  tail -1 $O/equivalence.txt; grep FAIL $O/equivalence.txt | head
  NBMC_GPU_CHECK_STEPS="pointers subdomains" scripts/gpu_check.sh $D $L/gc2 > $O/pointers-subdomains.txt 2>&1; echo "pointers+subdomains rc $?"
  grep -i "fail\|DIFFERENT" $O/pointers-subdomains.txt | head
  echo "check done at $(( $(date +%s) - t0 )) s" ;;
bench)
  [ -n "${OLDPID:-}" ] && wait $OLDPID
  {
  for round in 1 2 3; do
    for v in old new; do
      B=$N; [ $v = old ] && B=$OB
      for args in "--no-cleanup --repeat 5" "--no-cleanup --device-resident --repeat 5" "--repeat 3" "--no-cleanup --tile 2 --repeat 2"; do
        echo "# $v r$round $args"; $B/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda $args 2>&1 | grep RESULT
      done
    done
  done
  } > $O/bench.txt 2>&1
  grep -A1 "^# " $O/bench.txt | grep -o "^# .*\|total=[0-9.]*\| t4=[0-9.]*" | paste -sd' ' | sed 's/# /\n/g'
  echo "bench done at $(( $(date +%s) - t0 )) s" ;;
cpu)
  [ -n "${OLDPID:-}" ] && wait $OLDPID
  {
  for round in 1 2; do
    for v in old new; do
      B=$N; [ $v = old ] && B=$OB
      for args in "--influence-radius 4" "--influence-radius 2"; do
        echo "# cpu16 $v r$round $args"; $B/bench/nbmc_bench $BIG --spacing 0.00484 --backend openmp --threads 16 --no-cleanup --repeat 2 $args 2>&1 | grep RESULT
      done
    done
  done
  } > $O/cpu.txt 2>&1
  grep -A1 "^# " $O/cpu.txt | grep -o "^# .*\|total=[0-9.]*\| t4=[0-9.]*" | paste -sd' ' | sed 's/# /\n/g'
  echo "cpu done at $(( $(date +%s) - t0 )) s" ;;
esac; done
echo "total $(( $(date +%s) - t0 )) s"
