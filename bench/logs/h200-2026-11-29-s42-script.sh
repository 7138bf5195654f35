#!/usr/bin/env bash
# Session 42 device runs. new = the working tree (the clean-up's move
# rounds: on the GPU where the mesh is made, on the host threads
# elsewhere), old = e0bde7f (session 41's end), from out/dev/old.tgz.
# Step "moves": CUDA meshes with the moves on the GPU against
# NBMC_DEVICE_MOVES=0 (the host's rounds), byte for byte.
set -uo pipefail
R=$PWD; O=${OUT:-/tmp/o}; L=/tmp/L; mkdir -p $O $L
export PATH=/usr/local/cuda/bin:$PATH
mkdir -p ~/.cache/nbmc/src && tar -C ~/.cache/nbmc/src -xzf out/dev/kk.tgz
D=$R/out/dev/data; BIG=$D/xyz/cbd1654k_t040_1654104.xyz
N=$R/build-cuda; OB=$R/out/oldsrc/build-cuda
t0=$(date +%s)
res() { grep -o "total=[0-9.]*\| postprocess=[0-9.]*\|triangles=[0-9]*" | paste -sd' '; }
for step in "$@"; do case $step in
build)
  NBMC_GPU_CHECK_STEPS=build scripts/gpu_check.sh $D $L/gc > $L/build.txt 2>&1 || { tail -40 $L/build.txt $L/gc/build.log | grep -v "^ *$" | tail -40; exit 1; }
  echo "new built in $(( $(date +%s) - t0 )) s" ;;
oldbg)
  mkdir -p out/oldsrc && tar -xzf out/dev/old.tgz -C out/oldsrc
  (cd out/oldsrc && NBMC_CUDA_CMAKE_ARGS="-DNBMC_BUILD_TESTS=OFF" NBMC_JOBS=6 scripts/setup.sh --cuda-only > $L/old-build.txt 2>&1; echo "old build rc $? at $(( $(date +%s) - t0 )) s") &
  OLDPID=$! ;;
moves)  # the GPU's move rounds against the host's (NBMC_DEVICE_MOVES=0), the same frames and methods, byte for byte
  for fs in cbd46k_t050_46250:0.0156 cbd292k_t040_292008:0.0086 cbd1654k_t040_1654104:0.00484 splashsurf_dambreak_f23_24389:0.05 splashsurf_bunny_f14_7706:0.05 cbd950k_t040_950232:0.0058; do
    f=${fs%%:*}; sp=${fs#*:}
    for m in ssp07 yt10 zb05 sph; do for res in 0.5 1; do
      a="$D/xyz/$f.xyz --spacing $sp --cell-size $res --method $m"
      NBMC_TRACE=1 $N/src/cli/nbmc reconstruct $a --backend cuda -o /tmp/gm.ply > /tmp/gm.txt 2>&1 || echo "FAIL gpu $f $m $res"
      NBMC_DEVICE_MOVES=0 $N/src/cli/nbmc reconstruct $a --backend cuda -o /tmp/hm.ply > /dev/null 2>&1 || echo "FAIL host $f $m $res"
      mv=$(grep -o "moves on the device *n=[0-9]*" /tmp/gm.txt | grep -o "[0-9]*$" | head -1)
      if cmp -s /tmp/gm.ply /tmp/hm.ply; then echo "SAME $f $m $res device-moves=${mv:-none}"; else echo "DIFFERENT $f $m $res device-moves=${mv:-none}"; fi
    done; done
  done > $O/moves.txt 2>&1
  grep -c SAME $O/moves.txt; grep "DIFFERENT\|FAIL\|none" $O/moves.txt | head
  echo "moves done at $(( $(date +%s) - t0 )) s" ;;
probe)  # the device rounds' steps; host rounds (NBMC_DEVICE_MOVES=0) against device rounds; the clean-up alone at 16 threads
  NBMC_TRACE=1 $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --device-resident --repeat 3 2>&1 | grep "moves on the device:" | cut -c1-250
  NBMC_TRACE=1 $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --tile 2 --repeat 2 2>&1 | grep "moves on the device:" | cut -c1-250
  for round in 1 2; do for e in "" "NBMC_DEVICE_MOVES=0"; do
    for args in "--backend cuda --device-resident --repeat 5" "--backend cuda --repeat 5" "--backend cuda --tile 2 --repeat 3"; do
      echo "# ${args// /_} ${e:-device-moves} r$round $(env $e $N/bench/nbmc_bench $BIG --spacing 0.00484 $args 2>&1 | grep RESULT | res)"
    done
  done; done
  echo "probe done at $(( $(date +%s) - t0 )) s" ;;
