#!/usr/bin/env bash
# The source folders' layers, checked from the includes: a stage may use the
# stages below it, never those above, so each folder can be read (and
# changed) knowing only what lies below. The public headers (include/pqdc/)
# include only each other, so that an installed package is whole. Apps, the
# Python module and the benchmarks use the library through the public headers
# only; a benchmark that needs an internal header is listed below by name.
#
#   tests/layering/run.sh SOURCE_DIR
#
# Prints every include that breaks a rule (file:line, the include, the rule)
# and exits 1, or prints the layers and exits 0. A new folder must be placed
# in LAYERS: an unlisted folder fails too.
set -euo pipefail
src=${1:?usage: run.sh SOURCE_DIR}
cd "$src"

# src/ folders, lowest first. A folder may include itself and the folders
# before it.
LAYERS=(
  memory      # large arrays on huge pages
  geometry    # exact predicates
  ranks       # collectives of distributed runs
  procedural  # procedural fields and their sampling
  volume      # volumes made from meshes, seeded noise
  measure     # distances, topology, exact self-intersections
  io          # .vdb and mesh files, atomic and streaming writers
  lattice     # the front end both meshers share
  render      # the software renderer
  postprocess # small-component removal
  bricks      # values read brick by brick, brick stores
  decimate    # edge-collapse decimation
  normals     # vertex normals from the field
  uniform     # uniform dual contouring, in core
  scale       # the uniform drivers brick by brick and across ranks
  adaptive    # octree dual marching cubes
)
# Internal headers a benchmark may include (it checks outputs with them).
BENCH_INTERNAL=("decimate/exact_predicates.hpp")

declare -A rank
for i in "${!LAYERS[@]}"; do rank[${LAYERS[$i]}]=$i; done
broken=0
fail() { echo "$1: $2"; broken=1; }

for dir in src/*/; do
  f=$(basename "$dir")
  [ -n "${rank[$f]+x}" ] || fail "src/$f/" "folder not in tests/layering/run.sh's LAYERS; place it there"
done

# Quoted includes of the form "folder/file" (same-folder includes have no folder).
while IFS=: read -r file line text; do
  from=${file#src/}; from=${from%%/*}
  to=$(sed -E 's/.*#include "([a-z_]+)\/.*/\1/' <<<"$text")
  [ "$to" = pqdc ] && continue
  [ -n "${rank[$from]+x}" ] || continue  # reported above
  if [ -z "${rank[$to]+x}" ]; then
    fail "$file:$line" "includes '$to/', which is not a source folder"
  elif (( rank[$to] > rank[$from] )); then
    fail "$file:$line" "src/$from/ includes src/$to/, a layer above it ($(sed -E 's/^[[:space:]]*//' <<<"$text"))"
  fi
done < <(grep -rnE '^[[:space:]]*#include "[a-z_]+/' src --include='*.cpp' --include='*.hpp' --include='*.h' || true)

# Public headers: only each other.
while IFS=: read -r file line text; do
  header=$(sed -E 's/.*#include "([^"]+)".*/\1/' <<<"$text")
  case "$header" in pqdc/*) continue ;; esac
  fail "$file:$line" "a public header includes '$header', which is not installed; include only pqdc/ headers"
done < <(grep -rnE '^[[:space:]]*#include "' include --include='*.hpp' --include='*.h' --include='*.in' || true)

# Apps, Python and benchmarks: public headers, their own headers, listed exceptions.
while IFS=: read -r file line text; do
  header=$(sed -E 's/.*#include "([^"]+)".*/\1/' <<<"$text")
  case "$header" in pqdc/*|*.inc) continue ;; esac
  case "$header" in */*) ;; *) continue ;; esac  # the caller's own folder
  [ "${header#../}" != "$header" ] && continue   # a parent folder of the caller's own tree (apps/)
  if [[ "$file" == bench/* ]] && printf '%s\n' "${BENCH_INTERNAL[@]}" | grep -qxF "$header"; then continue; fi
  fail "$file:$line" "includes the library's internal '$header'; use a public header (include/pqdc/)"
done < <(grep -rnE '^[[:space:]]*#include "' apps python/src bench --include='*.cpp' --include='*.hpp' --include='*.h' || true)

if (( broken )); then
  echo "layering: the includes above break the layers (tests/layering/run.sh says why each is a rule)"
  exit 1
fi
echo "layering: every include respects the layers, lowest first: ${LAYERS[*]}"
