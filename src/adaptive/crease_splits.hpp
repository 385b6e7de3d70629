// Adaptive stage "polygons": the vertices of concave creases that the dual
// marching cubes loops skip, put back by edge splits.
#pragma once

#include "adaptive/field_probe.hpp"

#include <openvdb/openvdb.h>

#include <cstdint>
#include <vector>

namespace pqdc::adaptive_detail {

/// How far, in voxels, the field's mean on a sphere of one voxel around p
/// lies below its value at p (first order: divided by the gradient's
/// length). About 0.3 on a 90-degree concave crease of a distance field
/// (a min of the faces' distances), 0 on a plane, negative where convex.
double concavity(FieldProbe& probe, const openvdb::Vec3d& p);

/// Splits, for each point of `hidden` in order, the mesh edge it was cut
/// off from: the edge within reach whose midpoint lies farthest outside the
/// surface (more than 0.1 voxel) and which passes beside the point, when the
/// four new triangles face as the two old ones did and cross no triangle
/// with a corner in the 27 voxels around; then flips the edges around the
/// new vertices that still cut through the outside. The point becomes a new
/// vertex (appended to `points`); the two triangles are rewritten and two
/// appended (to `tris`, `alive`, and `changed`, which marks all four, so
/// that no quad is joined across them). Each triangle is split at most once
/// per pass; two passes. Sequential, in the order given. Returns the splits.
std::size_t split_at_concave_creases(const std::vector<openvdb::Vec3d>& hidden, FieldProbe& probe,
                                     std::vector<openvdb::Vec3d>& points, std::vector<openvdb::Vec3I>& tris,
                                     std::vector<std::uint8_t>& alive, std::vector<std::uint8_t>& changed);

}  // namespace pqdc::adaptive_detail
