#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# The nbmc command under mpirun: one frame split over 3 ranks gives the same
# file as one process; --pieces writes one piece per rank and a ParaView
# index (also with --double-positions); --attributes gathered and in pieces; a sequence is shared by 2 ranks, a failed frame is reported and the
# rest written, --resume skips them; a bad input fails on every rank with no
# output left. Usage: cli_mpi.sh NBMC MPIEXEC [MPIEXEC FLAGS...]
set -u
NBMC=$1; shift
MPIRUN=("$@")
SRC=$(cd "$(dirname "$0")/../.." && pwd)
FRAME=$SRC/examples/data/double_dam_break_4732.xyz
W=$(mktemp -d)
trap 'rm -rf "$W"' EXIT
cd "$W"
fail=0
check() { if ! eval "$2"; then echo "FAIL: $1"; fail=1; else echo "ok   $1"; fi; }

"$NBMC" reconstruct "$FRAME" --particle-radius 0.025 -o whole.ply -q
"${MPIRUN[@]}" -n 3 "$NBMC" reconstruct "$FRAME" --particle-radius 0.025 -o mpi.ply --json mpi.json -q
check "gathered mesh equals one process's, byte for byte" "cmp -s whole.ply mpi.ply"
check "report lists 3 ranks" "grep -q '\"mpi\": {\"ranks\": 3' mpi.json"
"${MPIRUN[@]}" -n 3 "$NBMC" reconstruct "$FRAME" --particle-radius 0.025 -o split.ply --subdomains 3x2x2 -q
check "--subdomains under MPI: the same file" "cmp -s whole.ply split.ply"

"$NBMC" reconstruct "$FRAME" --particle-radius 0.025 -o whole64.ply --double-positions -q
"${MPIRUN[@]}" -n 3 "$NBMC" reconstruct "$FRAME" --particle-radius 0.025 -o mpi64.ply --double-positions -q
check "--double-positions: gathered mesh equals one process's, byte for byte (doubles)" \
  "cmp -s whole64.ply mpi64.ply && grep -aq 'property double x' mpi64.ply"
"${MPIRUN[@]}" -n 2 "$NBMC" reconstruct "$FRAME" --particle-radius 0.025 -o surf64.pvtp --pieces --double-positions -q
check "--double-positions --pieces: Float64 points in the pieces and the index" \
  "grep -aq 'type=\"Float64\" Name=\"Points\"' surf64_0.vtp && grep -q 'PDataArray type=\"Float64\" NumberOfComponents=\"3\"' surf64.pvtp"

H5=$SRC/tests/data/h5part_steps.h5part
"$NBMC" reconstruct "$H5" --spacing 0.1 -o h5-whole.ply -q
"${MPIRUN[@]}" -n 3 "$NBMC" reconstruct "$H5" --spacing 0.1 -o h5-par.ply -q
check "HDF5 read by every rank (hyperslabs): the same file" "cmp -s h5-whole.ply h5-par.ply"
"${MPIRUN[@]}" -n 2 "$NBMC" reconstruct "$H5" --spacing 0.1 -o h5-root.ply -q --read-on-root
check "HDF5 read on rank 0 and scattered: the same file" "cmp -s h5-whole.ply h5-root.ply"

"$NBMC" reconstruct "$H5" --spacing 0.1 -o h5-attr-whole.ply --attributes rho,v -q
"${MPIRUN[@]}" -n 3 "$NBMC" reconstruct "$H5" --spacing 0.1 -o h5-attr-mpi.ply --attributes rho,v --json attr.json -q
check "--attributes under MPI: the same file as one process (rho, v), byte for byte" \
  "cmp -s h5-attr-whole.ply h5-attr-mpi.ply && grep -aq 'property float rho' h5-attr-mpi.ply"
