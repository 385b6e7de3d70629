#!/usr/bin/env bash
# Whole-process wall time and peak RSS of pqdc against a one-call
# openvdb::tools::volumeToMesh program (bench/vdb_to_mesh.cpp: read, mesh,
# write binary float PLY), both writing binary float PLY from the same .vdb,
# default threads. Runs alternate (pqdc, peer, pqdc, ...), median of N (5).
# Peak RSS is /usr/bin/time's %M: the largest process of the run (pqdc's
# meshing child; its supervising parent stays small, reported separately).
#
#   bench/bench_process.sh [BUILD_DIR] [RUNS]      (default: build 5)
#
# Volumes (made once into BUILD_DIR/bench_process/, kept for reruns):
#   sphere    vdb_tool -sphere dim=826 (12.7 M active voxels)
#   armadillo CGAL's armadillo.off at 512 voxels (vdb_tool -mesh2ls dim=512)
#   csg       the noisy CSG field of Figure 3 at 512 (pqdc --procedural figure3 --write-volume)
#   fog       the armadillo level set at 512 as a fog volume (vdb_tool -ls2fog), isovalue 0.5
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build=${1:-$root/build}
runs=${2:-5}
case "$build" in /*) ;; *) build="$root/$build" ;; esac
pqdc=$build/bin/pqdc
peer=$build/bin/vdb_to_mesh
for tool in "$pqdc" "$peer"; do
  [ -x "$tool" ] || { echo "bench_process: $tool not found; build it (cmake --build $build --target pqdc_cli vdb_to_mesh)" >&2; exit 1; }
done
command -v vdb_tool >/dev/null || { echo "bench_process: vdb_tool not found (Debian libopenvdb-tools)" >&2; exit 1; }
work=$build/bench_process
mkdir -p "$work"
cd "$work"

if [ ! -f sphere.vdb ]; then vdb_tool -sphere dim=826 -write sphere.vdb >/dev/null; fi
if [ ! -f armadillo.vdb ]; then
  data=$(dpkg -L libcgal-demo 2>/dev/null | grep '/data\.tar\.gz$' | head -n 1)
  tar -xzf "$data" data/meshes/armadillo.off
  # vdb_tool reads OBJ, not OFF: "OFF", counts, vertices, then "n i j k..." faces.
  awk '/^#/ || NF == 0 { next } s == 0 { s = 1; next } s == 1 { nv = $1; s = 2; next }
       s == 2 && v < nv { print "v", $1, $2, $3; ++v; next }
       s == 2 { printf "f"; for (i = 2; i <= $1 + 1; ++i) printf " %d", $i + 1; printf "\n" }' \
    data/meshes/armadillo.off > armadillo.obj
  vdb_tool -read armadillo.obj -mesh2ls dim=512 -write armadillo.vdb >/dev/null
  rm -rf data armadillo.obj
fi
if [ ! -f csg.vdb ]; then "$pqdc" --procedural figure3 --resolution 512 --write-volume csg.vdb -q; fi
if [ ! -f fog.vdb ]; then vdb_tool -read armadillo.vdb -ls2fog -write fog.vdb >/dev/null; fi

median() { sort -g | awk '{a[NR]=$1} END {print (NR % 2) ? a[(NR+1)/2] : (a[NR/2] + a[NR/2+1]) / 2}'; }
measure() {  # prints "wall_s rss_kib"
  /usr/bin/time -f "%e %M" -o time.txt "$@" >/dev/null 2>&1 || { echo "bench_process: failed: $*" >&2; exit 1; }
  cat time.txt
}

printf '| volume | active voxels | pqdc wall s | volumeToMesh wall s | wall ratio | pqdc peak RSS MiB | volumeToMesh peak RSS MiB | RSS ratio |\n'
printf '|---|---|---|---|---|---|---|---|\n'
for case in sphere armadillo csg fog; do
  iso=0; [ "$case" = fog ] && iso=0.5
  voxels=$(vdb_print -l "$case.vdb" 2>/dev/null | awk '/active voxels/ {print $NF; exit}')
  [ -n "$voxels" ] || voxels=$(vdb_print "$case.vdb" | awk '{for (i=1;i<=NF;i++) if ($i ~ /Vox$/) {print $i; exit}}')
  : > p.txt; : > v.txt
  for ((r = 0; r < runs; ++r)); do
    measure "$pqdc" "$case.vdb" --isovalue "$iso" -o p.ply -q >> p.txt
    measure "$peer" "$case.vdb" v.ply "$iso" >> v.txt
  done
  pw=$(cut -d' ' -f1 p.txt | median); vw=$(cut -d' ' -f1 v.txt | median)
  pm=$(cut -d' ' -f2 p.txt | median); vm=$(cut -d' ' -f2 v.txt | median)
  awk -v c="$case" -v n="$voxels" -v pw="$pw" -v vw="$vw" -v pm="$pm" -v vm="$vm" 'BEGIN {
    printf "| %s | %s | %.2f | %.2f | %.2fx | %.0f | %.0f | %.2fx |\n", c, n, pw, vw, pw / vw, pm / 1024, vm / 1024, pm / vm }'
done
rm -f p.ply v.ply p.txt v.txt time.txt
