// Adaptive stage "untangle": the output never contains two faces that
// intersect other than along a shared edge or vertex.
//
// The uniform stage (lattice/untangle.hpp) moves offending vertices towards
// safe positions: cell centers. Moving a merged leaf's vertex towards its
// center would break the octree's error bound (a 16-voxel leaf's center can
// be 8 voxels off the surface), so the adaptive stage works in three steps:
//  1. Refine. The mesh is checked exactly (find_self_intersections, at the
//     stored precision). The finest cells within one voxel of every corner
//     of an offending triangle are pinned, and the octree is built again
//     with no merged leaf containing a pinned cell. Repeated while it pins
//     something new: the pinned set only grows and is finite, and a round
//     that pins nothing new would rebuild the same octree, so this ends
//     (in practice after one or two rebuilds). Where nothing is merged the
//     mesh is dual marching cubes on the lattice.
//  2. Move. What is left has its corners in finest leaves, and those may
//     move as in uniform mode: lattice/untangle.hpp's loop, with the safe
//     position of a vertex in a pinned finest cell the cell's center and
//     every other vertex fixed. The loop ends either free of
//     self-intersections or with offending pairs whose corners are all safe.
//  3. Fall back. That the mesh with every pinned vertex at its center is
//     free of self-intersections is observed (the suites of bench_quality
//     and the property tests), not proven for the octree's polygons (added
//     centroid vertices, separated coincident vertices). When step 2 ends
//     unresolved the driver returns the uniform extractor's mesh, whose
//     safe positions are proven (uniform/safe_positions.hpp), and says so in
//     AdaptiveStats::untangle_fallback and a warning.
#pragma once

#include "adaptive/shape_limits.hpp"
#include "adaptive/octree.hpp"
#include "lattice/resources.hpp"
#include "lattice/transform.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/mesh.hpp"
#include "pqdc/stats.hpp"

#include <openvdb/openvdb.h>

#include <cstdint>
#include <functional>
#include <vector>

namespace pqdc::adaptive_detail {

/// Finest cells no merged leaf may contain (step 1).
class PinnedCells {
public:
    /// Whether the node `code` of `level` contains a pinned finest cell
    /// (its finest descendants are one run of Morton codes).
    bool covers(int level, std::uint64_t code) const;
    /// Whether the finest cell with this index-space origin is pinned.
    bool pinned(const Octree& frame, const openvdb::Coord& cell) const;

    /// Pins the finest cells within one voxel of every index-space point in
    /// `corners`; returns how many were not pinned before.
    std::size_t pin_around(const Octree& frame, const std::vector<openvdb::Vec3d>& corners);

    std::size_t size() const { return codes_.size(); }

private:
    std::vector<std::uint64_t> codes_;  ///< sorted, unique Morton codes of finest cells
};

/// Step 2's safe positions, world space: the center of the pinned finest
/// cell holding the vertex (index_points: `mesh`'s vertices in index space),
/// pulled half way towards its neighbours' mean where several vertices share
/// the cell; the vertex itself where the cell is not pinned.
std::vector<openvdb::Vec3d> pinned_safe_positions(const Octree& frame, const PinnedCells& pinned,
                                                  const std::vector<openvdb::Vec3d>& index_points, const Mesh& mesh,
                                                  const detail::LatticeTransform& xf);

/// The index-space mesh of the octree built with these cells pinned
/// (stages "hermite" to "polygons") and these angle-flip limits, reporting
/// in the span. It sets the stats it is given to what the driver had before
/// the first build plus this build's counters.
using Rebuild =
    std::function<Mesh(const PinnedCells&, const ShapeLimits&, const detail::ProgressSpan&, AdaptiveStats&)>;
/// `stats` after a rebuild (stage "bridges" or "untangle") whose own
/// counters are `round`: the build's counters replace the last build's; the
/// stages and the counters of stages "bridges" and "untangle" carry over.
void take_rebuild_counters(AdaptiveStats round, AdaptiveStats& stats);

/// The uniform extractor's world-space mesh of the same input (step 3),
/// reporting progress from the given fraction to 1.
using UniformFallback = std::function<Mesh(ExtractStats&, double)>;

/// Stage "untangle": maps the index-space `mesh` (built with `pinned`, stage
/// "bridges"' cells, which every rebuild keeps) to world space and returns it free of self-intersections at
/// options.stored_precision, by steps 1-3. Before step 3, a mesh with angle
/// flips gets one more try without them (rebuild and step 2): the moves of
/// step 2 were designed for the marching-cubes triangles. `frame` is the octree's empty
/// frame (codes and origin). Fills stats.untangle_*; a rebuild's counters
/// replace the first build's, stages are kept. Progress: the check from
/// 0.85 to 0.95, rebuilds after.
Mesh untangle_adaptive(Mesh mesh, const Rebuild& rebuild, const detail::LatticeTransform& xf, const Octree& frame,
                       const ExtractOptions& options, const PinnedCells& pinned, const UniformFallback& fallback,
                       const detail::Progress& progress, AdaptiveStats& stats);

}  // namespace pqdc::adaptive_detail
