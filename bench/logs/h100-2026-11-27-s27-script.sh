#!/usr/bin/env bash
# Session 27 device runs. new = working tree, old = out/dev/old.tar (c4b0240).
# usage: s27.sh STEPS...   (prof build check bench ncu)
set -uo pipefail
R=$PWD; O=${OUT:-/tmp/o}; L=/tmp/L; mkdir -p $O $L
export PATH=/usr/local/cuda/bin:$PATH
mkdir -p ~/.cache/nbmc/src && cp -rn out/dev/kk/* ~/.cache/nbmc/src/
D=$R/out/dev/data; BIG=$D/xyz/cbd1654k_t040_1654104.xyz; MID=$D/xyz/cbd292k_t040_292008.xyz
N=$R/build-cuda; OB=/tmp/old/build-cuda
t0=$(date +%s)
sass_of() {  # $1 library, $2 kernel substring: the SASS of the first matching ParallelFor function
  cuobjdump -sass "$1" | awk -v pat="$2" '/Function : /{p = (index($0, pat) > 0 && index($0, "ParallelFor") > 0 && !done)} p{print} /EXIT/&&p{} /\.\.\.\.\.\.\.\.\.\./{if(p){done=1;p=0}}'
}
for step in "$@"; do case $step in
ptrs)
  NBMC_GPU_CHECK_STEPS="pointers subdomains" scripts/gpu_check.sh $D $L/gc2 > $O/pointers-subdomains.txt 2>&1; echo "pointers+subdomains rc $?"
  grep -iE "pass|fail|identical|different|same|error" $O/pointers-subdomains.txt | cut -c1-160 | tail -30 ;;
fastbuild)
  mkdir -p /tmp/old && tar -xf out/dev/old.tar -C /tmp/old
  (cd /tmp/old && NBMC_CUDA_CMAKE_ARGS="-DNBMC_BUILD_TESTS=OFF" NBMC_JOBS=8 scripts/setup.sh --cuda-only > $L/old-build.txt 2>&1; echo "old build rc $?") &
  OLDPID=$!
  NBMC_CUDA_CMAKE_ARGS="-DNBMC_BUILD_TESTS=OFF" NBMC_JOBS=10 scripts/setup.sh --cuda-only > $L/build.txt 2>&1 || { tail -30 $L/build.txt; exit 1; }
  echo "new built in $(( $(date +%s) - t0 )) s" ;;
build)
  NBMC_GPU_CHECK_STEPS=build scripts/gpu_check.sh $D $L/gc > $L/build.txt 2>&1 || { tail -40 $L/build.txt $L/gc/build.log | grep -v "^ *$" | tail -40; exit 1; }
  echo "new built in $(( $(date +%s) - t0 )) s"
  if [ ! -x $OB/bench/nbmc_bench ]; then
    mkdir -p /tmp/old && tar -xf out/dev/old.tar -C /tmp/old
    (cd /tmp/old && NBMC_CUDA_CMAKE_ARGS="-DNBMC_BUILD_TESTS=OFF" NBMC_JOBS=8 scripts/setup.sh --cuda-only > $L/old-build.txt 2>&1; echo "old build rc $?") &
    OLDPID=$!
  fi ;;
check)
  { echo "== equivalence (new)"; NBMC_CHECK_BAND=1 $N/tests/gpu/nbmc_cuda_equivalence $D 2>&1 | tail -60; } > $O/equivalence.txt
  tail -1 $O/equivalence.txt; grep FAIL $O/equivalence.txt | head
  [ -n "${OLDPID:-}" ] && wait $OLDPID
  {
  for spec in "$MID 0.0086" "$BIG 0.00484"; do set -- $spec
    for m in ssp07 zb05 sph yt10; do for c in 1 0.5; do
      $N/install/bin/nbmc reconstruct $1 --spacing $2 --cell-size $c --method $m --backend cuda -o $L/n.ply -q
      $OB/install/bin/nbmc reconstruct $1 --spacing $2 --cell-size $c --method $m --backend cuda -o $L/o.ply -q
      echo "$(basename $1) $m c$c: new/old $(cmp -s $L/n.ply $L/o.ply && echo same || echo DIFFERENT) $(md5sum < $L/n.ply | cut -c1-8)"
    done; done
  done
  } 2>&1 | tee $O/meshes.txt | grep -c same
  NBMC_GPU_CHECK_STEPS="pointers subdomains" scripts/gpu_check.sh $D $L/gc2 > $O/pointers-subdomains.txt 2>&1; echo "pointers+subdomains rc $?"
  echo "check done at $(( $(date +%s) - t0 )) s" ;;
bench)
  [ -n "${OLDPID:-}" ] && wait $OLDPID
  {
  for round in 1 2; do
    for v in ${VARIANTS:-old new sub0 p40}; do
      B=$N; [ $v = old ] && B=$OB; E=""; [ $v = sub0 ] && E="NBMC_SUB_CELLS=0"; [ $v = p40 ] && E="NBMC_GPU_POS4=0"
      ARGS=("--no-cleanup --repeat 5" "--no-cleanup --device-resident --repeat 5" "--repeat 3" "--no-cleanup --tile 2 --repeat 3" "--cell-size 1 --no-cleanup --repeat 5" "--no-cleanup --method zb05 --repeat 5" "--no-cleanup --method sph --repeat 3" "--no-cleanup --method yt10 --repeat 3")
      case $v in sub0|p40) ARGS=("--no-cleanup --repeat 5" "--no-cleanup --device-resident --repeat 5" "--no-cleanup --tile 2 --repeat 3");; esac
      for args in "${ARGS[@]}"; do
        echo "# $v r$round $args"; env $E $B/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda $args 2>&1 | grep RESULT
      done
    done
  done
  } > $O/bench.txt 2>&1
  grep -A1 "^# " $O/bench.txt | grep -o "^# .*\|total=[0-9.]*\| t[0-6]=[0-9.]*" | paste -sd' ' | sed 's/# /\n/g'
  echo "bench done at $(( $(date +%s) - t0 )) s" ;;
ncu)
  for v in old new; do B=$N; [ $v = old ] && B=$OB
    timeout 250 ncu --metrics gpu__time_duration.sum --csv --kernel-name-base demangled $B/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --no-cleanup --device-resident > $L/ncu-$v.csv 2>/dev/null
    cp $L/ncu-$v.csv $O/
  done
  python3 - $L/ncu-old.csv $L/ncu-new.csv <<'PY' | tee $O/ncu.txt
import csv, sys
def load(f):
    rows = [r for r in csv.reader(open(f)) if len(r) > 10]
    h = rows[0]; ki = h.index("Kernel Name"); vi = h.index("Metric Value")
    return [(r[ki], float(r[vi].replace(",", ""))) for r in rows[1:]]
a, b = load(sys.argv[1]), load(sys.argv[2])
print(f"old {len(a)} kernels {sum(v for _,v in a)/1e6:.3f} ms; new {len(b)} kernels {sum(v for _,v in b)/1e6:.3f} ms")
for tag, ks in (("old", a), ("new", b)):
    print("==", tag)
    for i, (k, v) in enumerate(ks):
        print(f"{i:3d} {v/1000:9.1f} us  {k[:140]}")
PY
  echo "ncu done at $(( $(date +%s) - t0 )) s" ;;
prof)
  timeout 300 ncu --kernel-name-base demangled --launch-count 1 -k regex:gather_vertices --section SourceCounters --section WarpStateStats --section InstructionStats --section LaunchStats --section Occupancy --section SpeedOfLight --import-source yes -o $L/g $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --no-cleanup > $L/ncu-run.txt 2>&1; echo "ncu rc $?"; tail -5 $L/ncu-run.txt
  ncu -i $L/g.ncu-rep --page details > $O/gather-details.txt 2>&1
  ncu -i $L/g.ncu-rep --page source --csv --print-source sass > $O/gather-source-sass.csv 2>&1 || ncu -i $L/g.ncu-rep --page source --csv > $O/gather-source.csv 2>&1
  ncu -i $L/g.ncu-rep --page source --csv --print-source cuda > $O/gather-source-cuda.csv 2>&1
  ls -la $O; head -5 $O/gather-source-sass.csv | cut -c1-300
  echo "prof done at $(( $(date +%s) - t0 )) s" ;;
esac; done
echo "total $(( $(date +%s) - t0 )) s"