check)
  { echo "== equivalence (new)"; NBMC_CHECK_BAND=1 $N/tests/gpu/nbmc_cuda_equivalence $D 2>&1 | tail -80; } > $O/equivalence.txt
  tail -1 $O/equivalence.txt; grep FAIL $O/equivalence.txt | head
  NBMC_GPU_CHECK_STEPS="pointers subdomains" scripts/gpu_check.sh $D $L/gc2 > $O/pointers-subdomains.txt 2>&1; echo "pointers+subdomains rc $?"
  grep -i "fail\|DIFFERENT" $O/pointers-subdomains.txt | head
  echo "check done at $(( $(date +%s) - t0 )) s" ;;
waitold)
  [ -n "${OLDPID:-}" ] && wait $OLDPID; OLDPID=""
  tail -3 $L/old-build.txt; echo "old waited at $(( $(date +%s) - t0 )) s" ;;
trace)  # per frame: the clean-up's steps, 1.65 M SSP07 device-resident, YT10 host mesh, 13.2 M host mesh
  for v in new old; do B=$N; [ $v = old ] && B=$OB
    NBMC_TRACE=1 $B/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --device-resident --repeat 4 > $O/trace-$v.txt 2>&1
    NBMC_TRACE=1 $B/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --method yt10 --repeat 3 > $L/trace-yt-$v.txt 2>&1
    NBMC_TRACE=1 $B/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --tile 2 --repeat 3 > $L/trace-t2-$v.txt 2>&1
    for f in $O/trace-$v.txt $L/trace-yt-$v.txt $L/trace-t2-$v.txt; do echo "# $v $(basename $f)"; grep -h "clean-up rounds\|clean-up: repairs\|RESULT" $f | tail -12 | cut -c1-230 | sed 's/RESULT.*\(total=[0-9.]*\).*\(postprocess=[0-9.]*\).*/\1 \2/'; done
  done
  grep -h "clean-up" $L/trace-yt-*.txt $L/trace-t2-*.txt > /dev/null; cat $L/trace-yt-new.txt $L/trace-t2-new.txt | grep -v "^ *$" > $O/trace-yt-t2-new.txt; cat $L/trace-yt-old.txt $L/trace-t2-old.txt > $O/trace-yt-t2-old.txt
  echo "trace done at $(( $(date +%s) - t0 )) s" ;;
sanit)
  NBMC_GPU_CHECK_STEPS="sanitizers" scripts/gpu_check.sh $D $L/gc3 > $O/sanitizers.txt 2>&1; echo "sanitizers rc $?"
  grep -iE "error summary|errors|hazard" $O/sanitizers.txt | head -12
  echo "sanitizers done at $(( $(date +%s) - t0 )) s" ;;
trace8)
  for v in new old; do B=$N; [ $v = old ] && B=$OB
    NBMC_TRACE=1 $B/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --device-resident --repeat 8 > $O/trace8-$v.txt 2>&1
    echo "# $v"; grep -h "changed entries\|upload (\|compaction on the device\|compaction's device" $O/trace8-$v.txt | tail -8 | cut -c1-120
    grep RESULT $O/trace8-$v.txt | res
  done
  echo "trace8 done at $(( $(date +%s) - t0 )) s" ;;
benchdr)
  {
  for round in 1 2 3 4; do
    for v in old new; do B=$N; [ $v = old ] && B=$OB
      for args in "--backend cuda --device-resident --repeat 5" "--backend cuda --device-resident --method yt10 --repeat 5" "--backend cuda --device-resident --tile 2 --repeat 3"; do
        echo "# ${args// /_} $v r$round"; $B/bench/nbmc_bench $BIG --spacing 0.00484 $args 2>&1 | grep RESULT
      done
    done
  done
  } > $O/benchdr.txt 2>&1
  grep -A1 "^# " $O/benchdr.txt | grep -o "^# .*\|total=[0-9.]*\| postprocess=[0-9.]*" | paste -sd' ' | sed 's/# /\n/g'
  echo "benchdr done at $(( $(date +%s) - t0 )) s" ;;
