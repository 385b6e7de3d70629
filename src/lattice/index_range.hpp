// The grid's index space, checked once for both extractors: every stage
// reads blocks, halos and brick margins around the active voxels, in 32-bit
// coordinates, so the voxels must keep some room from the int limits.
#pragma once

#include "pqdc/exceptions.hpp"

#include <openvdb/openvdb.h>

#include <cstdint>
#include <limits>
#include <string>

namespace pqdc::detail {

/// Index coordinates the active voxels must keep from INT_MIN and INT_MAX:
/// more than any halo, block or brick margin the stages read (at most a
/// leaf plus an 8-voxel halo, and 8^3 blocks around them).
constexpr std::int64_t kIndexRoom = 4096;

/// Throws input_error naming the grid when an active voxel lies within
/// kIndexRoom of the 32-bit index limits (the stages would wrap around: a
/// hang or a crash). Only root entries near the limits are looked at
/// closely, so ordinary grids pay nothing.
template <class TreeT>
void check_index_range(const TreeT& tree, const std::string& grid_name) {
    constexpr std::int64_t lo = std::int64_t(std::numeric_limits<std::int32_t>::min()) + kIndexRoom;
    constexpr std::int64_t hi = std::int64_t(std::numeric_limits<std::int32_t>::max()) - kIndexRoom;
    using RootChild = typename TreeT::RootNodeType::ChildNodeType;
    auto roomy = [&](const openvdb::CoordBBox& b) {
        for (int a = 0; a < 3; ++a)
            if (std::int64_t(b.min()[a]) < lo || std::int64_t(b.max()[a]) > hi) return false;
        return true;
    };
    bool near_limits = false;
    for (auto it = tree.root().cbeginChildOn(); it && !near_limits; ++it)
        near_limits = !roomy(it->getNodeBoundingBox());
    for (auto it = tree.root().cbeginValueOn(); it && !near_limits; ++it)
        near_limits = !roomy(openvdb::CoordBBox::createCube(it.getCoord(), RootChild::DIM));
    if (!near_limits) return;
    openvdb::CoordBBox active;
    if (!tree.evalActiveVoxelBoundingBox(active) || roomy(active)) return;
    auto text = [](const openvdb::Coord& c) {
        return "(" + std::to_string(c.x()) + ", " + std::to_string(c.y()) + ", " + std::to_string(c.z()) + ")";
    };
    throw input_error("grid '" + grid_name + "' has active voxels at index coordinates " + text(active.min()) +
                      " to " + text(active.max()) + ", within " + std::to_string(kIndexRoom) +
                      " of the 32-bit index limits; pqdc reads blocks around them there. Move the grid's voxels "
                      "towards the origin (copy them to shifted coordinates) and translate its transform back by "
                      "as many voxels");
}

}  // namespace pqdc::detail
