#!/usr/bin/env bash
# pqdc-mpi against pqdc: the same output bytes for 1 to 4 ranks, uniform
# and adaptive, and a failing or killed job leaves no output. Run by ctest (tests/CMakeLists.txt) as
#   run.sh PQDC PQDC_MPI PQDC_BRICKS PQDC_ADD_NOISE VOLUMES_DIR SCRATCH_DIR MPIEXEC
# Ranks run on loopback only (the machines here have no network), as root
# when CI runs as root.
set -euo pipefail
pqdc=$1 pqdc_mpi=$2 pqdc_bricks=$3 add_noise=$4 volumes=$5 scratch=$6 mpiexec=$7
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
rm -rf "$scratch"
mkdir -p "$scratch"
cd "$scratch"

mpi() {
  local ranks=$1
  shift
  "$mpiexec" -np "$ranks" --oversubscribe --mca btl self,tcp --mca btl_tcp_if_include lo \
             --mca oob_tcp_if_include lo "$pqdc_mpi" "$@"
}

fail() {
  echo "mpi test: $*" >&2
  exit 1
}

# same_bytes NAME RANKS... -- ARGS...: pqdc ARGS -o NAME.ply against pqdc-mpi on each rank count.
same_bytes() {
  local name=$1
  shift
  local ranks=()
  while [ "$1" != "--" ]; do ranks+=("$1"); shift; done
  shift
  "$pqdc" "$@" --brick-size 128 -o "$name.ply" --quiet
  [ -s "$name.ply" ] || fail "$name: pqdc wrote no mesh"
  for n in "${ranks[@]}"; do
    mpi "$n" "$@" --brick-size 128 -o "$name.$n.ply" --quiet
    cmp "$name.ply" "$name.$n.ply" || fail "$name: $n ranks differ from pqdc"
    echo "mpi test: $name, $n ranks: same bytes ($(stat -c %s "$name.ply") bytes)"
  done
}

# A CAD part (sharp edges, about 8 bricks of 128), quads and sharp gradients.
same_bytes fandisk 1 2 3 4 -- "$volumes/fandisk.vdb"
same_bytes fandisk-quads 3 -- "$volumes/fandisk.vdb" --quads --gradient sharp --precision double
# Uniform runs are streamed: each rank meshes its bricks and writes its part
# of the file at its offset (a shared file system: this one). A text format
# (OBJ) and the stage names in --stats show it.
"$pqdc" "$volumes/fandisk.vdb" -o fandisk.obj --quiet
mpi 3 "$volumes/fandisk.vdb" --brick-size 128 -o fandisk.3.obj --stats fandisk.3.json --quiet
cmp fandisk.obj fandisk.3.obj || fail "fandisk OBJ: 3 ranks differ from pqdc"
grep -q '"write pieces"' fandisk.3.json || fail "fandisk: the 3-rank run was not streamed: $(cat fandisk.3.json)"
echo "mpi test: fandisk OBJ, 3 ranks streamed: same bytes"
# Standard output is no file the other ranks can open: their parts travel to
# rank 0, which writes them in order (PartTransfer::through_root).
mpi 3 "$volumes/fandisk.vdb" --brick-size 128 -o - --format obj --quiet > fandisk.3.stdout.obj
cmp fandisk.obj fandisk.3.stdout.obj || fail "fandisk OBJ to standard output: 3 ranks differ from pqdc"
echo "mpi test: fandisk OBJ to standard output, 3 ranks: same bytes"
# Noisy: the automatic denoising smooths each brick with its halo.
"$add_noise" "$volumes/armadillo.vdb" --sigma-voxels 0.3 --seed 3 -o noisy.vdb >/dev/null
same_bytes noisy 2 3 -- noisy.vdb
# A brick store (pqdc-bricks split), read file by file: each rank reads a share of
# the files for the candidate list, then the files its bricks and halos overlap.
"$pqdc_bricks" split "$volumes/fandisk.vdb" --brick-size 128 -o fandisk.bricks >/dev/null
same_bytes store 2 3 -- fandisk.bricks
# Vertex normals: each rank computes those of its own pieces (streamed);
# with --min-component rank 0 reads the delay-loaded grid node by node.
same_bytes normals 2 3 -- "$volumes/fandisk.vdb" --vertex-normals
same_bytes normals-components 2 -- "$volumes/fandisk.vdb" --vertex-normals --min-component 2
# Islands (--min-component), streamed: the ranks join the components that
# cross their boundaries.
same_bytes islands 2 3 4 -- noisy.vdb --min-component 3.5 --sigma-n 0 --denoise off
# A procedural field: every rank samples it.
same_bytes procedural 2 -- --procedural sphere --resolution 96

# Adaptive mode: the ranks share the finest octree level, rank 0 builds the rest.
same_bytes adaptive 1 2 3 4 -- "$volumes/fandisk.vdb" --adaptive
same_bytes adaptive-noisy 3 -- noisy.vdb --adaptive --quads
same_bytes adaptive-store 2 -- fandisk.bricks --adaptive --gradient sharp
# The untangle stage pins cells here and rank 0 rebuilds the octree alone.
same_bytes adaptive-rebuilds 2 -- --procedural figure3 --resolution 48 --adaptive --max-error 0.2 --max-cell-size 8

