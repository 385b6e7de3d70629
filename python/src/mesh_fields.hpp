// Per-vertex field samples the Python Mesh exposes: the outward unit normal
// from the field's gradient and the field value, both sampled from the grid
// the mesh came from.
#pragma once

#include <pqdc/mesh.hpp>

#include <openvdb/openvdb.h>

#include <functional>
#include <vector>

namespace pqdc::python {

struct VertexFields {
    std::vector<openvdb::Vec3d> normals;  ///< unit, outward; zero where the gradient vanishes or is not finite
    std::vector<double> values;           ///< trilinear interpolation of the grid values
};

/// Samples a float or double grid at `index_points` (index space). The
/// gradient is the trilinear interpolation of the corners' central
/// differences (one-sided next to a non-finite neighbour), multiplied by
/// `outward_sign` (+1 when inside is below the isovalue, -1 above) and mapped
/// to world space as a covector: by `index_to_world_covector` (the inverse
/// transpose of the index-to-world linear map), then normalized. progress is
/// called between chunks (cancellation point; false throws cancelled_error).
VertexFields sample_vertex_fields(const openvdb::GridBase& grid, const std::vector<openvdb::Vec3d>& index_points,
                                  double outward_sign, const openvdb::Mat3d& index_to_world_covector,
                                  const std::function<bool(double)>& progress);

}  // namespace pqdc::python
