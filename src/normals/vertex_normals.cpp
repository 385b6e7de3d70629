#include "pqdc/vertex_normals.hpp"

#include "pqdc/exceptions.hpp"

#include "scale/brick_source.hpp"

#include <openvdb/math/Operators.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/parallel_sort.h>

#include <cmath>
#include <functional>
#include <limits>
#include <string>
#include <vector>

namespace pqdc {
namespace {

using openvdb::Vec3d;

/// Area-weighted face normals summed at each vertex (quads as 0-1-2, 0-2-3).
std::vector<Vec3d> face_normal_sums(const Mesh& mesh) {
    std::vector<Vec3d> sum(mesh.points.size(), Vec3d(0.0));
    auto add = [&](unsigned a, unsigned b, unsigned c) {
        const Vec3d& pa = mesh.points[a];
        const Vec3d n = (mesh.points[b] - pa).cross(mesh.points[c] - pa);  // twice the area, outward by winding
        sum[a] += n, sum[b] += n, sum[c] += n;
    };
    for (const auto& t : mesh.triangles) add(t[0], t[1], t[2]);
    for (const auto& q : mesh.quads) add(q[0], q[1], q[2]), add(q[0], q[2], q[3]);
    return sum;
}

bool finite(const Vec3d& v) { return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]); }

/// Normalizes the gradients, orients them all by the one sign under which
/// they agree best with the faces, and falls back to the faces' normal.
void finish(Mesh& mesh, std::vector<Vec3d>& gradient) {
    const std::vector<Vec3d> faces = face_normal_sums(mesh);
    double agreement = 0;  // serial sum: the sign must not depend on thread scheduling
    for (std::size_t i = 0; i < gradient.size(); ++i) {
        const double len = gradient[i].length();
        if (finite(gradient[i]) && len > 0 && std::isfinite(len)) {
            gradient[i] /= len;
            const double f = faces[i].length();
            if (f > 0) agreement += gradient[i].dot(faces[i]) / f;
        } else {
            gradient[i] = Vec3d(0.0);
        }
    }
    const double sign = agreement < 0 ? -1.0 : 1.0;
    for (std::size_t i = 0; i < gradient.size(); ++i) {
        if (gradient[i] != Vec3d(0.0)) {
            gradient[i] *= sign;
        } else {
            const double f = faces[i].length();
            gradient[i] = f > 0 && std::isfinite(f) ? faces[i] / f : Vec3d(0.0);
        }
    }
    mesh.normals = std::move(gradient);
}

/// A finite index-space position whose voxel coordinates fit an int with
/// room for the stencil (also false for NaN).
bool index_in_range(const Vec3d& x) {
    constexpr double kLimit = 1e9;
    return std::abs(x[0]) < kLimit && std::abs(x[1]) < kLimit && std::abs(x[2]) < kLimit;
}

/// The field's world-space gradient at `point`: central differences at the
/// 8 voxels around it, interpolated trilinearly, mapped as a covector.
/// Reads voxels floor(x) - 1 to floor(x) + 2 (x in index space) on each
/// axis, the box that normal_read_box() grows a node by. NaN where
/// index_in_range() fails (finish() then uses the faces' normal).
template <class AccessorT>
Vec3d gradient_at(const AccessorT& acc, const openvdb::math::Transform& xf, const Vec3d& point) {
    const Vec3d x = xf.worldToIndex(point);
    if (!index_in_range(x)) return Vec3d(std::numeric_limits<double>::quiet_NaN());
    const openvdb::Coord base(int(std::floor(x[0])), int(std::floor(x[1])), int(std::floor(x[2])));
    const Vec3d t = x - base.asVec3d();
    Vec3d g(0.0);
    for (int c = 0; c < 8; ++c) {
        const openvdb::Coord ijk = base.offsetBy(c & 1, (c >> 1) & 1, (c >> 2) & 1);
        const double w = ((c & 1) ? t[0] : 1 - t[0]) * ((c & 2) ? t[1] : 1 - t[1]) * ((c & 4) ? t[2] : 1 - t[2]);
        if (w == 0) continue;
        const auto gi = openvdb::math::ISGradient<openvdb::math::CD_2ND>::result(acc, ijk);
        g += w * Vec3d(gi[0], gi[1], gi[2]);
    }
    // A gradient is a covector: index-space to world through the inverse Jacobian transpose.
    return xf.baseMap()->applyIJT(g, x);
}

template <class GridT>
void grid_normals(Mesh& mesh, const GridT& grid) {
    const openvdb::math::Transform& xf = grid.transform();
    std::vector<Vec3d> gradient(mesh.points.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mesh.points.size(), 4096), [&](const auto& r) {
        auto acc = grid.getConstAccessor();
        for (std::size_t i = r.begin(); i != r.end(); ++i) gradient[i] = gradient_at(acc, xf, mesh.points[i]);
    });
    finish(mesh, gradient);
}

