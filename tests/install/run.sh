#!/usr/bin/env bash
# Installs the pqdc build tree into a scratch prefix, then configures, builds
# and runs tests/install/consumer against it with find_package(pqdc).
set -euo pipefail
build_dir=$1
scratch=$2
src_dir=$(cd "$(dirname "$0")" && pwd)
rm -rf "$scratch"
cmake --install "$build_dir" --prefix "$scratch/prefix" >/dev/null
cmake -S "$src_dir" -B "$scratch/build" -DCMAKE_PREFIX_PATH="$scratch/prefix" -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$scratch/build" -j2 >/dev/null
"$scratch/build/consumer"
"$scratch/build/render_consumer"
# Every app is installed and runs from the prefix (RPATH finds libpqdc).
for app in pqdc pqdc-measure pqdc-render pqdc-mesh-to-volume pqdc-add-noise pqdc-bricks pqdc-decimate; do
  "$scratch/prefix/bin/$app" --help >/dev/null
done
# pqdc finds its installed worker (libexec/pqdc/pqdc-job) and meshes a shipped volume with it.
"$scratch/prefix/bin/pqdc" "$src_dir/../../volumes/sphere.vdb" -o "$scratch/sphere.ply" --quiet
test -s "$scratch/sphere.ply"
test -x "$(find "$scratch/prefix" -path '*/libexec/pqdc/pqdc-job' | head -n 1)"
# The library carries its SONAME version.
soname=$(objdump -p "$(find "$scratch/prefix" -name libpqdc.so | head -n 1)" 2>/dev/null | awk '/SONAME/ {print $2}')
case "$soname" in
  libpqdc.so.[0-9]*) echo "consumer: installed $soname and every app" ;;
  *) echo "install: libpqdc has no versioned SONAME ('$soname')" >&2; exit 1 ;;
esac
# The installed config prefers an OpenVDB CMake config when there is one
# (OpenVDB 11+, vcpkg, conda): a stand-in config that wraps Debian's Find
# module and announces itself must be the one used.
fake=$scratch/fake-openvdb/lib/cmake/OpenVDB
mkdir -p "$fake"
cat > "$fake/OpenVDBConfig.cmake" <<'CFG'
message(STATUS "pqdc-install-test: OpenVDBConfig.cmake used")
find_package(TBB CONFIG REQUIRED)  # as OpenVDB's own config finds it (find_dependency)
find_path(_fake_openvdb_module FindOpenVDB.cmake PATH_SUFFIXES lib/${CMAKE_LIBRARY_ARCHITECTURE}/cmake/OpenVDB PATHS /usr)
list(APPEND CMAKE_MODULE_PATH ${_fake_openvdb_module})
find_package(OpenVDB MODULE REQUIRED COMPONENTS openvdb)
set(OpenVDB_FOUND TRUE)
CFG
log=$(cmake -S "$src_dir" -B "$scratch/build-config" -DCMAKE_BUILD_TYPE=Release \
  "-DCMAKE_PREFIX_PATH=$scratch/prefix;$scratch/fake-openvdb" 2>&1)
case "$log" in
  *"OpenVDBConfig.cmake used"*) echo "consumer: pqdcConfig.cmake took the OpenVDB CMake config first" ;;
  *) echo "install: pqdcConfig.cmake did not try find_package(OpenVDB CONFIG)" >&2; echo "$log" >&2; exit 1 ;;
esac
