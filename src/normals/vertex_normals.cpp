#include "pqdc/vertex_normals.hpp"

#include "pqdc/exceptions.hpp"

#include "normals/outward_normal.hpp"
#include "bricks/brick_source.hpp"
#include "measure/mesh_internal.hpp"

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

/// The field's world-space gradient at `point` (detail::central_gradient
/// mapped as a covector); NaN outside detail::index_in_range() (finish()
/// then uses the faces' normal).
template <class AccessorT>
Vec3d gradient_at(const AccessorT& acc, const openvdb::math::Transform& xf, const Vec3d& point) {
    const Vec3d x = xf.worldToIndex(point);
    if (!detail::index_in_range(x)) return Vec3d(std::numeric_limits<double>::quiet_NaN());
    const openvdb::Coord base = detail::cell_base(x);
    detail::Block4<typename AccessorT::ValueType> b;
    detail::read_block4(acc, base.offsetBy(-1), b.v);
    // A gradient is a covector: index-space to world through the inverse Jacobian transpose.
    return xf.baseMap()->applyIJT(detail::central_gradient(b, x - base.asVec3d()), x);
}

/// f(accessor, point) at every vertex, read through the grid's accessors.
template <class GridT, class PerVertex>
std::vector<Vec3d> at_vertices(const Mesh& mesh, const GridT& grid, const PerVertex& f) {
    std::vector<Vec3d> out(mesh.points.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mesh.points.size(), 4096), [&](const auto& r) {
        auto acc = grid.getConstAccessor();
        for (std::size_t i = r.begin(); i != r.end(); ++i) out[i] = f(acc, mesh.points[i]);
    });
    return out;
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
        if (!detail::index_in_range(x)) continue;
        keyed.emplace_back(detail::cell_base(x) & ~((1 << kNodeLog2) - 1), std::uint32_t(v));
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

/// at_vertices(), bit for bit, reading the grid node by node; `none` for
/// the vertices in no group.
template <class GridT, class PerVertex>
std::vector<Vec3d> at_vertices_by_nodes(const Mesh& mesh, const GridT& grid, const PerVertex& f, const Vec3d& none) {
    using TreeT = typename GridT::TreeType;
    const std::vector<NodeGroup> groups = group_by_node(mesh, grid.transform());
    std::vector<Vec3d> out(mesh.points.size(), none);
    // Each group reads a copy of the voxels it needs (detail::copy_tree_box:
    // node pointers only, so a delay-loaded grid loads just the copy, which
    // is freed with the group) and gives the same values as the grid itself.
    tbb::parallel_for(std::size_t(0), groups.size(), [&](std::size_t k) {
        TreeT part(grid.tree().background());
        detail::copy_tree_box(grid.tree(), normal_read_box(groups[k].origin), part);
        openvdb::tree::ValueAccessor<const TreeT> acc(part);
        for (std::uint32_t v : groups[k].vertices) out[v] = f(acc, mesh.points[v]);
    });
    return out;
}

/// The central gradient at each vertex, for finish().
template <class GridT>
auto gradient_of(const GridT& grid) {
    return [&grid](const auto& acc, const Vec3d& p) { return gradient_at(acc, grid.transform(), p); };
}

/// +1 when the field grows outward (inside below the isovalue), -1 otherwise.
double outward_sign(Interior inside) {
    if (inside == Interior::automatic)
        throw option_error("compute_vertex_normals: the interior must be below_isovalue or above_isovalue, "
                           "not automatic (ExtractStats::interior says which one a run chose)");
    return inside == Interior::below_isovalue ? 1.0 : -1.0;
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

// The overloads that orient by the faces check their indices first
// (input_error, as every function taking a mesh), before any gradient is sampled.
void compute_vertex_normals(Mesh& mesh, const openvdb::GridBase& grid) {
    detail::check_indices(mesh);
    with_scalar_grid(grid, [&](const auto& typed) {
        std::vector<Vec3d> gradient = at_vertices(mesh, typed, gradient_of(typed));
        finish(mesh, gradient);
    });
}

void compute_vertex_normals_by_nodes(Mesh& mesh, const openvdb::GridBase& grid) {
    detail::check_indices(mesh);
    // A vertex in no group keeps gradient_at()'s answer for it: none (NaN).
    const Vec3d none(std::numeric_limits<double>::quiet_NaN());
    with_scalar_grid(grid, [&](const auto& typed) {
        std::vector<Vec3d> gradient = at_vertices_by_nodes(mesh, typed, gradient_of(typed), none);
        finish(mesh, gradient);
    });
}

void compute_vertex_normals(Mesh& mesh, const openvdb::GridBase& grid, Interior inside) {
    const double outward = outward_sign(inside);
    with_scalar_grid(grid, [&](const auto& typed) {
        mesh.normals = detail::outward_normals(typed, typed.transform(), outward, mesh.points);
    });
}

void compute_vertex_normals_by_nodes(Mesh& mesh, const openvdb::GridBase& grid, Interior inside) {
    const double outward = outward_sign(inside);
    with_scalar_grid(grid, [&](const auto& typed) {
        const auto normal = [&](const auto& acc, const Vec3d& p) {
            return detail::outward_normal(acc, typed.transform(), outward, p);
        };
        mesh.normals = at_vertices_by_nodes(mesh, typed, normal, Vec3d(0.0));
    });
}

void compute_outward_vertex_normals(Mesh& mesh, const ScalarField& field) {
    std::vector<Vec3d> n(mesh.points.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mesh.points.size(), 4096), [&](const auto& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            const Vec3d g = field.gradient(mesh.points[i]);
            const double len = g.length();
            n[i] = finite(g) && len > 0 && std::isfinite(len) ? g / len : Vec3d(0.0);
        }
    });
    mesh.normals = std::move(n);
}

void compute_vertex_normals(Mesh& mesh, const ScalarField& field) {
    detail::check_indices(mesh);
    std::vector<Vec3d> gradient(mesh.points.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mesh.points.size(), 4096), [&](const auto& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) gradient[i] = field.gradient(mesh.points[i]);
    });
    finish(mesh, gradient);
}

}  // namespace pqdc
