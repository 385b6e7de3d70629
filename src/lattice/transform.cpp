#include "lattice/transform.hpp"

#include "pqdc/exceptions.hpp"

#include <cmath>
#include <exception>

namespace pqdc::detail {

LatticeTransform check_transform(const openvdb::math::Transform& xf, const std::string& grid_name) {
    const auto map = xf.baseMap();
    bool similarity = map->isLinear();
    openvdb::Mat3d m;
    if (similarity) {
        try {
            const openvdb::Mat4d full = map->getAffineMap()->getMat4();
            m = full.getMat3();
            for (int i = 0; i < 4; ++i)
                for (int j = 0; j < 4; ++j)
                    if (!std::isfinite(full(i, j))) similarity = false;
        } catch (const std::exception&) {
            // OpenVDB refuses to build maps it cannot invert (tiny voxels).
            throw input_error("grid '" + grid_name + "' has a transform OpenVDB cannot invert (voxel size " +
                              std::to_string(xf.voxelSize()[0]) +
                              "); rescale the grid to a voxel size OpenVDB supports (about 1e-4 or more)");
        }
    }
    if (similarity) {
        // OpenVDB's hasUniformScale() judges det against an absolute
        // tolerance and rejects small voxels; test M^T M = s^2 I relatively.
        const openvdb::Mat3d mtm = m.transpose() * m;
        const double s2 = (mtm(0, 0) + mtm(1, 1) + mtm(2, 2)) / 3.0;
        similarity = s2 > 0 && std::isfinite(s2);
        for (int i = 0; i < 3 && similarity; ++i)
            for (int j = 0; j < 3; ++j)
                if (std::abs(mtm(i, j) - (i == j ? s2 : 0.0)) > 1e-5 * s2) similarity = false;  // OpenVDB maps carry ~1e-6 rounding
    }
    if (!similarity) {
        throw input_error("grid '" + grid_name + "' has a " + map->type() +
                          " transform with non-uniform scale, shear, perspective or non-finite entries; pqdc needs cubic voxels "
                          "(resample the grid, e.g. with openvdb::tools::resampleToMatch)");
    }
    LatticeTransform t;
    t.transform = &xf;
    t.mirrored = m.det() < 0;
    return t;
}

}  // namespace pqdc::detail
