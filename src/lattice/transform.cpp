#include "lattice/transform.hpp"

#include "pqdc/exceptions.hpp"

#include <cmath>
#include <exception>

namespace pqdc::detail {

LatticeTransform check_transform(const openvdb::math::Transform& xf, const std::string& grid_name) {
    const auto map = xf.baseMap();
    const std::string grid = "grid '" + grid_name + "'";
    if (!map->isLinear())
        throw input_error(grid + " has a " + map->type() +
                          " transform, which is not affine (voxels change size or shape across the grid, as in a "
                          "camera frustum); pqdc meshes grids with an affine voxel-to-world map (any scale, shear, "
                          "rotation or mirror). Resample the grid to a linear transform, e.g. with "
                          "openvdb::tools::resampleToMatch");
    openvdb::Mat4d full;
    try {
        full = map->getAffineMap()->getMat4();
    } catch (const std::exception&) {
        // OpenVDB refuses to build maps it cannot invert (tiny or flat voxels).
        const openvdb::Vec3d v = xf.voxelSize();
        throw input_error(grid + " has a transform OpenVDB cannot invert (voxel size " + std::to_string(v[0]) +
                          " x " + std::to_string(v[1]) + " x " + std::to_string(v[2]) +
                          "); rescale the grid to a voxel size OpenVDB supports (about 1e-4 or more along every axis)");
    }
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
            if (!std::isfinite(full(i, j)))
                throw input_error(grid + " has a " + map->type() +
                                  " transform with non-finite entries (NaN or infinity); the file's transform is "
                                  "damaged: rewrite the grid with a valid voxel size");
    const openvdb::Mat3d m = full.getMat3();
    // Singular relative to the voxel's edge lengths (Hadamard's bound), not
    // an absolute tolerance: small voxels are fine, flat ones are not.
    const double edges = m.row(0).length() * m.row(1).length() * m.row(2).length();
    const double det = m.det();
    if (!(edges > 0) || !(std::abs(det) > 1e-12 * edges))
        throw input_error(grid + " has a singular " + map->type() +
                          " transform (its voxels have no volume: two axes are parallel or one has zero length); "
                          "fix the grid's transform");
    LatticeTransform t;
    t.transform = &xf;
    t.mirrored = det < 0;
    // M M^T = s^2 I up to rounding (rows of OpenVDB's row-vector matrix).
    const double s2 = std::cbrt(det * det);
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            if (std::abs(m.row(i).dot(m.row(j)) - (i == j ? s2 : 0.0)) > 1e-9 * s2) t.cubic = false;
    return t;
}

}  // namespace pqdc::detail