scaling)  # the clean-up alone on the host threads: raw meshes, 1-16 threads
  for m in ssp07 yt10; do
    $N/src/cli/nbmc reconstruct $BIG --spacing 0.00484 --backend cuda --method $m --no-cleanup -o /tmp/raw-$m.ply > /dev/null 2>&1 || echo "raw $m failed"
    for t in 1 2 4 8 16; do
      NBMC_TRACE=1 $N/bench/nbmc_cleanup_bench /tmp/raw-$m.ply 0.00242 $t 3 > $L/scal-$m-$t.txt 2>&1
      echo "# $m threads=$t $(grep CLEANUP $L/scal-$m-$t.txt | grep -o 'wall=[0-9.]*' | paste -sd' ') $(grep 'clean-up: repairs' $L/scal-$m-$t.txt | tail -1 | grep -o '[0-9.]* ms')"
      awk '/clean-up: start/{b=""} /clean-up rounds|clean-up pass|clean-up: [a-z]/{b=b $0 "\n"} END{printf "%s", b}' $L/scal-$m-$t.txt | cut -c1-200
    done
  done > $O/scaling.txt 2>&1
  grep "^#\|items=9772\|items=15851" $O/scaling.txt | cut -c1-220
  echo "scaling done at $(( $(date +%s) - t0 )) s" ;;
scalold)  # the clean-up alone, new and old, on raw meshes made by new (4 and 16 host threads)
  for m in ssp07 yt10; do
    [ -f /tmp/raw-$m.ply ] || $N/src/cli/nbmc reconstruct $BIG --spacing 0.00484 --backend cuda --method $m --no-cleanup -o /tmp/raw-$m.ply > /dev/null 2>&1
    for round in 1 2; do for v in new old; do B=$N; [ $v = old ] && B=$OB
      for t in ${SCAL_THREADS:-4 16}; do
        NBMC_TRACE=1 $B/bench/nbmc_cleanup_bench /tmp/raw-$m.ply 0.00242 $t 4 > $L/so.txt 2>&1
        echo "# $m $v r$round threads=$t $(grep CLEANUP $L/so.txt | grep -o 'wall=[0-9.]*\|hash=[0-9a-f]*\|triangles=[0-9]*' | paste -sd' ')"
        grep "clean-up: moves \|clean-up: repairs \|clean-up: compaction" $L/so.txt | tail -3 | grep -o "clean-up: [a-z]*\|[0-9.]* ms" | paste -sd' '
        grep "^repairs:" $L/so.txt | tail -1
        cat $L/so.txt >> $L/scalold-$m-$v-t$t.txt
      done
    done; done
  done > $O/scalold.txt 2>&1
  cat $O/scalold.txt | cut -c1-300
  echo "scalold done at $(( $(date +%s) - t0 )) s" ;;
trace6)  # in the library: the clean-up's steps per frame, device-resident and host mesh
  for v in new old; do B=$N; [ $v = old ] && B=$OB
    for args in "--backend cuda --device-resident --repeat 6" "--backend cuda --repeat 6" "--backend cuda --tile 2 --repeat 3"; do
      NBMC_TRACE=1 $B/bench/nbmc_bench $BIG --spacing 0.00484 $args > $L/tr.txt 2>&1
      echo "# $v ${args// /_}"; grep -h "clean-up: repairs \|clean-up: compaction \|clean-up rounds: items=9772\|clean-up rounds: items=56\|pass: items=9772\|pass: items=56" $L/tr.txt | tail -8 | sed 's/.*main thread: //' | cut -c1-200; grep RESULT $L/tr.txt | res
      cat $L/tr.txt >> $L/trace6-$v.txt
    done
  done > $O/trace6.txt 2>&1
  cp $L/trace6-new.txt $L/trace6-old.txt $O/ 2>/dev/null; cat $O/trace6.txt
  echo "trace6 done at $(( $(date +%s) - t0 )) s" ;;
quality)  # issue #11's table, new and old, 16 host threads
  for v in new old; do B=$N; [ $v = old ] && B=$OB
    NBMC_QUALITY=$B/bench/nbmc_quality NBMC_DATA_DIR=$D bench/quality.sh --threads 16 --out $O/quality-$v.md > $L/q-$v.txt 2>&1; echo "quality $v rc $?"
  done
  echo "quality done at $(( $(date +%s) - t0 )) s" ;;