check "--attributes under MPI: listed in the report" "grep -q '\"rho\"' attr.json"
"${MPIRUN[@]}" -n 2 "$NBMC" reconstruct "$H5" --spacing 0.1 -o attr.pvtp --pieces --attributes rho,v -q
check "--attributes --pieces: the arrays in the pieces and the index" \
  "grep -aq 'Name=\"rho\"' attr_0.vtp && grep -aq 'Name=\"v\"' attr_1.vtp && grep -q 'Name=\"rho\"' attr.pvtp && grep -q 'Name=\"v\" NumberOfComponents=\"3\"' attr.pvtp"
"${MPIRUN[@]}" -n 2 "$NBMC" reconstruct "$H5" --spacing 0.1 -o bad-attr.ply --attributes nosuch -q 2>bad-attr.err
rc=$?
check "--attributes under MPI: a missing name fails on every rank, no output" \
  "[ $rc -ne 0 ] && grep -q \"no particle attribute 'nosuch'\" bad-attr.err && [ ! -e bad-attr.ply ]"

"$NBMC" reconstruct "$H5" --radius-attribute rho --radius-scale 0.0001 --attributes v -o h5-radii-whole.ply -q
"${MPIRUN[@]}" -n 3 "$NBMC" reconstruct "$H5" --radius-attribute rho --radius-scale 0.0001 --attributes v \
  -o h5-radii-mpi.ply --json radii.json -q
check "--radius-attribute (radii 0.1-0.102) with --attributes under MPI: one process's file, byte for byte" \
  "[ -s h5-radii-whole.ply ] && cmp -s h5-radii-whole.ply h5-radii-mpi.ply"
check "--radius-attribute under MPI: the frame's smallest and largest radius in the report" \
  "grep -q '\"min\": 0.1, \"max\": 0.1019' radii.json"

"${MPIRUN[@]}" -n 3 "$NBMC" reconstruct "$FRAME" --particle-radius 0.025 -o surf.pvtp --pieces -q
check "--pieces: three pieces and an index" \
  "[ -s surf_0.vtp ] && [ -s surf_1.vtp ] && [ -s surf_2.vtp ] && grep -c 'Piece Source' surf.pvtp | grep -q 3"
"${MPIRUN[@]}" -n 2 "$NBMC" reconstruct "$FRAME" --particle-radius 0.025 -o surf.ply --pieces -q 2>err.txt
rc=$?
check "--pieces needs .pvtp/.pvtu (usage error)" "[ $rc -ne 0 ] && grep -q pvtp err.txt"

mkdir -p fr
for i in 1 2 3 4 5; do cp "$FRAME" fr/f_$i.xyz; done
head -c 100 "$FRAME" > fr/f_6.xyz
"${MPIRUN[@]}" -n 2 "$NBMC" reconstruct 'fr/f_{}.xyz' --particle-radius 0.025 -o 'out/s_{}.ply' --json seq.json -q 2>seq.err
rc=$?
check "sequence: exit 1 for the failed frame" "[ $rc -ne 0 ]"
check "sequence: the other five written, equal to one process's" \
  "for i in 1 2 3 4 5; do cmp -s out/s_\$i.ply whole.ply || exit 1; done"
check "sequence: frame 6 reported" "grep -q 'frame 6' seq.err && [ ! -e out/s_6.ply ]"
"${MPIRUN[@]}" -n 2 "$NBMC" reconstruct 'fr/f_{}.xyz' --particle-radius 0.025 -o 'out/s_{}.ply' --resume \
  --frames 1:5 --json resume.json -q 2>/dev/null
check "sequence --resume: all five skipped" "[ \$(grep -o '\"skipped\"' resume.json | wc -l) -ge 5 ]"

"${MPIRUN[@]}" -n 2 "$NBMC" reconstruct fr/f_6.xyz --particle-radius 0.025 -o bad.ply -q 2>bad.err
rc=$?
check "bad input: non-zero exit, message, no output" "[ $rc -ne 0 ] && grep -q 'multiple of 12' bad.err && [ ! -e bad.ply ]"
exit $fail
