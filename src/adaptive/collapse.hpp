// Adaptive stage "collapse": crossings that the polygons placed on the same
// surface vertex are merged by edge collapses that keep the mesh a closed,
// edge-manifold, consistently oriented surface (the link condition).
#pragma once

#include "lattice/resources.hpp"

#include <openvdb/openvdb.h>

#include <cstdint>
#include <limits>
#include <vector>

namespace pqdc::adaptive_detail {

/// No octree root: a vertex of no surface leaf.
constexpr std::uint64_t kNoTile = std::numeric_limits<std::uint64_t>::max();

/// Collapses edges whose end points coincide exactly, in a fixed order,
/// whenever the link condition holds (the common neighbours of the two end
/// points are exactly the two vertices opposite the edge). rep maps every
/// vertex to its survivor; alive marks the triangles that remain.
///
/// tile[v] names the octree root holding vertex v's surface leaf (kNoTile
/// for vertices of no leaf). A collapse reads and writes only triangles
/// around its two vertices, and a triangle joins leaves around one octree
/// corner, so two roots that are not neighbours never touch the same
/// triangle: the roots of one coordinate-parity class are processed in
/// parallel, the eight classes one after another; edges between tiles come
/// last, in one sequential sweep over all edges. The result depends on the
/// tiles, not on the threads. The span reports (and cancels) between the
/// steps, the parity classes and chunks of the sweep.
void collapse_coincident_vertices(const std::vector<openvdb::Vec3d>& points, const std::vector<std::uint64_t>& tile,
                                  std::vector<openvdb::Vec3I>& tris, std::vector<std::uint32_t>& rep,
                                  std::vector<std::uint8_t>& alive, const detail::ProgressSpan& span);

}  // namespace pqdc::adaptive_detail
