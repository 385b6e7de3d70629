// Exact distances from points to a reference mesh's triangles and quads
// (MeshDistance: a bounding-box tree pruned only by boxes farther than the
// best triangle found, signed by angle-weighted pseudo-normals).
#include "pqdc/measure.hpp"

#include "measure/closest_point.hpp"
#include "measure/measure_common.hpp"
#include "pqdc/exceptions.hpp"

#include <tbb/combinable.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <string>
#include <utility>
#include <vector>

namespace pqdc {

using namespace measure_detail;
using namespace closest_point;

namespace {

// ---- distance to a reference mesh ----

void validate(const MeshDistanceOptions& options) {
    if (options.leaf_triangles < 1 || options.leaf_triangles > 64)
        throw option_error("MeshDistanceOptions::leaf_triangles = " + std::to_string(options.leaf_triangles) +
                           " is outside [1, 64]");
}

/// Squared distance from p to the box, 0 inside.
double box_distance2(const BoxNode& node, const Vec3d& p) {
    double d2 = 0.0;
    for (int k = 0; k < 3; ++k) {
        const double d = std::max({node.lo[k] - p[k], 0.0, p[k] - node.hi[k]});
        d2 += d * d;
    }
    return d2;
}

struct ReferenceTriangle {
    Vec3d a, b, c;
    std::uint32_t id;  // index into the pseudo-normal tables (quads split in place)
    bool thin;         // see is_thin
};


}  // namespace

// ---- MeshDistance ----

struct MeshDistance::Impl {
    std::vector<BoxNode> nodes;               // nodes[0] is the root
    std::vector<ReferenceTriangle> triangles;  // in leaf order
    // Pseudo-normals, unnormalized (only their direction is used).
    std::vector<Vec3d> vertex_normals;                  // by reference point
    std::vector<Vec3d> edge_normals;                    // by undirected edge
    std::vector<std::array<std::uint32_t, 3>> corners;  // by triangle id: points a, b, c
    std::vector<std::array<std::uint32_t, 3>> edges;    // by triangle id: edges ab, bc, ca
    double coordinate_scale = 0;                        // largest |coordinate| of a triangle corner

    struct Nearest {
        double distance2 = std::numeric_limits<double>::infinity();
        const ReferenceTriangle* triangle = nullptr;
        ClosestPoint closest{};
    };

    Nearest nearest(const Vec3d& p) const {
        Nearest best;
        // A box is skipped only when it is farther than the best triangle by
        // more than rounding of either distance could explain, so the result
        // is the minimum of the computed distances over all triangles (the
        // same number a brute-force loop gives), whatever the tree's shape.
        const double slack = 1e-12 * (coordinate_scale + std::max({std::abs(p[0]), std::abs(p[1]), std::abs(p[2])}));
        double skip_above = std::numeric_limits<double>::infinity();
        struct Pending {
            std::uint32_t node;
            double distance2;
        };
        // Depth is at most 33 for 2^32 triangles; each level leaves at most one sibling pending.
        std::array<Pending, 64> stack;
        int top = 0;
        stack[top++] = {0, box_distance2(nodes[0], p)};
        while (top > 0) {
            const Pending current = stack[--top];
            if (current.distance2 > skip_above) continue;
            const BoxNode& node = nodes[current.node];
            if (node.triangle_count > 0) {
                const std::uint32_t first = node.second_child_or_first_triangle;
                for (std::uint32_t i = first; i < first + node.triangle_count; ++i) {
                    const ReferenceTriangle& t = triangles[i];
                    const ClosestPoint q =
                        t.thin ? closest_on_thin_triangle(p, t.a, t.b, t.c) : closest_on_triangle(p, t.a, t.b, t.c);
                    const double d2 = (q.point - p).lengthSqr();
                    if (d2 < best.distance2 || !best.triangle) {
                        best = {d2, &t, q};
                        const double r = std::sqrt(d2) * (1.0 + 1e-12) + slack;
                        skip_above = r * r;
                    }
                }
                continue;
            }
            Pending near{current.node + 1, 0.0}, far{node.second_child_or_first_triangle, 0.0};
            near.distance2 = box_distance2(nodes[near.node], p);
            far.distance2 = box_distance2(nodes[far.node], p);
            if (far.distance2 < near.distance2) std::swap(near, far);
            if (far.distance2 <= skip_above) stack[top++] = far;
            if (near.distance2 <= skip_above) stack[top++] = near;  // popped first
        }
        return best;
    }

