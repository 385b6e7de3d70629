// Adaptive stage "polygons": marching cubes on the octree's dual cells,
// sharing crossings between cells, then collapse (collapse.hpp) and repair
// (repair.hpp). See include/pqdc/adaptive.hpp, steps 3-5.
#pragma once

#include "adaptive/dual_grid.hpp"
#include "adaptive/field_probe.hpp"
#include "adaptive/octree.hpp"
#include "adaptive/untangle.hpp"
#include "lattice/resources.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/mesh.hpp"
#include "pqdc/stats.hpp"

#include <vector>

namespace pqdc::adaptive_detail {

/// Marching cubes on the dual cells; returns an index-space mesh wound
/// counter-clockwise seen from outside in index space (the caller maps points
/// to world space and flips the winding for mirrored transforms). The span
/// reports (and cancels) between its steps and between chunks of dual cells.
/// Triangles with a corner in a pinned cell, and their neighbours, are not
/// relaxed (relax.hpp) or flipped for angles (angle_flips.hpp): stage
/// "untangle" pins cells where it found intersections, and the rebuild must
/// not put them back. `shape` limits both steps.
Mesh polygonize_dual_cells(const Octree& tree, const LeafNumbering& numbering, const std::vector<DualCell>& cells,
                           const FieldSource& field, FaceType faces, const PinnedCells& pinned,
                           const ShapeLimits& shape, AdaptiveStats& stats, const detail::ProgressSpan& span);

}  // namespace pqdc::adaptive_detail
