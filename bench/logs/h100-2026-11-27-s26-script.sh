#!/usr/bin/env bash
# Session 26 device runs. new = working tree, old = out/dev/old.tar (1ff28b0).
# usage: s26.sh STEPS...   (build check bench ncu)
set -uo pipefail
R=$PWD; O=${OUT:-/tmp/o}; L=/tmp/L; mkdir -p $O $L
export PATH=/usr/local/cuda/bin:$PATH
mkdir -p ~/.cache/nbmc/src && cp -rn out/dev/kk/* ~/.cache/nbmc/src/
D=$R/out/dev/data; BIG=$D/xyz/cbd1654k_t040_1654104.xyz; MID=$D/xyz/cbd292k_t040_292008.xyz
N=$R/build-cuda; OB=/tmp/old/build-cuda
t0=$(date +%s)
for step in "$@"; do case $step in
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
    for v in old new; do
      B=$N; [ $v = old ] && B=$OB
      for args in "--no-cleanup" "--no-cleanup --repeat 5" "--no-cleanup --device-resident --repeat 5" "--repeat 3" "--no-cleanup --tile 2 --repeat 3" "--cell-size 1 --no-cleanup --repeat 5" "--no-cleanup --method zb05 --repeat 5"; do
        echo "# $v r$round $args"; $B/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda $args 2>&1 | grep RESULT
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
cputrace)
  # The host's block-key compaction and sort ("band: sorted block keys"), 16 threads.
  {
  for round in 1 2 3; do for v in old new; do B=$N; [ $v = old ] && B=$OB
    echo "# $v r$round"
    NBMC_TRACE=1 $B/install/bin/nbmc reconstruct $BIG --spacing 0.00484 --cell-size 0.5 --backend openmp --threads 16 --no-cleanup -o $L/c.ply -q 2>&1 | grep -i "band: insert\|sorted block\|stage done"
  done; done
  for round in 1 2; do for v in old new; do B=$N; [ $v = old ] && B=$OB
    echo "# $v r$round bench 16 threads"; $B/bench/nbmc_bench $BIG --spacing 0.00484 --backend openmp --threads 16 --no-cleanup --repeat 3 2>&1 | grep RESULT
  done; done
  } > $O/cputrace.txt 2>&1
  grep "sorted block\|^#\|RESULT" $O/cputrace.txt | sed 's/RESULT.*total=/total=/' | cut -c1-150
  echo "cputrace done at $(( $(date +%s) - t0 )) s" ;;
first)
  # Where a process's first reconstruction's extra time goes: lazy module loading?
  {
  for round in 1 2 3; do
    echo "# lazy r$round"; $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --no-cleanup 2>&1 | grep RESULT
    echo "# eager r$round"; CUDA_MODULE_LOADING=EAGER $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --no-cleanup 2>&1 | grep RESULT
    echo "# eager wall r$round"; TIMEFORMAT="wall %R s"; { time CUDA_MODULE_LOADING=EAGER $N/install/bin/nbmc reconstruct $BIG --spacing 0.00484 --cell-size 0.5 --backend cuda --no-cleanup -o $L/e.ply -q; } 2>&1 | tail -1
    echo "# lazy wall r$round"; { time $N/install/bin/nbmc reconstruct $BIG --spacing 0.00484 --cell-size 0.5 --backend cuda --no-cleanup -o $L/e.ply -q; } 2>&1 | tail -1
  done
  } > $O/first.txt 2>&1
  grep -A1 "^# " $O/first.txt | grep -o "^# .*\|total=[0-9.]*\| t[0-6]=[0-9.]*\|wall.*" | paste -sd' ' | sed 's/# /\n/g'
  echo "first done at $(( $(date +%s) - t0 )) s" ;;
dltrace)
  # The mesh download: waiting for the GPU's copies vs the host's copies.
  {
  for args in "--no-cleanup --repeat 3" "--no-cleanup --tile 2 --repeat 2"; do for round in 1 2; do
    echo "# new $args r$round"; NBMC_TRACE=1 $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda $args 2>&1 | grep "download:\|RESULT" | sed 's/RESULT.*total=/total=/'
  done; done
  } > $O/dltrace.txt 2>&1
  cat $O/dltrace.txt | cut -c1-160
  echo "dltrace done at $(( $(date +%s) - t0 )) s" ;;
cache)
  # The host block cache: same binary, NBMC_HOST_CACHE=0 (off) vs default, alternated.
  {
  for round in 1 2 3; do for v in off on; do
    E=""; [ $v = off ] && E="NBMC_HOST_CACHE=0"
    for args in "--no-cleanup --repeat 5" "--repeat 3" "--no-cleanup --tile 2 --repeat 3"; do
      echo "# $v r$round $args"; env $E NBMC_TRACE=1 $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda $args 2>&1 | grep "download:\|RESULT" | tail -2 | sed 's/RESULT.*total=/total=/'
    done
    echo "# $v r$round cpu16"; env $E $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend openmp --threads 16 --repeat 3 2>&1 | grep RESULT | sed 's/RESULT.*total=/total=/'
  done; done
  } > $O/cache.txt 2>&1
  grep -v "download:" $O/cache.txt | cut -c1-200
  echo "cache done at $(( $(date +%s) - t0 )) s" ;;
esac; done
echo "total $(( $(date +%s) - t0 )) s"
