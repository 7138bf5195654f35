#!/usr/bin/env bash
# Session 28 device runs. new = working tree, old = out/dev/old.tar (c4b0240).
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
fastbuild)
  if [ -n "${WITH_OLD:-}" ] && [ ! -x $OB/bench/nbmc_bench ]; then
    mkdir -p /tmp/old && tar -xf out/dev/old.tar -C /tmp/old
    (cd /tmp/old && NBMC_CUDA_CMAKE_ARGS="-DNBMC_BUILD_TESTS=OFF" NBMC_JOBS=6 scripts/setup.sh --cuda-only > $L/old-build.txt 2>&1; echo "old build rc $?") &
    OLDPID=$!
  fi
  NBMC_CUDA_CMAKE_ARGS="-DNBMC_BUILD_TESTS=OFF" NBMC_JOBS=14 scripts/setup.sh --cuda-only > $L/build.txt 2>&1 || { tail -30 $L/build.txt; exit 1; }
  echo "new built in $(( $(date +%s) - t0 )) s" ;;
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
first)
  [ -n "${OLDPID:-}" ] && wait $OLDPID
  { cat /sys/kernel/mm/transparent_hugepage/enabled /sys/kernel/mm/transparent_hugepage/defrag; nproc; free -g | head -2; } > $O/first-machine.txt
  {
  for round in 1 2 3; do
    for v in ${FIRST_VARIANTS:-old new thp0}; do
      B=$N; [ $v = old ] && B=$OB; E=""; [ $v = thp0 ] && E="NBMC_HOST_THP=0"; [ $v = eager ] && E="CUDA_MODULE_LOADING=EAGER"
      for args in "--no-cleanup" ""; do
        echo "# $v r$round [$args]"
        s=$(date +%s%N); env $E $B/install/bin/nbmc reconstruct $BIG --spacing 0.00484 --cell-size 0.5 --backend cuda $args -o $L/f.ply 2>&1 | sed -n '/^stage/,/library total/p' | tr -s ' ' | paste -sd' '
        echo "wall $(( ($(date +%s%N) - s) / 1000000 )) ms"
      done
    done
  done
  } > $O/first-cli.txt 2>&1
  grep -E "^#|wall" $O/first-cli.txt | paste - - | head -30
  { for v in new thp0; do E=""; [ $v = thp0 ] && E="NBMC_HOST_THP=0"; for r in 1 2; do echo "# trace $v r$r"; env $E NBMC_TRACE=1 $N/install/bin/nbmc reconstruct $BIG --spacing 0.00484 --cell-size 0.5 --backend cuda --no-cleanup -o $L/f.ply 2>&1; done; done; } > $O/first-trace.txt 2>&1
  { for v in old new thp0; do B=$N; [ $v = old ] && B=$OB; E=""; [ $v = thp0 ] && E="NBMC_HOST_THP=0"; for r in 1 2 3; do echo "# bench single $v r$r"; env $E $B/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --no-cleanup 2>&1 | grep RESULT; done; done; } > $O/first-bench.txt 2>&1
  grep -A1 "^# " $O/first-bench.txt | grep -o "^# .*\|total=[0-9.]*\| t[0-6]=[0-9.]*\|set_particles=[0-9.]*" | paste -sd' ' | sed 's/# /\n/g'
  echo "first done at $(( $(date +%s) - t0 )) s" ;;
bench)
  [ -n "${OLDPID:-}" ] && wait $OLDPID
  {
  for round in 1 2; do
    for v in ${VARIANTS:-old new}; do
      B=$N; [ $v = old ] && B=$OB
      for args in "--no-cleanup --repeat 5" "--no-cleanup --device-resident --repeat 5" "--repeat 3"; do
        echo "# $v r$round $args"; $B/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda $args 2>&1 | grep RESULT
      done
    done
  done
  } > $O/bench.txt 2>&1
  grep -A1 "^# " $O/bench.txt | grep -o "^# .*\|total=[0-9.]*\| t[0-6]=[0-9.]*" | paste -sd' ' | sed 's/# /\n/g'
  echo "bench done at $(( $(date +%s) - t0 )) s" ;;