hostmesh)  # new only: the host-mesh path, defaults
  for round in 1 2 3; do for args in "--backend cuda --repeat 5" "--backend cuda --device-resident --repeat 5"; do
    echo "# ${args// /_} new r$round $($N/bench/nbmc_bench $BIG --spacing 0.00484 $args 2>&1 | grep RESULT | grep -o 'total=[0-9.]*\| postprocess=[0-9.]*' | paste -sd' ')"
  done; done | tee $O/hostmesh.txt
  echo "hostmesh done at $(( $(date +%s) - t0 )) s" ;;
bench)
  {
  for round in 1 2 3 4 5; do
    for v in old new; do B=$N; [ $v = old ] && B=$OB
      for args in "--backend cuda --device-resident --repeat 5" "--backend cuda --repeat 5" "--backend cuda --method yt10 --repeat 5" "--backend cuda --tile 2 --repeat 3"; do
        echo "# ${args// /_} $v r$round"; $B/bench/nbmc_bench $BIG --spacing 0.00484 $args 2>&1 | grep RESULT
      done
    done
  done
  } > $O/bench.txt 2>&1
  grep -A1 "^# " $O/bench.txt | grep -o "^# .*\|total=[0-9.]*\| postprocess=[0-9.]*" | paste -sd' ' | sed 's/# /\n/g'
  echo "bench done at $(( $(date +%s) - t0 )) s" ;;
dltrace)  # per frame: the download's trace lines, old / new / nopin
  for v in new nopin old; do B=$N; E=""; [ $v = old ] && B=$OB; [ $v = nopin ] && E="NBMC_HOST_PIN=0"
    for args in "--backend cuda --repeat 6" "--backend cuda --device-resident --repeat 6" "--backend cuda --tile 2 --repeat 4"; do
      env $E NBMC_TRACE=1 $B/bench/nbmc_bench $BIG --spacing 0.00484 $args > $L/dl.txt 2>&1
      echo "# $v ${args// /_}"; grep -h "download:\|post-processing: download\|mesh: download\|stage done.*n=6 " $L/dl.txt | cut -c1-200 | tail -12; grep RESULT $L/dl.txt | res
      cat $L/dl.txt >> $O/dltrace-$v.txt
    done
  done > $O/dltrace.txt 2>&1
  grep "^#\|download:\|total=" $O/dltrace.txt | cut -c1-200
  echo "dltrace done at $(( $(date +%s) - t0 )) s" ;;
bench3)
  {
  for round in 1 2 3 4 5 6 7 8; do
    for v in old new nopin; do B=$N; E=""; [ $v = old ] && B=$OB; [ $v = nopin ] && E="NBMC_HOST_PIN=0"
      for args in "--backend cuda --repeat 5" "--backend cuda --device-resident --repeat 5" "--backend cuda --tile 2 --repeat 3"; do
        echo "# ${args// /_} $v r$round"; env $E $B/bench/nbmc_bench $BIG --spacing 0.00484 $args 2>&1 | grep RESULT
      done
    done
  done
  } > $O/bench3.txt 2>&1
  grep -A1 "^# " $O/bench3.txt | grep -o "^# .*\|total=[0-9.]*\| postprocess=[0-9.]*" | paste -sd' ' | sed 's/# /\n/g'
  echo "bench3 done at $(( $(date +%s) - t0 )) s" ;;
order)  # the 13.2 M frame, traced per frame, old and new in both orders
  for seq in "old new" "new old" "old new" "new old"; do for v in $seq; do B=$N; [ $v = old ] && B=$OB
    NBMC_TRACE=1 $B/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --tile 2 --repeat 5 > $L/or.txt 2>&1
    echo "# $v ($seq) $(grep RESULT $L/or.txt | res)"
    grep "clean-up: repairs .*n=56015" $L/or.txt | grep -o "[0-9.]* ms" | paste -sd' ' | sed 's/^/  repairs /'
    grep "rounds: items=81382" $L/or.txt | grep -o "waiting [0-9.]*" | paste -sd' ' | sed 's/^/  /'
    grep "pass: items=81382" $L/or.txt | grep -o "list [0-9.]*" | paste -sd' ' | sed 's/^/  /'
    cat $L/or.txt >> $L/order-$v.txt
  done; done > $O/order.txt 2>&1
  cat $O/order.txt
  echo "order done at $(( $(date +%s) - t0 )) s" ;;
esac; done
echo "total $(( $(date +%s) - t0 )) s"