/// Vertices are grouped by the 128^3 node (an internal node of OpenVDB's
/// 5-4-3 tree) that holds floor(x) of their index-space position.
constexpr int kNodeLog2 = 7;

/// The voxels gradient_at() reads for the vertices of the node at `origin`.
openvdb::CoordBBox normal_read_box(const openvdb::Coord& origin) {
    constexpr int n = 1 << kNodeLog2;
    return openvdb::CoordBBox(origin.offsetBy(-1), origin.offsetBy(n + 1));
}

/// One group per node: the node's origin and its vertices, in vertex order.
struct NodeGroup {
    openvdb::Coord origin;
    std::vector<std::uint32_t> vertices;
};

/// Vertices for which gradient_at() reads no voxel (outside
/// index_in_range()) are in no group.
std::vector<NodeGroup> group_by_node(const Mesh& mesh, const openvdb::math::Transform& xf) {
    // (node key, vertex) pairs sorted: the groups in node order, each in vertex order.
    std::vector<std::pair<openvdb::Coord, std::uint32_t>> keyed;
    keyed.reserve(mesh.points.size());
    for (std::size_t v = 0; v < mesh.points.size(); ++v) {
        const Vec3d x = xf.worldToIndex(mesh.points[v]);
        if (!index_in_range(x)) continue;
        const openvdb::Coord base(int(std::floor(x[0])), int(std::floor(x[1])), int(std::floor(x[2])));
        keyed.emplace_back(base & ~((1 << kNodeLog2) - 1), std::uint32_t(v));
    }
    tbb::parallel_sort(keyed.begin(), keyed.end(), [](const auto& a, const auto& b) {
        return a.first < b.first || (a.first == b.first && a.second < b.second);
    });
    std::vector<NodeGroup> groups;
    for (const auto& [origin, v] : keyed) {
        if (groups.empty() || groups.back().origin != origin) groups.push_back({origin, {}});
        groups.back().vertices.push_back(v);
    }
    return groups;
}

template <class GridT>
void grid_normals_by_nodes(Mesh& mesh, const GridT& grid) {
    using TreeT = typename GridT::TreeType;
    const openvdb::math::Transform& xf = grid.transform();
    const std::vector<NodeGroup> groups = group_by_node(mesh, xf);
    // A vertex in no group keeps gradient_at()'s answer for it: none (NaN).
    std::vector<Vec3d> gradient(mesh.points.size(), Vec3d(std::numeric_limits<double>::quiet_NaN()));
    // Each group reads a copy of the voxels it needs (detail::copy_tree_box:
    // node pointers only, so a delay-loaded grid loads just the copy, which
    // is freed with the group) and gives the same values as the grid itself.
    tbb::parallel_for(std::size_t(0), groups.size(), [&](std::size_t k) {
        TreeT part(grid.tree().background());
        detail::copy_tree_box(grid.tree(), normal_read_box(groups[k].origin), part);
        openvdb::tree::ValueAccessor<const TreeT> acc(part);
        for (std::uint32_t v : groups[k].vertices) gradient[v] = gradient_at(acc, xf, mesh.points[v]);
    });
    finish(mesh, gradient);
}

/// f(the grid as a FloatGrid or DoubleGrid); input_error for other value types.
template <class F>
void with_scalar_grid(const openvdb::GridBase& grid, const F& f) {
    if (const auto* typed = dynamic_cast<const openvdb::FloatGrid*>(&grid)) return f(*typed);
    if (const auto* typed = dynamic_cast<const openvdb::DoubleGrid*>(&grid)) return f(*typed);
    throw input_error("vertex normals need a float or double grid; grid '" + grid.getName() + "' holds " +
                      grid.valueType() + " values");
}

}  // namespace

void compute_vertex_normals(Mesh& mesh, const openvdb::GridBase& grid) {
    with_scalar_grid(grid, [&](const auto& typed) { grid_normals(mesh, typed); });
}

void compute_vertex_normals_by_nodes(Mesh& mesh, const openvdb::GridBase& grid) {
    with_scalar_grid(grid, [&](const auto& typed) { grid_normals_by_nodes(mesh, typed); });
}

void compute_vertex_normals(Mesh& mesh, const ScalarField& field) {
    std::vector<Vec3d> gradient(mesh.points.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mesh.points.size(), 4096), [&](const auto& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) gradient[i] = field.gradient(mesh.points[i]);
    });
    finish(mesh, gradient);
}

}  // namespace pqdc
