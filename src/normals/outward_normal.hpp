// Internal: one vertex's outward normal from the field's values, for
// pqdc::compute_vertex_normals and the streamed runs' pieces
// (ExtractOptions::vertex_normals), which must agree bit for bit. Any
// accessor with getValue(Coord) will do: a grid's, a copied node's, or
// the leaf-by-leaf reader of a brick source (bricks/source_values.hpp).
#pragma once

#include "pqdc/vertex_normals.hpp"

#include <openvdb/math/Operators.h>
#include <openvdb/math/Transform.h>
#include <openvdb/openvdb.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace pqdc::detail {

/// A finite index-space position whose voxel coordinates fit an int with
/// room for the stencil (also false for NaN).
inline bool index_in_range(const openvdb::Vec3d& x) {
    constexpr double kLimit = 1e9;
    return std::abs(x[0]) < kLimit && std::abs(x[1]) < kLimit && std::abs(x[2]) < kLimit;
}

/// The voxel at the minimum corner of the cell holding index-space `x`.
inline openvdb::Coord cell_base(const openvdb::Vec3d& x) {
    return openvdb::Coord(int(std::floor(x[0])), int(std::floor(x[1])), int(std::floor(x[2])));
}

/// The values of the 4^3 voxels from `min` on, x-major (index 16 x + 4 y + z).
/// Readers with a faster way (bricks/source_values.hpp) overload it.
template <class AccessorT>
void read_block4(const AccessorT& acc, const openvdb::Coord& min, typename AccessorT::ValueType* out) {
    for (int x = 0; x < 4; ++x)
        for (int y = 0; y < 4; ++y)
            for (int z = 0; z < 4; ++z) *out++ = acc.getValue(min.offsetBy(x, y, z));
}

/// The 4^3 voxels around the cell holding an index-space point:
/// cell_base(x) - 1 to + 2, everything the gradients below read.
template <class ValueT>
struct Block4 {
    ValueT v[64];
    const ValueT& at(int x, int y, int z) const { return v[16 * x + 4 * y + z]; }
};

/// Index-space gradient at `x` (t: x - cell_base(x)): central differences
/// at the 8 voxels around it (OpenVDB's ISGradient<CD_2ND>, in the value
/// type), interpolated trilinearly.
template <class ValueT>
openvdb::Vec3d central_gradient(const Block4<ValueT>& b, const openvdb::Vec3d& t) {
    using D = openvdb::math::D1<openvdb::math::CD_2ND>;
    openvdb::Vec3d g(0.0);
    for (int c = 0; c < 8; ++c) {
        const int i = 1 + (c & 1), j = 1 + ((c >> 1) & 1), k = 1 + ((c >> 2) & 1);
        const double w = ((c & 1) ? t[0] : 1 - t[0]) * ((c & 2) ? t[1] : 1 - t[1]) * ((c & 4) ? t[2] : 1 - t[2]);
        if (w == 0) continue;
        const openvdb::math::Vec3<ValueT> gi(D::difference(b.at(i + 1, j, k), b.at(i - 1, j, k)),
                                             D::difference(b.at(i, j + 1, k), b.at(i, j - 1, k)),
                                             D::difference(b.at(i, j, k + 1), b.at(i, j, k - 1)));
        g += w * openvdb::Vec3d(gi[0], gi[1], gi[2]);
    }
    return g;
}

/// Index-space gradient at `x` (t as above) of the trilinear interpolant of
/// the 8 voxels around it: needs only those 8 values, so it stands in for
/// central_gradient() next to NaN values the differences would reach.
template <class ValueT>
openvdb::Vec3d cell_gradient(const Block4<ValueT>& b, const openvdb::Vec3d& t) {
    openvdb::Vec3d g(0.0);
    for (int axis = 0; axis < 3; ++axis) {
        const int bit = 1 << axis;
        for (int c = 0; c < 8; ++c) {
            if (c & bit) continue;
            double w = 1.0;  // the weight of this edge along the other two axes
            for (int other = 0; other < 3; ++other)
                if (other != axis) w *= (c & (1 << other)) ? t[other] : 1 - t[other];
            const int d = c | bit;
            g[axis] += w * (double(b.at(1 + (d & 1), 1 + ((d >> 1) & 1), 1 + ((d >> 2) & 1))) -
                            double(b.at(1 + (c & 1), 1 + ((c >> 1) & 1), 1 + ((c >> 2) & 1))));
        }
    }
    return g;
}

