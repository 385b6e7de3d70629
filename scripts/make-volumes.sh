#!/usr/bin/env bash
# Regenerates every volume in volumes/ (see volumes/README.md for what each
# one is and where it comes from).
#
#   scripts/make-volumes.sh [BUILD_DIR]     (default: build)
#
# Needs the built tools BUILD_DIR/bin/pqdc and BUILD_DIR/bin/pqdc-mesh-to-volume
# and, for the mesh-derived volumes, CGAL's data set from Debian's
# libcgal-demo (scripts/install-deps.sh installs it). Only the meshes used are
# extracted, into a temporary directory that is removed on exit.
# The voxel data are deterministic; the .vdb files still differ from run to
# run in the 36-byte file UUID OpenVDB writes into every header.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/.." && pwd)"
build="${1:-build}"
case "$build" in /*) ;; *) build="$root/$build" ;; esac
out="$root/volumes"

pqdc="$build/bin/pqdc"
mesh_to_volume="$build/bin/pqdc-mesh-to-volume"
for tool in "$pqdc" "$mesh_to_volume"; do
  if [ ! -x "$tool" ]; then
    echo "make-volumes: $tool not found; build first (cmake --build $build)" >&2
    exit 1
  fi
done

# CGAL's data tarball ships with libcgal-demo; its path has moved between
# releases, so ask dpkg rather than hard-coding it.
cgal_data="$(dpkg -L libcgal-demo 2>/dev/null | grep '/data\.tar\.gz$' | head -n 1 || true)"
if [ -z "$cgal_data" ] || [ ! -f "$cgal_data" ]; then
  echo "make-volumes: CGAL's data.tar.gz not found; install libcgal-demo (scripts/install-deps.sh)" >&2
  exit 1
fi

tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
tar -xzf "$cgal_data" -C "$tmp" data/meshes/fandisk.off data/meshes/armadillo.off

mkdir -p "$out"
set -x
# Mesh-derived level sets (cells along the longest side of the mesh's box;
# narrow band of 3 voxels each side).
# --distances openvdb: these two files predate pqdc's exact distances and stay
# as they were (golden hashes and README figures are measured on them).
"$mesh_to_volume" "$tmp/data/meshes/fandisk.off" --resolution 160 --half-width 3 --distances openvdb -o "$out/fandisk.vdb"
"$mesh_to_volume" "$tmp/data/meshes/armadillo.off" --resolution 128 --half-width 3 --distances openvdb -o "$out/armadillo.vdb"

# Procedural fields sampled by pqdc (default parameters, grid "surface").
"$pqdc" --procedural sphere --resolution 64 --write-volume "$out/sphere.vdb"
"$pqdc" --procedural box --resolution 64 --write-volume "$out/box.vdb"
"$pqdc" --procedural figure3 --resolution 64 --write-volume "$out/figure3.vdb"
