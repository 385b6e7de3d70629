#!/usr/bin/env bash
# Installs every Debian 12 package pqdc needs to build, test, benchmark and
# regenerate its figures. Idempotent and quiet; needs root (or sudo).
set -euo pipefail
PKGS=(
  build-essential cmake
  libopenvdb-dev libboost-iostreams-dev libtbb-dev libeigen3-dev libopenexr-dev libpng-dev
  catch2 libcli11-dev nlohmann-json3-dev libxxhash-dev libopenvdb-tools
  python3 python3-numpy python3-matplotlib
  python3-dev pybind11-dev libboost-python-dev python3-pytest python3-openvdb python3-skimage python3-scipy python3-open3d
  libcgal-dev libcgal-demo libmeshoptimizer-dev
  libopenmpi-dev openmpi-bin
)
missing=()
for p in "${PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
echo "install-deps: installing ${missing[*]}" >&2
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
