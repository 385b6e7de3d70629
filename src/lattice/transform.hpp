// The grid's index-to-world map, checked once for both extractors.
#pragma once

#include <openvdb/openvdb.h>

#include <string>

namespace pqdc::detail {

/// A validated similarity transform (uniform scale, rotation, translation).
/// Both extractors mesh in index space and map vertices through it at the
/// end; faces wound counter-clockwise in index space come out clockwise in
/// world space when the map is a mirror, so `mirrored` makes them flip.
struct LatticeTransform {
    const openvdb::math::Transform* transform = nullptr;
    bool mirrored = false;  ///< negative determinant: face winding must flip to stay outward
    openvdb::Vec3d to_world(const openvdb::Vec3d& index) const { return transform->indexToWorld(index); }
};

/// Throws input_error naming the grid unless the transform is a similarity.
LatticeTransform check_transform(const openvdb::math::Transform& xf, const std::string& grid_name);

}  // namespace pqdc::detail