    Vec3d pseudo_normal(const ReferenceTriangle& t, Feature feature) const {
        switch (feature) {
            case Feature::vertex_a: return vertex_normals[corners[t.id][0]];
            case Feature::vertex_b: return vertex_normals[corners[t.id][1]];
            case Feature::vertex_c: return vertex_normals[corners[t.id][2]];
            case Feature::edge_ab: return edge_normals[edges[t.id][0]];
            case Feature::edge_bc: return edge_normals[edges[t.id][1]];
            case Feature::edge_ca: return edge_normals[edges[t.id][2]];
            case Feature::face: break;
        }
        return (t.b - t.a).cross(t.c - t.a);
    }
};

MeshDistance::MeshDistance(const Mesh& reference, const MeshDistanceOptions& options) {
    validate(options);
    if (reference.face_count() == 0)
        throw input_error("reference mesh has no triangles or quads (" + std::to_string(reference.points.size()) +
                          " points); distances are measured to its faces, so give it a surface");
    check_indices(reference, "reference mesh");
    const FaceView faces(reference);
    for (std::size_t f = 0; f < faces.size(); ++f)
        for (int k = 0; k < faces.corners(f); ++k)
            if (!finite(reference.points[faces.vertex(f, k)]))
                throw input_error("reference mesh point " + std::to_string(faces.vertex(f, k)) + " (a corner of face " +
                                  std::to_string(f) +
                                  ") has a NaN or infinite coordinate; fix the point or drop the faces using it");
    const std::size_t count = split_triangle_count(reference);
    // Node and triangle indices are 32-bit; a tree has fewer than 2 nodes per triangle.
    const std::size_t max_count = std::numeric_limits<std::uint32_t>::max() / 2;
    if (count > max_count)
        throw input_error("reference mesh has " + std::to_string(count) + " triangles (quads count 2); at most " +
                          std::to_string(max_count) + " are supported");

    auto impl = std::make_shared<Impl>();
    impl->corners.resize(count);
    for (std::size_t t = 0; t < count; ++t) {
        const auto c = split_triangle(reference, t);
        impl->corners[t] = {c[0], c[1], c[2]};
    }
    std::vector<std::array<Vec3d, 3>> positions(count);
    std::vector<Vec3d> unit_normals(count, Vec3d(0.0));
    for (std::size_t t = 0; t < count; ++t) {
        for (int k = 0; k < 3; ++k) {
            positions[t][k] = reference.points[impl->corners[t][k]];
            for (int axis = 0; axis < 3; ++axis)
                impl->coordinate_scale = std::max(impl->coordinate_scale, std::abs(positions[t][k][axis]));
        }
        const Vec3d n = (positions[t][1] - positions[t][0]).cross(positions[t][2] - positions[t][0]);
        const double length = n.length();
        if (length > 0.0 && std::isfinite(length)) unit_normals[t] = n / length;
    }

    // Angle-weighted vertex normals; summed serially in id order (deterministic rounding).
    impl->vertex_normals.assign(reference.points.size(), Vec3d(0.0));
    for (std::size_t t = 0; t < count; ++t)
        for (int k = 0; k < 3; ++k) {
            const Vec3d& v = positions[t][k];
            const Vec3d u = positions[t][(k + 1) % 3] - v, w = positions[t][(k + 2) % 3] - v;
            const double angle = std::atan2(u.cross(w).length(), u.dot(w));
            if (std::isfinite(angle)) impl->vertex_normals[impl->corners[t][k]] += unit_normals[t] * angle;
        }

    // Edge normals: the sum of the unit normals of the triangles sharing the edge.
    std::vector<std::pair<std::uint64_t, std::uint64_t>> sides(3 * count);  // (edge key, 3 * id + side)
    for (std::size_t t = 0; t < count; ++t)
        for (int k = 0; k < 3; ++k) {
            const std::uint64_t a = impl->corners[t][k], b = impl->corners[t][(k + 1) % 3];
            sides[3 * t + std::size_t(k)] = {(std::min(a, b) << 32) | std::max(a, b), 3 * t + std::size_t(k)};
        }
    tbb::parallel_sort(sides.begin(), sides.end());  // a total order: same result for any thread count
    impl->edges.resize(count);
    for (std::size_t i = 0; i < sides.size(); ++i) {
        if (i == 0 || sides[i].first != sides[i - 1].first) impl->edge_normals.emplace_back(0.0);
        const std::size_t t = sides[i].second / 3;
        impl->edges[t][sides[i].second % 3] = std::uint32_t(impl->edge_normals.size() - 1);
        impl->edge_normals.back() += unit_normals[t];
    }

    BoxTreeBuilder builder(positions, options.leaf_triangles);
    builder.build(impl->nodes);
    impl->triangles.resize(count);
    for (std::size_t i = 0; i < count; ++i) {
        const std::uint32_t t = builder.order()[i];
        const auto& x = positions[t];
        impl->triangles[i] = {x[0], x[1], x[2], t, is_thin(x[0], x[1], x[2])};
    }
    impl_ = std::move(impl);
}

double MeshDistance::operator()(const Vec3d& p) const {
    if (!finite(p)) return std::numeric_limits<double>::quiet_NaN();
    return std::sqrt(impl_->nearest(p).distance2);
}

double MeshDistance::signed_distance(const Vec3d& p) const {
    if (!finite(p)) return std::numeric_limits<double>::quiet_NaN();
    const Impl::Nearest nearest = impl_->nearest(p);
    const double d = std::sqrt(nearest.distance2);
    const Vec3d n = impl_->pseudo_normal(*nearest.triangle, nearest.closest.feature);
    return (p - nearest.closest.point).dot(n) < 0.0 ? -d : d;
}

Vec3d MeshDistance::nearest_face_normal(const Vec3d& p) const {
    if (!finite(p)) return Vec3d(std::numeric_limits<double>::quiet_NaN());
    const ReferenceTriangle& t = *impl_->nearest(p).triangle;
    const Vec3d n = (t.b - t.a).cross(t.c - t.a);
    const double length = n.length();
    return length > 0.0 && std::isfinite(length) ? n / length : Vec3d(0.0);
}

DistanceStats measure_distance(const Mesh& mesh, const Mesh& reference, const MeshDistanceOptions& options) {
    return measure_distance(mesh, MeshDistance(reference, options));
}

DistanceStats measure_distance(const Mesh& mesh, const MeshDistance& distance) {
    const std::size_t n = mesh.points.size();
    std::vector<double> signed_distance(n, 0.0);
    std::vector<char> valid(n, 0);
    parallel_indices(n, [&](std::size_t i) {
        const Vec3d& p = mesh.points[i];
        if (!finite(p)) return;
        const double d = distance.signed_distance(p);
        if (!std::isfinite(d)) return;
        valid[i] = 1;
        signed_distance[i] = d;
    });
    return summarize_distances(signed_distance, valid, 0);
}

NormalDeviation measure_normal_deviation(const Mesh& mesh, const MeshDistance& reference) {
    check_indices(mesh);
    const FaceView faces(mesh);
    std::vector<double> angles(faces.size());
    parallel_indices(faces.size(), [&](std::size_t f) {
        const Vec3d normal = faces.area_vector2(f), c = faces.centroid(f);
        const Vec3d truth = finite(c) ? reference.nearest_face_normal(c) : Vec3d(0.0);
        angles[f] = normal.lengthSqr() > 0.0 && finite(normal) && truth.lengthSqr() > 0.0
                        ? angle_degrees(normal, truth)
                        : std::numeric_limits<double>::quiet_NaN();
    });
    return summarize_angles(angles);
}

}  // namespace pqdc
