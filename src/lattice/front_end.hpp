// Helpers shared by the uniform and adaptive extractors (internal).
#pragma once

#include "pqdc/extract.hpp"

#include <openvdb/openvdb.h>

#include <cstddef>
#include <string>

namespace pqdc::detail {

/// A validated similarity transform (uniform scale, rotation, translation).
struct LatticeTransform {
    const openvdb::math::Transform* transform = nullptr;
    bool mirrored = false;  ///< negative determinant: face winding must flip to stay outward
    openvdb::Vec3d to_world(const openvdb::Vec3d& index) const { return transform->indexToWorld(index); }
};

/// Throws input_error naming the grid unless the transform is a similarity.
LatticeTransform check_transform(const openvdb::math::Transform& xf, const std::string& grid_name);

/// 80% of physical memory.
std::size_t default_memory_limit();

/// Throws resource_error when `needed` bytes exceed the options' limit.
void check_memory(std::size_t needed, const ExtractOptions& options, const char* what);

}  // namespace pqdc::detail
