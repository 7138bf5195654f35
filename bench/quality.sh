#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Surface-quality benchmark of issue #11: bench/nbmc_quality over the frames
# of ../shared/data/xyz (all but cbd950k), every method, cells r and r/2,
# variants raw (no clean-up), clean (defaults) and smooth (clean-up and
# smooth_iterations = 10). Writes bench/logs/quality-<date>.md: the command,
# machine and commit, the Markdown table, and the QUALITY lines.
#
#   bench/quality.sh [--threads N] [--frames PATTERN] [--out FILE]
#
# Environment: NBMC_QUALITY (the program; default build/bench/nbmc_quality),
# NBMC_DATA_DIR (default ../shared/data).
set -euo pipefail
cd "$(dirname "$0")/.."
cmdline="bench/quality.sh $*"
threads=2
pattern=""
out="bench/logs/quality-$(date -u +%Y-%m-%d).md"
while [ $# -gt 0 ]; do
  case "$1" in
    --threads) threads="$2"; shift 2 ;;
    --frames) pattern="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    *) echo "usage: bench/quality.sh [--threads N] [--frames PATTERN] [--out FILE]" >&2; exit 2 ;;
  esac
done
prog="${NBMC_QUALITY:-build/bench/nbmc_quality}"
data="${NBMC_DATA_DIR:-../shared/data}"
[ -x "$prog" ] || { echo "quality.sh: $prog not built (cmake --build build --target nbmc_quality)" >&2; exit 1; }

# frame file, spacing r (../shared/data/README.md)
frames=(
  "splashsurf_doubledambreak_f26_4732.xyz 0.05"
  "splashsurf_bunny_f14_7706.xyz 0.05"
  "splashsurf_dambreak_f23_24389.xyz 0.05"
  "cbd46k_t050_46250.xyz 0.0156"
  "cbd292k_t040_292008.xyz 0.0086"
  "cbd1654k_t040_1654104.xyz 0.00484"
)

mkdir -p "$(dirname "$out")"
table="$(mktemp)"; lines="$(mktemp)"
trap 'rm -f "$table" "$lines"' EXIT
start=$(date -u +%s)
for entry in "${frames[@]}"; do
  set -- $entry
  file="$data/xyz/$1"
  if [ -n "$pattern" ] && [[ "$1" != *$pattern* ]]; then continue; fi
  [ -f "$file" ] || { echo "quality.sh: missing $file" >&2; exit 1; }
  echo "== $1 (r = $2)" >&2
  "$prog" "$file" --spacing "$2" --threads "$threads" --methods ssp07,zb05,sph,yt10 --cells 1,0.5 \
    --variants raw,clean,smooth --smooth 10 --markdown "$table" | tee -a "$lines" >&2
done
end=$(date -u +%s)

{
  echo "# Surface quality (issue #11), $(date -u '+%Y-%m-%d %H:%M UTC')"
  echo
  echo "Command: \`$cmdline\` ($prog, NBMC_DATA_DIR=$data, threads $threads)"
  echo "Commit: $(git rev-parse --short HEAD 2>/dev/null || echo unknown)$(git diff --quiet 2>/dev/null || echo ' (with local changes)')"
  echo "Machine: $(uname -srm), $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')"
  echo "Wall time of the whole run: $((end - start)) s"
  echo
  echo "Variants: raw = cleanup 0, smoothing 0 (the marching-cubes mesh); clean = the defaults"
  echo "(cleanup on); smooth10 = cleanup on, smooth_iterations 10. Distances from each vertex"
  echo "to its nearest particle in units of r; V/(N r³) = enclosed volume over N r³."
  echo
  cat "$table"
  echo
  echo '```'
  cat "$lines"
  echo '```'
} > "$out"
echo "quality.sh: wrote $out" >&2