# Usage errors: reported once, exit 2, nothing written.
set +e
mpi 2 - -o stdin.ply <"$volumes/fandisk.vdb" 2>usage.txt
code=$?
set -e
[ "$code" -eq 2 ] || fail "input -: exit code $code, expected 2"
[ "$(grep -c 'reads its input on every rank' usage.txt)" -eq 1 ] || fail "input -: message not printed exactly once: $(cat usage.txt)"
[ ! -e stdin.ply ] || fail "input -: an output file was written"
# --help is pqdc-mpi's own (its usage lines), printed once.
mpi 2 --help >help.txt
[ "$(grep -c '^usage: mpirun -np N pqdc-mpi' help.txt)" -eq 1 ] || fail "--help: not pqdc-mpi's usage, once: $(head -5 help.txt)"
if grep -q '^usage: pqdc \|\[OPTIONS\]' help.txt; then fail "--help: pqdc's or CLI11's usage line"; fi

# A failing rank ends the job (MPI_Abort) with its error and no output: a
# brick file cut short, refused by the size index.txt records before OpenVDB
# parses it (every rank opens every brick file, so each rank that gets there
# first reports it). Parsed, the cut file made OpenVDB allocate about 8 GB
# per rank, and the OOM killer ended a rank before it could speak.
last=$(ls fandisk.bricks/brick-*.vdb | sort -V | tail -n 1)
truncate -s 2000 "$last"
set +e
mpi 3 fandisk.bricks -o broken.ply --quiet 2>broken.txt
code=$?
set -e
[ "$code" -ne 0 ] || fail "a corrupt brick: exit code 0"
grep -q "pqdc-mpi (rank" broken.txt || fail "a corrupt brick: no rank error message: $(cat broken.txt)"
ls broken.ply* .broken.ply* 2>/dev/null && fail "a corrupt brick: output left behind"
echo "mpi test: usage and rank failures end the job without output"

# A rank killed outright (SIGKILL: the OOM killer, a batch system's limit)
# while the ranks write their parts into the shared temporary file: mpirun
# ends the other rank with SIGTERM, and its handler removes the file
# (pqdc::remove_temporary_files) instead of waiting for a write that cannot
# finish. Rank 1 first; then rank 0, once rank 1 holds the file open by its
# name. The ranks are stopped (SIGSTOP) the moment the file appears, so
# that the test looks at them while it exists (about 200 MB of PLY, a few
# tenths of a second of writing).
# ranks_of PID: mpirun's pqdc-mpi children (from /proc: procps may be missing).
ranks_of() {
  local stat
  for stat in /proc/[0-9]*/stat; do
    read -r pid comm _ ppid _ <"$stat" 2>/dev/null || continue
    [ "$ppid" = "$1" ] && [ "$comm" = "(pqdc-mpi)" ] && echo "$pid"
  done
  return 0
}
"$pqdc_bricks" procedural sphere --resolution 1024 -o big.bricks -q
for victim in 1 0; do
  # mpirun follows its SIGTERM with SIGKILL after odls_base_sigkill_timeout
  # (1 s by default); under ctest -j2 a rank may not run its handler that
  # soon, so the test gives it 10 s.
  "$mpiexec" -np 2 --oversubscribe --mca btl self,tcp --mca btl_tcp_if_include lo \
             --mca oob_tcp_if_include lo --mca odls_base_sigkill_timeout 10 \
             "$pqdc_mpi" big.bricks -o killed.ply --quiet 2>killed.txt &
  job=$!
  # Both ranks' pids first, so that they can be frozen the moment the file
  # appears: it exists for a few tenths of a second, less than a loaded
  # machine may take between two looks.
  ranks=
  for _ in $(seq 3000); do
    ranks=$(ranks_of "$job")
    [ "$(printf '%s\n' "$ranks" | grep -c .)" = 2 ] && break
    sleep 0.01
  done
  [ "$(printf '%s\n' "$ranks" | grep -c .)" = 2 ] || fail "killing rank $victim: mpirun's two ranks not found"
  temp=
  for _ in $(seq 6000); do
    temp=$(ls killed.ply.tmp-* 2>/dev/null | head -n 1) || true
    [ -n "$temp" ] && break
    kill -0 "$job" 2>/dev/null || break
    sleep 0.01
  done
  [ -n "$temp" ] || fail "killing rank $victim: the shared temporary file never appeared: $(cat killed.txt)"
  kill -STOP $ranks  # frozen, the file stays while the test looks
  [ -e "$temp" ] || fail "killing rank $victim: the run renamed its file before the ranks were stopped"
  rank0=${temp#killed.ply.tmp-}
  rank0=${rank0%%-*}  # the name is <path>.tmp-<pid of rank 0>-<random>
  rank1=$(printf '%s\n' "$ranks" | grep -vx "$rank0")
  if [ "$victim" = 0 ]; then
    # The ranks run in 10 ms steps until rank 1 holds the file open by its
    # name (it opens it on rank 0's word, before it writes its part, which
    # rank 0 waits for before the rename).
    opened=
    for _ in $(seq 1000); do
      ls -l "/proc/$rank1/fd" 2>/dev/null | grep -q "$temp" && { opened=1; break; }
      kill -CONT $ranks
      sleep 0.01
      kill -STOP $ranks
    done
    [ -n "$opened" ] || fail "killing rank 0: rank 1 never opened the shared file"
    kill -9 "$rank0"
    kill -CONT "$rank1"
  else
    kill -9 "$rank1"
    kill -CONT "$rank0"
  fi
  set +e
  wait "$job"
  code=$?
  set -e
  [ "$code" -ne 0 ] || fail "killing rank $victim: mpirun's exit code is 0"
  if ls killed.ply.tmp-* 2>/dev/null; then fail "killing rank $victim: the temporary file was left behind"; fi
  echo "mpi test: rank $victim killed while writing: exit $code, no temporary file left"
  rm -f killed.ply
done
rm -rf big.bricks
