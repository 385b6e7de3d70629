// Exact distances from points to a reference mesh's triangles and quads
// (MeshDistance: a bounding-box tree pruned only by boxes farther than the
// best triangle found, signed by angle-weighted pseudo-normals).
#include "pqdc/measure.hpp"

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

namespace {

// ---- distance to a reference mesh ----

/// Which part of a triangle a closest point lies on; the sign of a distance
/// comes from that part's pseudo-normal.
enum class Feature : std::uint8_t { vertex_a, vertex_b, vertex_c, edge_ab, edge_bc, edge_ca, face };

struct ClosestPoint {
    Vec3d point;
    Feature feature;
};

ClosestPoint closest_on_segment(const Vec3d& p, const Vec3d& a, const Vec3d& b, Feature at_a, Feature at_b,
                                Feature inside) {
    const Vec3d ab = b - a;
    const double len2 = ab.lengthSqr();
    const double t = ab.dot(p - a);
    if (!(t > 0.0) || !(len2 > 0.0)) return {a, at_a};
    if (t >= len2) return {b, at_b};
    return {a + ab * (t / len2), inside};
}

/// The nearest point of the three sides.
ClosestPoint closest_on_sides(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    ClosestPoint best = closest_on_segment(p, a, b, Feature::vertex_a, Feature::vertex_b, Feature::edge_ab);
    for (const ClosestPoint& q : {closest_on_segment(p, b, c, Feature::vertex_b, Feature::vertex_c, Feature::edge_bc),
                                  closest_on_segment(p, c, a, Feature::vertex_c, Feature::vertex_a, Feature::edge_ca)})
        if ((q.point - p).lengthSqr() < (best.point - p).lengthSqr()) best = q;
    return best;
}

/// For well-shaped triangles (see is_thin). Ericson, Real-Time Collision
/// Detection, 5.1.5: the Voronoi regions of the corners, sides and interior
/// in turn. Its region tests are differences of products of dot products,
/// whose rounding grows as 1 / thinness^2.
ClosestPoint closest_on_triangle(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    const Vec3d ab = b - a, ac = c - a, ap = p - a;
    const double d1 = ab.dot(ap), d2 = ac.dot(ap);
    if (d1 <= 0 && d2 <= 0) return {a, Feature::vertex_a};
    const Vec3d bp = p - b;
    const double d3 = ab.dot(bp), d4 = ac.dot(bp);
    if (d3 >= 0 && d4 <= d3) return {b, Feature::vertex_b};
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) return {a + ab * (d1 / (d1 - d3)), Feature::edge_ab};
    const Vec3d cp = p - c;
    const double d5 = ab.dot(cp), d6 = ac.dot(cp);
    if (d6 >= 0 && d5 <= d6) return {c, Feature::vertex_c};
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) return {a + ac * (d2 / (d2 - d6)), Feature::edge_ca};
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0)
        return {b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6))), Feature::edge_bc};
    const double denom = 1.0 / (va + vb + vc);
    return {a + ab * (vb * denom) + ac * (vc * denom), Feature::face};
}

/// Thin and zero-area triangles: the nearest point of the sides, or the foot
/// of p on the plane when it falls inside. Inside is decided by the signs of
/// triple products, which do not cancel like Ericson's region tests, and
/// the plane offset is measured from the nearest side point (in the plane,
/// next to the foot), so the normal's large relative rounding across a
/// sliver tilts it by almost nothing: errors stay near rounding of the
/// coordinates at any thinness.
ClosestPoint closest_on_thin_triangle(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    const ClosestPoint side = closest_on_sides(p, a, b, c);
    const Vec3d n = (b - a).cross(c - a);
    const double n2 = n.lengthSqr();
    if (!(n2 > 0.0) || !std::isfinite(n2)) return side;
    const Vec3d pa = a - p, pb = b - p, pc = c - p;
    if (!(n.dot(pb.cross(pc)) > 0 && n.dot(pc.cross(pa)) > 0 && n.dot(pa.cross(pb)) > 0)) return side;
    const Vec3d unit = n / std::sqrt(n2);
    const Vec3d foot = p - unit * unit.dot(p - side.point);
    if ((foot - p).lengthSqr() < (side.point - p).lengthSqr()) return {foot, Feature::face};
    return side;
}

/// Thin: twice the area below a tenth of the longest side squared (the
/// height onto that side below a tenth of its length), zero-area, or so
/// large that the squares overflow. Above that, Ericson's rounding (about
/// 1e-16 / thinness^2 of the triangle's size) stays below 1e-14, and none
/// of its divisions can be 0 / 0.
bool is_thin(const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    const double longest2 = std::max({(b - a).lengthSqr(), (c - b).lengthSqr(), (a - c).lengthSqr()});
    const double bound = 0.01 * longest2 * longest2;
    return !((b - a).cross(c - a).lengthSqr() >= bound) || !std::isfinite(bound);
}

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
        valid[i] = 1;
        signed_distance[i] = distance.signed_distance(p);
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
