#!/usr/bin/env bash
# Session 25, device run 5: the host's mixed-cell bit-mask filter on the GPU
# (round-0 leak detection, pass A), new = working tree, old = HEAD (fb55d88).
set -uo pipefail
R=$PWD; O=${OUT:-/tmp/o}; L=/tmp/L; mkdir -p $O $L
export PATH=/usr/local/cuda/bin:$PATH
mkdir -p ~/.cache/nbmc/src && cp -r out/dev/kk/* ~/.cache/nbmc/src/
D=$R/out/dev/data; BIG=$D/xyz/cbd1654k_t040_1654104.xyz; MID=$D/xyz/cbd292k_t040_292008.xyz
t0=$(date +%s)
NBMC_GPU_CHECK_STEPS=build scripts/gpu_check.sh $D $L/gc > $L/build.txt 2>&1 || { tail -40 $L/build.txt $L/gc/build.log | grep -v "^ *$" | tail -40; exit 1; }
echo "new built in $(( $(date +%s) - t0 )) s"
mkdir -p /tmp/old && tar -xf out/dev/old.tar -C /tmp/old
(cd /tmp/old && NBMC_CUDA_CMAKE_ARGS="-DNBMC_BUILD_TESTS=OFF" NBMC_JOBS=8 scripts/setup.sh --cuda-only > $L/old-build.txt 2>&1; echo "old build rc $?") &
OLDPID=$!
N=$R/build-cuda; OB=/tmp/old/build-cuda
{ echo "== equivalence (new)"; NBMC_CHECK_BAND=1 $N/tests/gpu/nbmc_cuda_equivalence $D 2>&1 | tail -30; } > $O/equivalence.txt
tail -1 $O/equivalence.txt
wait $OLDPID
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
{
for round in 1 2 3; do
  for v in old new; do
    B=$N; [ $v = old ] && B=$OB
    for args in "--no-cleanup" "--no-cleanup --device-resident" "" "--no-cleanup --tile 2" "--no-cleanup --method zb05" "--cell-size 1 --no-cleanup"; do
      echo "# $v r$round $args"; $B/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda $args 2>&1 | grep RESULT
    done
  done
done
} > $O/bench.txt 2>&1
grep -A1 "^# " $O/bench.txt | grep -o "^# .*\|total=[0-9.]*\|t4=[0-9.]*\|t5=[0-9.]*" | paste -sd' ' | sed 's/# /\n/g'
for v in old new; do B=$N; [ $v = old ] && B=$OB
  timeout 200 ncu --metrics gpu__time_duration.sum --csv --kernel-name-base demangled -k regex:"mark_surface_particles" $B/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --no-cleanup > $L/ncu-$v.csv 2>/dev/null
  python3 - $L/ncu-$v.csv $v <<'PY' | tee -a $O/ncu.txt
import csv, sys
rows = [r for r in csv.reader(open(sys.argv[1])) if len(r) > 10]
h = rows[0]; ki = h.index("Kernel Name"); vi = h.index("Metric Value")
tot = 0
for r in rows[1:]:
    v = float(r[vi].replace(",", "")); tot += v
    print(sys.argv[2], f"{v/1000:9.1f} us", r[ki][:150])
print(sys.argv[2], f"total {tot/1e6:.3f} ms")
PY
done
echo "total $(( $(date +%s) - t0 )) s"
