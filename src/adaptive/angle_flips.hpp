// Adaptive stage "polygons", last step: edge flips for fatter triangles,
// and for folds.
#pragma once

#include "adaptive/field_probe.hpp"

#include <openvdb/openvdb.h>

#include <cstdint>
#include <vector>

namespace pqdc::adaptive_detail {

/// Limits of flip_for_angles. The defaults were chosen on bench_quality's
/// suite (see the .cpp).
struct AngleFlipLimits {
    /// A pair of triangles is flipped only when their normals, and the new
    /// pair's, differ by at most this (degrees, (0, 90)): flat enough that
    /// the flip moves the surface by a small fraction of the pair's size and
    /// never across a crease.
    double max_fold_degrees = 30;
    /// Sweeps over all edges (>= 1); each flip strictly raises the smallest
    /// angle of its pair, so sweeps stop by themselves, this only bounds them.
    int max_sweeps = 8;
};

/// Flips the shared edge of two alive triangles (a, b, c) and (b, a, d) to
/// (c, a, d) and (d, b, c) when that raises the pair's smallest angle, the
/// pair is nearly flat (AngleFlipLimits), the new edge c-d does not exist
/// yet (manifold) and neither triangle is `frozen` (quads to be joined).
/// Dual marching cubes on an octree makes slivers where cells of different
/// sizes meet; the vertices do not move. With a `field` (the signed field,
/// index space as `points`; null: none) it also unfolds: a pair that is
/// not flat flips when the new pair is flat and follows the field's
/// gradient better (its worse face normal closer to it than the old
/// pair's worse one).
/// Sweeps visit the triangles in index order, so the result does not depend
/// on threads. Flipped triangles are marked in `changed` (sized like tris).
/// Returns the number of flips.
std::size_t flip_for_angles(const std::vector<openvdb::Vec3d>& points, std::vector<openvdb::Vec3I>& tris,
                            const std::vector<std::uint8_t>& alive, const std::vector<std::uint8_t>& frozen,
                            std::vector<std::uint8_t>& changed, FieldProbe* field, const AngleFlipLimits& limits = {});

}  // namespace pqdc::adaptive_detail
