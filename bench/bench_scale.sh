#!/usr/bin/env bash
# Issue 14's scale benchmark: a volume larger than the memory it is meshed
# in. A level-set sphere is sampled straight into a brick store as a dense
# volume (every voxel of the lattice active, like a CT scan), then meshed
# out of core; in the same run, for comparison, the same volume as one .vdb
# file meshed by pqdc in core and out of core and by a one-call
# openvdb::tools::volumeToMesh program (bench/vdb_to_mesh.cpp), and the
# store by pqdc-mpi on 1..R ranks (strong scaling). Peak RSS is
# /usr/bin/time's %M (for pqdc, its meshing child; for MPI, each rank).
#
#   bench/bench_scale.sh [BUILD_DIR] [RESOLUTION] [MAX_RANKS]   (default: build 1024 4)
#
# RESOLUTION 1024 gives 1.10 G active voxels (1032^3 points with the margin),
# 3.1 GB of brick files and a 4.3 GB .vdb; the band sphere at 4 x RESOLUTION
# 5.8 GB of brick files and a 3 GB mesh (removed at the end): keep about
# 16 GB of disk free under BUILD_DIR/bench_scale/. Every output of the
# dense volume is compared (cmp) with the store's.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build=${1:-$root/build}
res=${2:-1024}
max_ranks=${3:-4}
case "$build" in /*) ;; *) build="$root/$build" ;; esac
bin=$build/bin
for tool in pqdc pqdc-bricks vdb_to_mesh; do
  [ -x "$bin/$tool" ] || { echo "bench_scale: $bin/$tool not found; build it first" >&2; exit 1; }
done
work=$build/bench_scale
mkdir -p "$work"
cd "$work"
rm -rf store band out.* time.txt stats.json

measure() {  # label, command...: prints "label | wall s | peak RSS MiB"
  local label=$1; shift
  /usr/bin/time -f "%e %M" -o time.txt "$@" >/dev/null 2>log.txt || { cat log.txt >&2; echo "bench_scale: failed: $*" >&2; exit 1; }
  awk -v l="$label" '{printf "| %s | %.1f | %.0f |\n", l, $1, $2 / 1024}' time.txt
}
same() { cmp -s "$1" out.store.ply && echo "same bytes" || echo "DIFFERENT"; }

echo "## Dense level-set sphere at resolution $res"
echo
echo "| step | wall s | peak RSS MiB |"
echo "|---|---|---|"
measure "write the brick store (pqdc-bricks procedural)" \
  "$bin/pqdc-bricks" procedural sphere --resolution "$res" --active-band inf -o store
measure "mesh the store out of core (pqdc)" "$bin/pqdc" store -o out.store.ply --stats stats.json
cp stats.json stats.store.json
measure "write the same volume as one .vdb (pqdc --write-volume, in core)" \
  "$bin/pqdc" --procedural sphere --resolution "$res" --active-band inf --write-volume dense.vdb
measure "mesh the .vdb out of core (pqdc --out-of-core)" "$bin/pqdc" dense.vdb --out-of-core -o out.ooc.ply
echo "| (pqdc --out-of-core against the store: $(same out.ooc.ply)) | | |"
measure "mesh the .vdb in core (pqdc)" "$bin/pqdc" dense.vdb --memory-limit 20000 -o out.incore.ply
echo "| (pqdc in core against the store: $(same out.incore.ply)) | | |"
measure "mesh the .vdb with volumeToMesh (one call, in core)" "$bin/vdb_to_mesh" dense.vdb out.vdb.ply
echo
du -sb store dense.vdb out.store.ply | awk '{printf "%s: %.2f GB\n", $2, $1 / 1e9}'
echo
/usr/bin/python3 - stats.store.json <<'EOF'
import json, sys
s = json.load(open(sys.argv[1]))
t = s["seconds"]
print(f"store mesh: {s['vertices']} vertices, {s['triangles']} triangles, {s['active_cells']} surface cells")
stages = ", ".join(f"{k} {v:.2f}" for k, v in t.items() if k not in ("read", "total", "write"))
print(f"seconds: read {t['read']:.2f}, extraction {t['total']:.2f} ({stages}), write {t['write']:.2f}")
EOF

# A level set whose surface, not its volume, is large: the mesh (about 80 M
# vertices at 4096) would need over 10 GB in memory; streamed brick by
# brick it needs the topology and one brick.
big=$((4 * res))
echo
echo "## Level-set sphere at resolution $big, 10-voxel active band (the mesh streamed)"
echo
echo "| step | wall s | peak RSS MiB |"
echo "|---|---|---|"
measure "write the brick store (pqdc-bricks procedural --active-band 10)" \
  "$bin/pqdc-bricks" procedural sphere --resolution "$big" --active-band 10 -o band
measure "mesh the store (pqdc --memory-limit 4096)" "$bin/pqdc" band --memory-limit 4096 -o out.band.ply --stats stats.json
du -sb band out.band.ply | awk '{printf "%s: %.2f GB\n", $2, $1 / 1e9}'
/usr/bin/python3 - stats.json <<'EOF'
import json, sys
s = json.load(open(sys.argv[1]))
t = s["seconds"]
print(f"band mesh: {s['vertices']} vertices, {s['triangles']} triangles")
print(", ".join(f"{k} {v:.2f}" for k, v in t.items()))
EOF
rm -rf band out.band.ply

if [ -x "$bin/pqdc-mpi" ] && command -v mpirun >/dev/null; then
  echo
  echo "## pqdc-mpi on the store, 1..$max_ranks ranks on this machine (loopback)"
  echo
  echo "| ranks | wall s | largest rank peak RSS MiB | output |"
  echo "|---|---|---|---|"
  export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
  for ((n = 1; n <= max_ranks; ++n)); do
    start=$(date +%s.%N)
    mpirun -np "$n" --mca btl self,tcp --mca btl_tcp_if_include lo --mca oob_tcp_if_include lo \
      /usr/bin/time -f "%M" -a -o ranks.txt "$bin/pqdc-mpi" store -o out.mpi.ply -q >/dev/null 2>log.txt ||
      { cat log.txt >&2; exit 1; }
    wall=$(echo "$(date +%s.%N) - $start" | bc)
    printf "| %d | %.1f | %.0f | %s |\n" "$n" "$wall" "$(sort -g ranks.txt | tail -n 1 | awk '{print $1 / 1024}')" \
      "$(same out.mpi.ply)"
    rm -f ranks.txt
  done
fi
