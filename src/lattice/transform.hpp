// The grid's index-to-world map, checked once for both extractors.
#pragma once

#include <openvdb/openvdb.h>

#include <string>

namespace pqdc::detail {

/// A validated affine transform (any non-singular linear part: anisotropic
/// scale, shear, rotation, mirror, plus a translation). Both extractors mesh
/// in index space, where Hermite samples, quadrics and the vertex solve live
/// (tangent planes and their intersections are affine invariants, so sharp
/// features stay exact), and map vertices through it at the end. Faces wound
/// counter-clockwise in index space come out clockwise in world space when
/// the map is a mirror, so `mirrored` makes them flip.
struct LatticeTransform {
    const openvdb::math::Transform* transform = nullptr;
    bool mirrored = false;  ///< negative determinant: face winding must flip to stay outward
    /// Cubic voxels (a similarity map: rotation, uniform scale, mirror): the
    /// index-space field of a distance field is a distance field too.
    bool cubic = true;
    openvdb::Vec3d to_world(const openvdb::Vec3d& index) const { return transform->indexToWorld(index); }
};

/// Throws input_error naming the grid when the transform is not affine
/// (frustum and other perspective maps), is singular or has non-finite entries.
LatticeTransform check_transform(const openvdb::math::Transform& xf, const std::string& grid_name);

}  // namespace pqdc::detail