/// Infinite values replaced by finite ones beyond the block's finite range,
/// so that the gradients next to them (the mesh's vertices there) point
/// away from -inf and towards +inf, as the crossings' limit does.
template <class ValueT>
void finite_stand_ins(Block4<ValueT>& b) {
    double range = 0;
    bool any = false;
    for (const ValueT& v : b.v) {
        if (std::isinf(double(v))) any = true;
        else if (std::isfinite(double(v))) range = std::max(range, std::abs(double(v)));
    }
    if (!any) return;
    const ValueT far = ValueT(std::min(4 * range + 1, 1e30));
    for (ValueT& v : b.v)
        if (std::isinf(double(v))) v = v < 0 ? -far : far;
}

/// `g` (index space at `x`) mapped to world space as a covector and made
/// unit length; false when that is not possible (zero, not finite).
inline bool unit_world_normal(const openvdb::math::Transform& xf, const openvdb::Vec3d& x, openvdb::Vec3d g,
                              openvdb::Vec3d& out) {
    // A gradient is a covector: index-space to world through the inverse Jacobian transpose.
    g = xf.baseMap()->applyIJT(g, x);
    const double len = g.length();
    if (!(std::isfinite(g[0]) && std::isfinite(g[1]) && std::isfinite(g[2])) || !(len > 0) || !std::isfinite(len))
        return false;
    out = g / len;
    return true;
}

/// The unit world-space normal at world `point`, pointing to where the
/// field grows when `outward` > 0 (inside below the isovalue), to where it
/// falls otherwise: the central gradient, else the cell's, else (0, 0, 0).
template <class AccessorT>
openvdb::Vec3d outward_normal(const AccessorT& acc, const openvdb::math::Transform& xf, double outward,
                              const openvdb::Vec3d& point) {
    const openvdb::Vec3d x = xf.worldToIndex(point);
    if (!index_in_range(x)) return openvdb::Vec3d(0.0);
    const openvdb::Coord base = cell_base(x);
    const openvdb::Vec3d t = x - base.asVec3d();
    Block4<typename AccessorT::ValueType> b;
    read_block4(acc, base.offsetBy(-1), b.v);
    finite_stand_ins(b);
    openvdb::Vec3d n;
    if (!unit_world_normal(xf, x, central_gradient(b, t), n) && !unit_world_normal(xf, x, cell_gradient(b, t), n))
        return openvdb::Vec3d(0.0);
    return outward < 0 ? -n : n;
}

/// outward_normal() at every point, read through values.getConstAccessor()
/// (a grid, or bricks/source_values.hpp) on each thread.
template <class Values>
std::vector<openvdb::Vec3d> outward_normals(const Values& values, const openvdb::math::Transform& xf, double outward,
                                            const std::vector<openvdb::Vec3d>& points) {
    std::vector<openvdb::Vec3d> out(points.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points.size(), 4096), [&](const auto& r) {
        const auto acc = values.getConstAccessor();
        for (std::size_t i = r.begin(); i != r.end(); ++i) out[i] = outward_normal(acc, xf, outward, points[i]);
    });
    return out;
}

/// ExtractOptions::vertex_normals for a mesh assembled in memory:
/// `by_nodes` when the grid may be delay-loaded (a run by bricks), whose
/// accessors would load every leaf they touch.
inline void add_vertex_normals(Mesh& mesh, const openvdb::GridBase& grid, Interior inside, bool by_nodes) {
    if (by_nodes) compute_vertex_normals_by_nodes(mesh, grid, inside);
    else compute_vertex_normals(mesh, grid, inside);
}

}  // namespace pqdc::detail
