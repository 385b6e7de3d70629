// The polygon mesh pqdc produces, in the containers OpenVDB's own
// volumeToMesh uses (Vec3 points, Vec3I triangles, Vec4I quads).
#pragma once

#include <openvdb/Types.h>

#include <cstddef>
#include <vector>

namespace pqdc {

/// Precision of stored vertex coordinates and normals (mesh writers,
/// ExtractOptions::stored_precision).
enum class VertexPrecision {
    float32,  ///< IEEE single: what vdb_tool, MeshLab and most readers take; ~1e-7 relative
    float64,  ///< IEEE double: exact copies of pqdc's double-precision points
};
/// The name before 0.1.1, kept for callers' source.
using vertex_precision [[deprecated("pqdc::vertex_precision is now pqdc::VertexPrecision")]] = VertexPrecision;

/// A shared-vertex polygon mesh in world space. Faces are wound
/// counter-clockwise seen from outside (the normal points from the inside of
/// the surface to the outside). Points are double precision so volumes far
/// from the origin keep sub-voxel accuracy.
struct Mesh {
    std::vector<openvdb::Vec3d> points;     ///< world-space vertex positions
    std::vector<openvdb::Vec3I> triangles;  ///< indices into points
    std::vector<openvdb::Vec4I> quads;      ///< indices into points
    /// Optional unit outward vertex normals, world space: empty (default) or
    /// one per point (see pqdc/vertex_normals.hpp).
    std::vector<openvdb::Vec3d> normals;

    std::size_t face_count() const { return triangles.size() + quads.size(); }
    bool empty() const { return points.empty(); }
};

}  // namespace pqdc