probe)
  nvcc -O2 -arch=sm_90 out/dev/init_probe.cu -o $L/init_probe
  { for r in 1 2 3; do echo "# probe r$r"; s=$(date +%s%N); $L/init_probe; echo "process wall $(( ($(date +%s%N) - s) / 1000000 )) ms"; done
    for r in 1 2 3; do s=$(date +%s%N); $N/install/bin/nbmc --version > /dev/null; echo "nbmc --version wall $(( ($(date +%s%N) - s) / 1000000 )) ms"; done
    for r in 1 2 3; do echo "# trace r$r"; s=$(date +%s%N); NBMC_TRACE=1 $N/install/bin/nbmc reconstruct $BIG --spacing 0.00484 --cell-size 0.5 --backend cuda --no-cleanup -o $L/f.ply 2>&1 | grep -E "trace|setup|read |total|write"; echo "process wall $(( ($(date +%s%N) - s) / 1000000 )) ms"; done
    for r in 1 2; do echo "# eager trace r$r"; CUDA_MODULE_LOADING=EAGER NBMC_TRACE=1 $N/install/bin/nbmc reconstruct $BIG --spacing 0.00484 --cell-size 0.5 --backend cuda --no-cleanup -o $L/f.ply 2>&1 | grep -E "upload|stage done|setup"; done
  } > $O/probe.txt 2>&1
  cat $O/probe.txt | cut -c1-100 | head -150 ;;
