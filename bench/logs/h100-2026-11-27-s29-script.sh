#!/usr/bin/env bash
# Session 29 device runs. new = working tree.
set -uo pipefail
R=$PWD; O=${OUT:-/tmp/o}; L=/tmp/L; mkdir -p $O $L
export PATH=/usr/local/cuda/bin:$PATH
mkdir -p ~/.cache/nbmc/src && cp -rn out/dev/kk/* ~/.cache/nbmc/src/
D=$R/out/dev/data; BIG=$D/xyz/cbd1654k_t040_1654104.xyz; MID=$D/xyz/cbd292k_t040_292008.xyz
N=$R/build-cuda; OB=$R/out/oldsrc/build-cuda
t0=$(date +%s)
for step in "$@"; do case $step in
fastbuild)
  NBMC_CUDA_CMAKE_ARGS="-DNBMC_BUILD_TESTS=OFF" NBMC_JOBS=14 scripts/setup.sh --cuda-only > $L/build.txt 2>&1 || { tail -30 $L/build.txt; exit 1; }
  echo "new built in $(( $(date +%s) - t0 )) s" ;;
build)
  NBMC_GPU_CHECK_STEPS=build scripts/gpu_check.sh $D $L/gc > $L/build.txt 2>&1 || { tail -40 $L/build.txt $L/gc/build.log | grep -v "^ *$" | tail -40; exit 1; }
  echo "new built in $(( $(date +%s) - t0 )) s" ;;
build2)
  mkdir -p out/oldsrc && tar -xf out/dev/old.tar -C out/oldsrc
  (cd out/oldsrc && NBMC_CUDA_CMAKE_ARGS="-DNBMC_BUILD_TESTS=OFF" NBMC_JOBS=5 scripts/setup.sh --cuda-only > $L/old-build.txt 2>&1; echo "old build rc $?") &
  OLDPID=$!
  NBMC_GPU_CHECK_STEPS=build scripts/gpu_check.sh $D $L/gc > $L/build.txt 2>&1 || { tail -40 $L/build.txt $L/gc/build.log | grep -v "^ *$" | tail -40; exit 1; }
  echo "new built in $(( $(date +%s) - t0 )) s"
  wait $OLDPID; echo "old built at $(( $(date +%s) - t0 )) s" ;;
check)
  { echo "== equivalence (new)"; NBMC_CHECK_BAND=1 $N/tests/gpu/nbmc_cuda_equivalence $D 2>&1 | tail -60; } > $O/equivalence.txt
  tail -1 $O/equivalence.txt; grep FAIL $O/equivalence.txt | head
  NBMC_GPU_CHECK_STEPS="pointers subdomains" scripts/gpu_check.sh $D $L/gc2 > $O/pointers-subdomains.txt 2>&1; echo "pointers+subdomains rc $?"
  echo "check done at $(( $(date +%s) - t0 )) s" ;;
bench2)
  [ -n "${OLDPID:-}" ] && wait $OLDPID
  {
  for round in 1 2; do
    for v in old new; do
      B=$N; [ $v = old ] && B=$OB
      for args in "--no-cleanup --repeat 5" "--no-cleanup --device-resident --repeat 5" "--repeat 3" "--no-cleanup --tile 2 --repeat 2" "--no-cleanup --method zb05 --repeat 3" "--no-cleanup --method sph --repeat 3" "--no-cleanup --method yt10 --repeat 3"; do
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
      for args in "" "--method yt10"; do
        echo "# cpu $v r$round $args"; $B/bench/nbmc_bench $BIG --spacing 0.00484 --backend openmp --no-cleanup $args 2>&1 | grep RESULT
      done
    done
  done
  } > $O/cpu.txt 2>&1
  grep -A1 "^# " $O/cpu.txt | grep -o "^# .*\|total=[0-9.]*\| t4=[0-9.]*" | paste -sd' ' | sed 's/# /\n/g'
  echo "cpu done at $(( $(date +%s) - t0 )) s" ;;
res)
  cuobjdump -res-usage $N/src/CMakeFiles/nbmc.dir/__/backends/kokkos/pipeline_cuda.cpp.o 2>&1 | grep -A1 "gather_vertices" | grep -v "^--" | paste - - > $L/res.txt
  while read -r l; do echo "$(echo "$l" | grep -o 'LaunchBoundsILj[0-9]*ELj[0-9]*E' | head -1) $(echo "$l" | grep -o 'FieldSSP07TILb[01]E\|FieldZB05[A-Za-z0-9]*\|FieldSPH[A-Za-z0-9]*\|FieldYT10[A-Za-z0-9]*' | head -1) $(echo "$l" | grep -o 'ILi[0-9]ELi[0-9]ELi[0-9]ELi[0-9]E\|REG:[0-9]*\|STACK:[0-9]*\|LOCAL:[0-9]*' | paste -sd' ')"; done < $L/res.txt | tee $O/res.txt ;;
exp)
  {
  for v in ${EXPS:-base lb5 lb6 lb8 u1 u2 u8 lb6u2}; do E="NBMC_EXP=$v"; [ $v = base ] && E="NBMC_EXP="
    env $E $N/install/bin/nbmc reconstruct $BIG --spacing 0.00484 --cell-size 0.5 --backend cuda --no-cleanup -o $L/e.ply -q
    echo "mesh $v $(md5sum < $L/e.ply | cut -c1-12)"
  done
  for round in 1 2 3; do
    for v in ${EXPS:-base lb5 lb6 lb8 u1 u2 u8 lb6u2}; do E="NBMC_EXP=$v"; [ $v = base ] && E="NBMC_EXP="
      echo "# $v r$round"; env $E $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --no-cleanup --repeat 5 2>&1 | grep RESULT
    done
  done
  } > $O/exp.txt 2>&1
  grep "^mesh" $O/exp.txt
  grep -A1 "^# " $O/exp.txt | grep -o "^# .*\|total=[0-9.]*\| t4=[0-9.]*" | paste -sd' ' | sed 's/# /\n/g'
  echo "exp done at $(( $(date +%s) - t0 )) s" ;;
ncu)
  for v in ${NCU_EXPS:-base lb6}; do E="NBMC_EXP=$v"; [ $v = base ] && E="NBMC_EXP="
    env $E ncu --kernel-name-base demangled --launch-count 1 -k regex:gather_vertices --section SpeedOfLight --section Occupancy --section WarpStateStats --section LaunchStats \
      $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --no-cleanup > $O/ncu-$v.txt 2>&1
    grep -E "Duration|Registers Per|Achieved Occupancy|Theoretical Occupancy|Issue Slots|Executed Ipc A|Block Size|Local Memory" $O/ncu-$v.txt | sed "s/^/$v /" | tr -s ' '
  done
  echo "ncu done at $(( $(date +%s) - t0 )) s" ;;
esac; done
echo "total $(( $(date +%s) - t0 )) s"
