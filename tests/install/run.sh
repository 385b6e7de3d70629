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
