// Adaptive stage "polygons", steps 1-1b: the side of every octree leaf
// for dual marching cubes (polygonize.cpp), with the vertex each leaf
// gives the dual cells.
#pragma once

#include "adaptive/dual_grid.hpp"
#include "adaptive/field_probe.hpp"
#include "adaptive/octree.hpp"
#include "lattice/resources.hpp"
#include "pqdc/stats.hpp"

#include <openvdb/openvdb.h>

#include <cstdint>
#include <vector>

namespace pqdc::adaptive_detail {

/// Every numbered leaf: its vertex (index space), the field there (empty
/// leaves) and its side.
struct LeafVertices {
    std::vector<openvdb::Vec3d> position;
    std::vector<double> value;
    std::vector<std::uint8_t> is_surface;
    std::vector<std::uint8_t> inside;
};

/// Every numbered leaf's vertex, field value and side: surface leaves
/// inside, empty ones by the field (step 1), those without a value by the
/// empty leaves they touch (step 1a), outside pockets walled in by surface
/// leaves filled (step 1b). Sets stats.surface_leaves, empty_leaves,
/// leaves_per_level, undefined_leaves_inside and filled_pockets.
LeafVertices leaf_sides(const Octree& tree, const LeafNumbering& numbering, const std::vector<DualCell>& cells,
                        const FieldSource& field, AdaptiveStats& stats, const detail::ProgressSpan& span);

}  // namespace pqdc::adaptive_detail
