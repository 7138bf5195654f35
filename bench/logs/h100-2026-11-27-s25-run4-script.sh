#!/usr/bin/env bash
# Session 25, device run 4: every kernel of one device-resident reconstruction (ncu durations).
set -uo pipefail
R=$PWD; O=${OUT:-/tmp/o}; L=/tmp/L; mkdir -p $O $L
export PATH=/usr/local/cuda/bin:$PATH
mkdir -p ~/.cache/nbmc/src && cp -r out/dev/kk/* ~/.cache/nbmc/src/
D=$R/out/dev/data; BIG=$D/xyz/cbd1654k_t040_1654104.xyz
t0=$(date +%s)
NBMC_GPU_CHECK_STEPS=build scripts/gpu_check.sh $D $L/gc > $L/build.txt 2>&1 || { tail -40 $L/build.txt; exit 1; }
echo "built in $(( $(date +%s) - t0 )) s"
N=$R/build-cuda
for i in 1 2 3; do $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --no-cleanup --device-resident 2>&1 | grep -o "total=.*t6=[0-9.]*"; done
timeout 400 ncu --metrics gpu__time_duration.sum --csv --kernel-name-base demangled $N/bench/nbmc_bench $BIG --spacing 0.00484 --backend cuda --no-cleanup --device-resident > $L/ncu.csv 2> $L/ncu.err
echo "ncu rc $? lines $(wc -l < $L/ncu.csv)"
python3 - $L/ncu.csv > $O/kernels.txt <<'PY'
import csv, sys, re, collections
rows = [r for r in csv.reader(open(sys.argv[1])) if len(r) > 10]
h = rows[0]; ki = h.index("Kernel Name"); vi = h.index("Metric Value"); ui = h.index("Metric Unit"); ii = h.index("ID")
seq = []; agg = collections.OrderedDict()
for r in rows[1:]:
    name = r[ki]; v = float(r[vi].replace(",", "")); unit = r[ui]
    us = v / 1000 if unit == "nsecond" else (v if unit == "usecond" else v * 1000)
    m = re.findall(r"nbmc::Details::([A-Za-z_0-9]+)", name)
    key = m[0] if m else ("cub " + re.sub(r"<.*", "", name.split("::")[-1]) if "cub" in name else name[:80])
    if "lambda" in name and m: key = m[0]
    seq.append((r[ii], key, us))
    a = agg.setdefault(key, [0, 0.0]); a[0] += 1; a[1] += us
tot = sum(x[2] for x in seq)
print(f"{len(seq)} kernels, {tot/1000:.2f} ms of kernel time")
for k, (n, us) in sorted(agg.items(), key=lambda kv: -kv[1][1]):
    print(f"{us/1000:8.3f} ms {n:4d}x  {k}")
print("\nin order:")
for i, k, us in seq: print(f"{i:>4} {us:9.1f} us  {k}")
PY
head -60 $O/kernels.txt
cp $L/ncu.err $O/ 2>/dev/null; head -c 3000 $L/ncu.csv > $O/ncu-head.csv
echo "total $(( $(date +%s) - t0 )) s"
