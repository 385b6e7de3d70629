// Internal: ExtractOptions::min_component_voxels for a mesh assembled in
// memory (every run that returns a Mesh, and the streamed runs that
// assemble). The streamed runs' counterpart is scale/stream_components.hpp.
#pragma once

#include "pqdc/components.hpp"
#include "pqdc/extract.hpp"

#include <openvdb/math/Transform.h>

#include <algorithm>

namespace pqdc::detail {

/// The length min_component_voxels counts in: the shortest voxel side, so
/// a bound holds along every axis.
inline double component_voxel_size(const openvdb::math::Transform& xf) {
    const openvdb::Vec3d v = xf.voxelSize();
    return std::min({v[0], v[1], v[2]});
}

/// Removes the small components of `mesh` when options ask for it, with
/// stats.components and the vertex and face counts updated.
inline void remove_islands(Mesh& mesh, const openvdb::math::Transform& xf, const ExtractOptions& options,
                           ExtractStats& stats) {
    if (!(options.min_component_voxels > 0)) return;
    ComponentFilterOptions filter;
    filter.min_diagonal_voxels = options.min_component_voxels;
    mesh = remove_small_components(mesh, component_voxel_size(xf), filter, &stats.components);
    stats.vertices = mesh.points.size();
    stats.triangles = mesh.triangles.size();
    stats.quads = mesh.quads.size();
}

}  // namespace pqdc::detail