seq)
  [ -n "${OLDPID:-}" ] && wait $OLDPID
  S=$L/seq; mkdir -p $S/in; for i in 1 2 3 4 5 6 7 8; do ln -sf $BIG $S/in/f_$i.xyz; done
  {
  for round in 1 2; do
    for v in old new thp0; do
      B=$N; [ $v = old ] && B=$OB; E=""; [ $v = thp0 ] && E="NBMC_HOST_THP=0"
      for args in "" "--no-cleanup" "--contexts 1" "--sequential-io"; do
        rm -rf $S/out; mkdir -p $S/out
        s=$(date +%s%N); env $E $B/install/bin/nbmc reconstruct "$S/in/f_{}.xyz" --spacing 0.00484 --cell-size 0.5 --backend cuda $args -o "$S/out/s_{}.ply" -q --json $S/seq.json
        w=$(( ($(date +%s%N) - s) / 1000000 ))
        python3 - "$v r$round [$args]" $w $S/seq.json <<'PY'
import json, sys
d = json.load(open(sys.argv[3])); fr = d["frames"]
def col(k): return " ".join("%.0f" % (1000 * f.get(k, 0)) for f in fr)
print("%-34s wall %s ms total %.3f s | frame %s | read %s | rec %s | write %s" % (sys.argv[1], sys.argv[2], d["total_seconds"], col("seconds"), col("read_seconds"), col("reconstruct_seconds"), col("write_seconds")))
PY
      done
    done
  done
  } > $O/seq.txt 2>&1
  cat $O/seq.txt
  md5sum $S/out/*.ply | awk '{print $1}' | sort | uniq -c
  echo "seq done at $(( $(date +%s) - t0 )) s" ;;
seq2)
  S=$L/seq; mkdir -p $S/in; for i in 1 2 3 4 5 6 7 8; do ln -sf $BIG $S/in/f_$i.xyz; done
  {
  for round in 1 2; do
    for spec in "|" "|--threads 14" "|--threads 12" "|--threads 8" "|--contexts 1" "|--contexts 1 --threads 14" "OMP_WAIT_POLICY=passive|" "OMP_WAIT_POLICY=passive|--threads 14" "|--sequential-io" "|--sequential-io --threads 14" "|--no-cleanup" "|--no-cleanup --threads 14"; do
      E=${spec%%|*}; args=${spec#*|}
      rm -rf $S/out; mkdir -p $S/out
      s=$(date +%s%N); env $E $N/install/bin/nbmc reconstruct "$S/in/f_{}.xyz" --spacing 0.00484 --cell-size 0.5 --backend cuda $args -o "$S/out/s_{}.ply" -q --json $S/seq.json
      w=$(( ($(date +%s%N) - s) / 1000000 ))
      python3 - "r$round $E [$args]" $w $S/seq.json <<'PY'
import json, sys
d = json.load(open(sys.argv[3])); fr = d["frames"]
def col(k): return " ".join("%.0f" % (1000 * f.get(k, 0)) for f in fr)
print("%-48s wall %s ms total %.3f s | frame %s | read %s | rec %s | write %s" % (sys.argv[1], sys.argv[2], d["total_seconds"], col("seconds"), col("read_seconds"), col("reconstruct_seconds"), col("write_seconds")))
PY
    done
  done
  } > $O/seq2.txt 2>&1
  cut -c1-95 $O/seq2.txt
  md5sum $S/out/*.ply | awk '{print $1}' | sort | uniq -c
  echo "seq2 done at $(( $(date +%s) - t0 )) s" ;;
policy)
  S=$L/seq; mkdir -p $S/in $S/in2; for i in 1 2 3 4 5 6 7 8; do ln -sf $BIG $S/in/f_$i.xyz; ln -sf $MID $S/in2/f_$i.xyz; done
  seqrun() {  # label env input spacing args
    rm -rf $S/out; mkdir -p $S/out
    s=$(date +%s%N); env $2 $N/install/bin/nbmc reconstruct "$3/f_{}.xyz" --spacing $4 --cell-size 0.5 $5 -o "$S/out/s_{}.ply" -q --json $S/seq.json
    w=$(( ($(date +%s%N) - s) / 1000000 ))
    python3 - "$1 $2 [$5]" $w $S/seq.json <<'PY'
import json, sys
d = json.load(open(sys.argv[3])); fr = d["frames"]
def col(k): return " ".join("%.0f" % (1000 * f.get(k, 0)) for f in fr)
print("%-60s wall %s ms total %.3f s | rec %s | read %s | write %s" % (sys.argv[1], sys.argv[2], d["total_seconds"], col("reconstruct_seconds"), col("read_seconds"), col("write_seconds")))
PY
  }
  {
  for round in 1 2; do
    for E in "X=1" "OMP_WAIT_POLICY=passive" "GOMP_SPINCOUNT=10000"; do
      seqrun "gpu-seq r$round" "$E" $S/in 0.00484 "--backend cuda"
      seqrun "gpu-seq r$round" "$E" $S/in 0.00484 "--backend cuda --contexts 1"
      seqrun "gpu-seq r$round" "$E" $S/in 0.00484 "--backend cuda --sequential-io"
      seqrun "cpu-seq r$round" "$E" $S/in2 0.0086 "--backend openmp"
      seqrun "cpu-seq r$round" "$E" $S/in2 0.0086 "--backend openmp --sequential-io"
      echo "# bench $E r$round"
      for args in "--backend cuda --no-cleanup --repeat 5" "--backend cuda --repeat 3" "--backend openmp --threads 16 --repeat 3"; do
        env $E $N/bench/nbmc_bench $BIG --spacing 0.00484 $args 2>&1 | grep RESULT | grep -o "total=[0-9.]*\| t4=[0-9.]*\|postprocess=[0-9.]*" | paste -sd' ' | sed "s/^/  $args: /"
      done
      for r in 1 2; do s=$(date +%s%N); env $E $N/install/bin/nbmc reconstruct $BIG --spacing 0.00484 --cell-size 0.5 --backend cuda -o $L/f.ply -q; echo "  single gpu cli wall $(( ($(date +%s%N) - s) / 1000000 )) ms"; done
    done
  done
  } > $O/policy.txt 2>&1
  cut -c1-150 $O/policy.txt
  echo "policy done at $(( $(date +%s) - t0 )) s" ;;
seq3)
  [ -n "${OLDPID:-}" ] && wait $OLDPID
  S=$L/seq; mkdir -p $S/in $S/in2; for i in 1 2 3 4 5 6 7 8; do ln -sf $BIG $S/in/f_$i.xyz; ln -sf $MID $S/in2/f_$i.xyz; done
  seqrun() {  # label binary env input spacing args
    rm -rf $S/out; mkdir -p $S/out
    s=$(date +%s%N); env $3 $2/install/bin/nbmc reconstruct "$4/f_{}.xyz" --spacing $5 --cell-size 0.5 $6 -o "$S/out/s_{}.ply" -q --json $S/seq.json
    w=$(( ($(date +%s%N) - s) / 1000000 ))
    python3 - "$1 $3 [$6]" $w $S/seq.json <<'PY'
import json, sys
d = json.load(open(sys.argv[3])); fr = d["frames"]
def col(k): return " ".join("%.0f" % (1000 * f.get(k, 0)) for f in fr)
print("%-64s wall %s ms total %.3f s | rec %s | read %s | write %s" % (sys.argv[1], sys.argv[2], d["total_seconds"], col("reconstruct_seconds"), col("read_seconds"), col("write_seconds")))
PY
    md5sum $S/out/*.ply | awk '{print $1}' | sort | uniq -c | tr '\n' ' '; echo
  }
  {
  for round in 1 2 3; do
    seqrun "gpu old r$round" $OB "X=1" $S/in 0.00484 "--backend cuda"
    seqrun "gpu new r$round" $N "X=1" $S/in 0.00484 "--backend cuda"
    seqrun "gpu new r$round" $N "X=1" $S/in 0.00484 "--backend cuda --contexts 1"
    seqrun "gpu new r$round" $N "NBMC_POSTPROCESS_ON_CALLER=1" $S/in 0.00484 "--backend cuda"
    seqrun "gpu new r$round" $N "NBMC_POSTPROCESS_ON_CALLER=1" $S/in 0.00484 "--backend cuda --contexts 1"
    seqrun "gpu new r$round" $N "OMP_WAIT_POLICY=active" $S/in 0.00484 "--backend cuda"
    seqrun "gpu new r$round" $N "X=1" $S/in 0.00484 "--backend cuda --sequential-io"
    seqrun "cpu old r$round" $OB "X=1" $S/in2 0.0086 "--backend openmp"
    seqrun "cpu new r$round" $N "X=1" $S/in2 0.0086 "--backend openmp"
  done
  } > $O/seq3.txt 2>&1
  cut -c1-120 $O/seq3.txt
  echo "seq3 done at $(( $(date +%s) - t0 )) s" ;;
exitcost)
  nvcc -O2 -arch=sm_90 out/dev/init_probe.cu -o $L/init_probe
  {
  for r in 1 2 3; do
    for m in normal quick reset; do s=$(date +%s%N); $L/init_probe $m > $L/p.txt; echo "probe $m r$r: process wall $(( ($(date +%s%N) - s) / 1000000 )) ms; $(grep -E 'reset' $L/p.txt)"; done
    for E in X=1 NBMC_QUICK_EXIT=1; do
      s=$(date +%s%N); env $E $N/install/bin/nbmc reconstruct $BIG --spacing 0.00484 --cell-size 0.5 --backend cuda --no-cleanup -o $L/f.ply > $L/r.txt 2>&1
      echo "nbmc $E r$r: process wall $(( ($(date +%s%N) - s) / 1000000 )) ms; report $(grep -E '^  total' $L/r.txt | tr -s ' ')"
      s=$(date +%s%N); env $E $N/install/bin/nbmc reconstruct $BIG --spacing 0.00484 --cell-size 0.5 --backend openmp --threads 16 --no-cleanup -o $L/f.ply > $L/r.txt 2>&1
      echo "nbmc cpu $E r$r: process wall $(( ($(date +%s%N) - s) / 1000000 )) ms; report $(grep -E '^  total' $L/r.txt | tr -s ' ')"
    done
  done
  } > $O/exitcost.txt 2>&1
  cat $O/exitcost.txt
  echo "exitcost done at $(( $(date +%s) - t0 )) s" ;;
hostbuf)
  [ -n "${OLDPID:-}" ] && wait $OLDPID
  { echo "== equivalence (new)"; NBMC_CHECK_BAND=1 $N/tests/gpu/nbmc_cuda_equivalence $D 2>&1 | tail -60; } > $O/equivalence.txt
  tail -1 $O/equivalence.txt
  {
  for round in 1 2; do
    for v in old new thp0 cache0; do
      B=$N; [ $v = old ] && B=$OB; E="X=1"; [ $v = thp0 ] && E="NBMC_HOST_THP=0"; [ $v = cache0 ] && E="NBMC_HOST_CACHE=0"
      for args in "--backend openmp --threads 16 --no-cleanup --repeat 3" "--backend openmp --threads 16 --repeat 3" "--backend openmp --threads 16 --no-cleanup" "--backend cuda --no-cleanup --repeat 5" "--backend cuda --repeat 3"; do
        echo "# $v r$round $args"; env $E $B/bench/nbmc_bench $BIG --spacing 0.00484 $args 2>&1 | grep RESULT
      done
      [ $round = 1 ] && { echo "# $v r$round tile2 cpu"; env $E $B/bench/nbmc_bench $BIG --spacing 0.00484 --backend openmp --threads 16 --no-cleanup --tile 2 --repeat 2 2>&1 | grep RESULT; }
      s=$(date +%s%N); env $E $B/install/bin/nbmc reconstruct $BIG --spacing 0.00484 --cell-size 0.5 --backend openmp --threads 16 -o $L/f.ply > $L/r.txt 2>&1
      echo "# $v r$round cli cpu single: wall $(( ($(date +%s%N) - s) / 1000000 )) ms; $(sed -n '/^stage/,/library/p' $L/r.txt | tr -s ' ' | paste -sd' ')"
    done
  done
  } > $O/hostbuf.txt 2>&1
  grep -A1 "^# " $O/hostbuf.txt | grep -o "^# .*bench.*\|^# [a-z0-9]* r[12] [a-z-].*\|peak_rss_mib=[0-9.]*\|total=[0-9.]*\| t[0-6]=[0-9.]*\|postprocess=[0-9.]*" | paste -sd' ' | sed 's/# /\n/g' | cut -c1-250
  echo "hostbuf done at $(( $(date +%s) - t0 )) s" ;;
esac; done
echo "total $(( $(date +%s) - t0 )) s"
