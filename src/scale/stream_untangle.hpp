// Stage "untangle" of a streamed run (issue 14, phases 2 and 3), with the in-core
// stage's result (lattice/untangle.hpp) but without the whole mesh.
//
// Why a part of the mesh is enough. The in-core stage repeats: find every
// intersecting pair and degenerate triangle at the current positions; stop
// if there is none; move the corners of each one step towards their safe
// positions. After the first round, a pair that intersects has a corner
// that moved in the round before (a pair of unmoved corners was found
// before and had its corners moved, or has them all snapped, and then
// cannot intersect). A vertex lies within D (max norm, index space) of its
// cell's center, and two triangles that meet, one with a corner in cell c,
// have all their corners within 2 + 2D cells of c. So with every moved
// vertex within R - (3 + 2D) cells of a first-round corner (a seed), the
// run on the faces with a corner within R of a seed finds, round after
// round, exactly the pairs the in-core run finds, and moves the same
// vertices the same way. The stage runs there, checks that premise
// afterwards, and doubles R until it holds (the whole mesh at the latest).
#pragma once

#include "lattice/untangle.hpp"
#include "pqdc/distributed.hpp"
#include "pqdc/extract.hpp"
#include "scale/stream_scratch.hpp"

#include <openvdb/openvdb.h>

#include <cstdint>
#include <utility>
#include <vector>

namespace pqdc::detail {

/// A vertex the untangle stage moved: its global index and new position.
using MovedVertex = std::pair<std::uint64_t, openvdb::Vec3d>;

/// Collective over `group`: the untangle stage over the mesh in the ranks'
/// scratch files (this rank's in `scratch`), whose first-round offending
/// corners are `seeds` (every rank's, global, sorted, unique), whose
/// `vertices` (every rank's) lie within `max_offset` (< 1.5) of their
/// cells' centers. Each rank sends rank 0 its share of the part near the
/// seeds; rank 0 repairs the part and every rank gets the result: the moved
/// vertices in index order. Adds the stage's counters to `counters`.
/// `xf`: the mesh's (safe positions, lattice spacing); `settings` as for
/// untangle(); the part of the mesh is checked against the memory limit of
/// `limits`. `first_reach` (cells; 0: 2 (3 + 2 max_offset)) is for tests:
/// a small one makes the stage double it.
std::vector<MovedVertex> untangle_streamed(StreamScratch& scratch, const std::vector<std::uint64_t>& seeds,
                                           double max_offset, std::uint64_t vertices, const LatticeTransform& xf,
                                           const UntangleSettings& settings, const ExtractOptions& limits,
                                           UntangleCounters& counters, RankGroup& group, int first_reach = 0);

/// Largest max_offset untangle_streamed() accepts: the brick halo of one
/// leaf (8 cells) must hold every triangle that meets a brick's own ones.
constexpr double kStreamMaxOffset = 1.5;

}  // namespace pqdc::detail
