// Internal: remove_small_components()' rule, one copy for the in-core
// filter (postprocess/components.cpp) and the streamed one
// (scale/stream_components.cpp), which must remove the same components and
// count them alike.
#pragma once

#include "pqdc/components.hpp"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

namespace pqdc::detail {

/// A component's bounding box, and whether a corner was not finite: NaN
/// coordinates poison the box (std::min and std::max would silently skip
/// them), so such components are kept.
struct ComponentBox {
    openvdb::Vec3d lo{std::numeric_limits<double>::infinity()}, hi{-std::numeric_limits<double>::infinity()};
    std::uint32_t non_finite = 0;

    void add(const openvdb::Vec3d& p) {
        if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) non_finite = 1;
        lo = openvdb::math::minComponent(lo, p);
        hi = openvdb::math::maxComponent(hi, p);
    }
    void add(const ComponentBox& b) {
        non_finite |= b.non_finite;
        lo = openvdb::math::minComponent(lo, b.lo);
        hi = openvdb::math::maxComponent(hi, b.hi);
    }
};

/// The decision for each component, and the counts of those decided.
struct ComponentRule {
    double voxel_size;           ///< world length of a voxel
    double min_diagonal_voxels;  ///< ComponentFilterOptions::min_diagonal_voxels
    ComponentFilterStats stats;  ///< components, removed_components and the diagonals of those decided
    bool kept_any = false;       ///< whether stats.smallest_kept_diagonal_voxels holds one

    /// Whether the component of `box` goes; counts it.
    bool remove(const ComponentBox& box) {
        ++stats.components;
        if (box.non_finite) return false;
        const double diagonal = (box.hi - box.lo).length() / voxel_size;
        if (diagonal < min_diagonal_voxels) {
            ++stats.removed_components;
            stats.largest_removed_diagonal_voxels = std::max(stats.largest_removed_diagonal_voxels, diagonal);
            return true;
        }
        if (!kept_any || diagonal < stats.smallest_kept_diagonal_voxels) stats.smallest_kept_diagonal_voxels = diagonal;
        kept_any = true;
        return false;
    }
};

}  // namespace pqdc::detail
