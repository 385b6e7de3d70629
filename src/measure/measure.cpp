// Mesh quality measures. Per-sample values are computed in parallel into
// arrays indexed by sample and reduced serially in index order, so floating
// point sums do not depend on how TBB split the work.
#include "pqdc/measure.hpp"

#include "pqdc/exceptions.hpp"
#include "measure/mesh_internal.hpp"

#include <openvdb/tools/Interpolation.h>

#include <tbb/blocked_range.h>
#include <tbb/combinable.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <numeric>
#include <string>
#include <utility>
#include <vector>

namespace pqdc {

namespace {

using detail::BoxNode;
using detail::BoxTreeBuilder;
using detail::check_indices;
using detail::split_triangle;
using detail::split_triangle_count;
using detail::UnionFind;

constexpr double kDegreesPerRadian = 57.29577951308232;

using Vec3d = openvdb::Vec3d;

bool finite(const Vec3d& v) { return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]); }

/// Angle between two vectors in degrees, robust near 0 and 180.
double angle_degrees(const Vec3d& a, const Vec3d& b) {
    return std::atan2(a.cross(b).length(), a.dot(b)) * kDegreesPerRadian;
}

/// Uniform access to triangles and quads as faces 0..F-1 (triangles first).
class FaceView {
public:
    explicit FaceView(const Mesh& mesh) : mesh_(mesh) {}
    std::size_t size() const { return mesh_.triangles.size() + mesh_.quads.size(); }
    int corners(std::size_t f) const { return f < mesh_.triangles.size() ? 3 : 4; }
    unsigned vertex(std::size_t f, int k) const {
        return f < mesh_.triangles.size() ? mesh_.triangles[f][k] : mesh_.quads[f - mesh_.triangles.size()][k];
    }
    bool has_repeated_vertex(std::size_t f) const {
        const int n = corners(f);
        for (int i = 0; i < n; ++i)
            for (int j = i + 1; j < n; ++j)
                if (vertex(f, i) == vertex(f, j)) return true;
        return false;
    }
    /// Vector area times 2 (triangle: cross of two sides; quad: cross of the
    /// diagonals, the exact vector area of a non-planar quad).
    Vec3d area_vector2(std::size_t f) const {
        const auto& p = mesh_.points;
        if (corners(f) == 3) {
            const Vec3d& a = p[vertex(f, 0)];
            return (p[vertex(f, 1)] - a).cross(p[vertex(f, 2)] - a);
        }
        return (p[vertex(f, 2)] - p[vertex(f, 0)]).cross(p[vertex(f, 3)] - p[vertex(f, 1)]);
    }
    Vec3d centroid(std::size_t f) const {
        Vec3d c(0.0);
        const int n = corners(f);
        for (int k = 0; k < n; ++k) c += mesh_.points[vertex(f, k)];
        return c / double(n);
    }
    double longest_side(std::size_t f) const {
        const int n = corners(f);
        double l = 0;
        for (int k = 0; k < n; ++k)
            l = std::max(l, (mesh_.points[vertex(f, (k + 1) % n)] - mesh_.points[vertex(f, k)]).length());
        return l;
    }

private:
    const Mesh& mesh_;
};

struct HalfEdge {
    std::uint64_t key;    // (lo << 32) | hi
    std::uint32_t face;
    bool forward;         // traversed lo -> hi
    bool operator<(const HalfEdge& o) const { return key != o.key ? key < o.key : face < o.face; }
};

template <typename Fn>
void parallel_indices(std::size_t n, Fn&& fn) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) fn(i);
    });
}

/// Newton projection of p onto f = 0. Returns true when |f(q)| <= tolerance
/// and q stayed local: a projection that travels more than twice the
/// first-order distance |f(p)| / |grad f(p)| has jumped to another part of
/// the surface (where the gradient is small, a full step overshoots), and
/// the caller falls back to the first-order estimate.
bool project_to_surface(const ScalarField& field, const Vec3d& p, const FieldDistanceOptions& options, Vec3d& q) {
    q = p;
    double reach = -1.0;
    for (int step = 0;; ++step) {
        const double f = field.value(q);
        if (!std::isfinite(f)) return false;
        if (std::abs(f) <= options.tolerance) return reach < 0.0 || (q - p).length() <= reach;
        if (step == options.newton_steps) return false;
        const Vec3d g = field.gradient(q);
        const double g2 = g.lengthSqr();
        if (!(g2 > 0.0) || !std::isfinite(g2)) return false;
        if (reach < 0.0) reach = 2.0 * std::abs(f) / std::sqrt(g2) + options.tolerance;
        q -= g * (f / g2);
        if ((q - p).length() > reach) return false;
    }
}

/// Distance along the unit direction u from p to the first point where f
/// changes sign, searched up to t_max; -1 when there is none. Steps of
/// |f| / L (L: the field's Lipschitz bound) cannot jump over the surface, a
/// floor of t_min keeps the march finite where f nearly vanishes, and the
/// last bracket is bisected.
double first_crossing_along(const ScalarField& field, const Vec3d& p, const Vec3d& u, double f0, double lipschitz,
                            double t_min, double t_max) {
    double t = 0.0;
    for (int step = 0; step < 100000; ++step) {
        const double f = field.value(p + u * t);
        if (!std::isfinite(f)) return -1.0;
        if (f == 0.0) return t;
        if ((f < 0.0) != (f0 < 0.0)) {
            double a = std::max(0.0, t - std::max(std::abs(f) / lipschitz, t_min)), b = t;
            a = std::max(0.0, a);
            for (int i = 0; i < 60 && b - a > 1e-3 * t_min; ++i) {
                const double m = 0.5 * (a + b);
                const double fm = field.value(p + u * m);
                if ((fm < 0.0) == (f0 < 0.0)) a = m;
                else b = m;
            }
            return 0.5 * (a + b);
        }
        if (t >= t_max) return -1.0;
        t = std::min(t_max, t + std::max(std::abs(f) / lipschitz, t_min));
    }
    return -1.0;
}

/// Where Newton's projection fails (|grad f| tiny or misleading), the
/// distance to the nearest surface point found by marching along the
/// gradient and the 26 lattice directions: an upper bound that is a real
/// surface point, unlike |f| / |grad f|, which explodes where the gradient
/// nearly vanishes. Falls back to the lower bound |f| / L when no march
/// meets the surface.
double fallback_distance(const ScalarField& field, const Vec3d& p, double f) {
    const double lipschitz = field.lipschitz_bound();
    const double lower = std::abs(f) / lipschitz;
    if (!(lipschitz > 0.0) || !std::isfinite(lower)) return std::abs(f);
    if (lower == 0.0) return 0.0;
    std::vector<Vec3d> dirs;
    const Vec3d g = field.gradient(p);
    if (g.lengthSqr() > 0.0 && finite(g)) {
        dirs.push_back(g.unitSafe());
        dirs.push_back(-g.unitSafe());
    }
    for (int z = -1; z <= 1; ++z)
        for (int y = -1; y <= 1; ++y)
            for (int x = -1; x <= 1; ++x)
                if (x || y || z) dirs.push_back(Vec3d(x, y, z).unitSafe());
    double best = -1.0;
    Vec3d q;
    const double t_min = 1e-3 * lower;
    for (const Vec3d& u : dirs) {
        const double t_max = best >= 0.0 ? best : 1000.0 * lower;
        const double t = first_crossing_along(field, p, u, f, lipschitz, t_min, t_max);
        if (t >= 0.0 && (best < 0.0 || t < best)) {
            best = t;
            q = p + u * t;
        }
    }
    if (best < 0.0) return lower;
    // The hit nearest along a fixed direction is rarely the nearest point:
    // slide it along the surface, from each q to the Newton projection of p's
    // foot on the tangent plane at q, while that gets closer.
    for (int it = 0; it < 32; ++it) {
        const Vec3d n = field.gradient(q);
        if (!(n.lengthSqr() > 0.0) || !finite(n)) break;
        const Vec3d un = n.unitSafe();
        const Vec3d foot = p - un * (p - q).dot(un);
        Vec3d next = foot;
        for (int k = 0; k < 16; ++k) {  // plain Newton from the foot (it starts on the surface's tangent plane)
            const double fv = field.value(next);
            const Vec3d g = field.gradient(next);
            if (!std::isfinite(fv) || !(g.lengthSqr() > 0.0)) break;
            next -= g * (fv / g.lengthSqr());
        }
        if (!(std::abs(field.value(next)) <= 1e-6 * lower * lipschitz)) break;
        if (!((p - next).length() < (p - q).length() * (1.0 - 1e-9))) break;
        q = next;
    }
    return std::max((p - q).length(), lower);
}

void validate(const FieldDistanceOptions& options) {
    if (options.newton_steps < 1 || options.newton_steps > 100)
        throw option_error("FieldDistanceOptions::newton_steps = " + std::to_string(options.newton_steps) +
                           " is outside [1, 100]");
    if (!(options.tolerance > 0.0) || !std::isfinite(options.tolerance))
        throw option_error("FieldDistanceOptions::tolerance must be a positive finite number");
}

DistanceStats summarize_distances(const std::vector<double>& signed_distance, const std::vector<char>& valid,
                                  std::size_t unreliable) {
    DistanceStats s;
    double sum = 0, sum_sq = 0, sum_signed = 0;
    for (std::size_t i = 0; i < signed_distance.size(); ++i) {
        if (!valid[i]) continue;
        const double d = std::abs(signed_distance[i]);
        ++s.sample_count;
        sum += d;
        sum_sq += d * d;
        sum_signed += signed_distance[i];
        s.max = std::max(s.max, d);
    }
    if (s.sample_count > 0) {
        const double n = double(s.sample_count);
        s.mean = sum / n;
        s.rms = std::sqrt(sum_sq / n);
        s.mean_signed = sum_signed / n;
    }
    s.unreliable_count = unreliable;
    return s;
}

NormalDeviation summarize_angles(const std::vector<double>& angles) {
    NormalDeviation d;
    double sum = 0, sum_sq = 0;
    for (double a : angles) {
        if (std::isnan(a)) {
            ++d.skipped_count;
            continue;
        }
        ++d.sample_count;
        sum += a;
        sum_sq += a * a;
        d.max_degrees = std::max(d.max_degrees, a);
    }
    if (d.sample_count > 0) {
        d.mean_degrees = sum / double(d.sample_count);
        d.rms_degrees = std::sqrt(sum_sq / double(d.sample_count));
    }
    return d;
}

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

// ---- JSON ----
class JsonObject {
public:
    JsonObject() : text_("{") {}
    JsonObject& add(const char* key, double v) {
        begin(key);
        if (!std::isfinite(v)) {
            text_ += "null";
        } else {
            char buf[32];
            const auto r = std::to_chars(buf, buf + sizeof buf, v);
            text_.append(buf, r.ptr);
        }
        return *this;
    }
    JsonObject& add(const char* key, std::size_t v) {
        begin(key);
        text_ += std::to_string(v);
        return *this;
    }
    JsonObject& add(const char* key, long long v) {
        begin(key);
        text_ += std::to_string(v);
        return *this;
    }
    JsonObject& add(const char* key, bool v) {
        begin(key);
        text_ += v ? "true" : "false";
        return *this;
    }
    std::string str() const { return text_ + "}"; }

private:
    void begin(const char* key) {
        if (text_.size() > 1) text_ += ",";
        text_ += "\"";
        text_ += key;
        text_ += "\":";
    }
    std::string text_;
};

}  // namespace

TopologyReport measure_topology(const Mesh& mesh) {
    check_indices(mesh);
    TopologyReport r;
    const FaceView faces(mesh);
    const std::size_t nf = faces.size();
    r.vertex_count = mesh.points.size();
    r.triangle_count = mesh.triangles.size();
    r.quad_count = mesh.quads.size();
    for (const Vec3d& p : mesh.points)
        if (!finite(p)) ++r.non_finite_point_count;

    // Degenerate faces: repeated indices are excluded from everything below;
    // zero-area faces (relative to their size, so rounding in nearly
    // collinear corners still counts) stay in the combinatorics.
    std::vector<char> excluded(nf, 0);
    tbb::combinable<std::size_t> degenerate([] { return std::size_t(0); });
    parallel_indices(nf, [&](std::size_t f) {
        if (faces.has_repeated_vertex(f)) {
            excluded[f] = 1;
            ++degenerate.local();
            return;
        }
        const double area2 = faces.area_vector2(f).length();
        const double side = faces.longest_side(f);
        if (area2 <= 1e-12 * side * side) ++degenerate.local();
    });
    r.degenerate_face_count = degenerate.combine(std::plus<std::size_t>());

    // Undirected edges by sorting half-edges.
    std::vector<std::size_t> first_half_edge(nf + 1, 0);
    for (std::size_t f = 0; f < nf; ++f) first_half_edge[f + 1] = first_half_edge[f] + (excluded[f] ? 0 : faces.corners(f));
    std::vector<HalfEdge> half_edges(first_half_edge[nf]);
    parallel_indices(nf, [&](std::size_t f) {
        if (excluded[f]) return;
        const int n = faces.corners(f);
        for (int k = 0; k < n; ++k) {
            const std::uint32_t a = faces.vertex(f, k), b = faces.vertex(f, (k + 1) % n);
            const std::uint32_t lo = std::min(a, b), hi = std::max(a, b);
            half_edges[first_half_edge[f] + std::size_t(k)] =
                HalfEdge{(std::uint64_t(lo) << 32) | hi, std::uint32_t(f), a < b};
        }
    });
    tbb::parallel_sort(half_edges.begin(), half_edges.end());
    for (std::size_t i = 0; i < half_edges.size();) {
        std::size_t j = i + 1;
        while (j < half_edges.size() && half_edges[j].key == half_edges[i].key) ++j;
        const std::size_t uses = j - i;
        ++r.edge_count;
        if (uses == 1) ++r.boundary_edge_count;
        else if (uses == 2 && half_edges[i].forward == half_edges[i + 1].forward) ++r.inconsistent_edge_count;
        else if (uses > 2) ++r.non_manifold_edge_count;
        i = j;
    }
    half_edges = std::vector<HalfEdge>();

    // Corners grouped by vertex: (face, previous vertex, next vertex).
    const std::size_t nv = mesh.points.size();
    std::vector<std::size_t> first_corner(nv + 1, 0);
    for (std::size_t f = 0; f < nf; ++f)
        if (!excluded[f])
            for (int k = 0; k < faces.corners(f); ++k) ++first_corner[faces.vertex(f, k) + 1];
    for (std::size_t v = 0; v < nv; ++v) first_corner[v + 1] += first_corner[v];
    struct Corner {
        std::uint32_t prev, next;
    };
    std::vector<Corner> corners(first_corner[nv]);
    {
        std::vector<std::size_t> fill(first_corner.begin(), first_corner.end() - 1);
        for (std::size_t f = 0; f < nf; ++f) {
            if (excluded[f]) continue;
            const int n = faces.corners(f);
            for (int k = 0; k < n; ++k)
                corners[fill[faces.vertex(f, k)]++] = Corner{faces.vertex(f, (k + n - 1) % n), faces.vertex(f, (k + 1) % n)};
        }
    }

    // A vertex is manifold when its faces are connected through the edges
    // they share at the vertex (one fan, open or closed).
    tbb::combinable<std::size_t> non_manifold_vertices([] { return std::size_t(0); });
    tbb::combinable<std::size_t> unreferenced([] { return std::size_t(0); });
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 2048), [&](const tbb::blocked_range<std::size_t>& range) {
        std::vector<std::pair<std::uint32_t, std::uint32_t>> spokes;  // (other vertex, local face)
        std::vector<std::uint32_t> parent;
        for (std::size_t v = range.begin(); v != range.end(); ++v) {
            const std::size_t b = first_corner[v], e = first_corner[v + 1];
            if (b == e) {
                ++unreferenced.local();
                continue;
            }
            if (e - b == 1) continue;
            spokes.clear();
            for (std::size_t c = b; c < e; ++c) {
                spokes.emplace_back(corners[c].prev, std::uint32_t(c - b));
                spokes.emplace_back(corners[c].next, std::uint32_t(c - b));
            }
            std::sort(spokes.begin(), spokes.end());
            parent.resize(e - b);
            std::iota(parent.begin(), parent.end(), 0u);
            auto find = [&](std::uint32_t x) {
                while (parent[x] != x) x = parent[x] = parent[parent[x]];
                return x;
            };
            std::size_t components = e - b;
            for (std::size_t i = 1; i < spokes.size(); ++i) {
                if (spokes[i].first != spokes[i - 1].first) continue;
                const std::uint32_t x = find(spokes[i].second), y = find(spokes[i - 1].second);
                if (x != y) {
                    parent[std::max(x, y)] = std::min(x, y);
                    --components;
                }
            }
            if (components > 1) ++non_manifold_vertices.local();
        }
    });
    r.non_manifold_vertex_count = non_manifold_vertices.combine(std::plus<std::size_t>());
    r.unreferenced_vertex_count = unreferenced.combine(std::plus<std::size_t>());

    UnionFind components(nv);
    std::size_t used_faces = 0;
    for (std::size_t f = 0; f < nf; ++f) {
        if (excluded[f]) continue;
        ++used_faces;
        for (int k = 1; k < faces.corners(f); ++k) components.unite(faces.vertex(f, 0), faces.vertex(f, k));
    }
    for (std::size_t v = 0; v < nv; ++v)
        if (first_corner[v] != first_corner[v + 1] && components.find(std::uint32_t(v)) == v)
            ++r.connected_component_count;

    r.euler_characteristic = static_cast<long long>(nv - r.unreferenced_vertex_count) -
                             static_cast<long long>(r.edge_count) + static_cast<long long>(used_faces);
    return r;
}

TriangleQuality measure_triangle_quality(const Mesh& mesh) {
    check_indices(mesh);
    const std::size_t nt = split_triangle_count(mesh);
    std::vector<double> min_angle(nt);
    auto corner_angle = [](const Vec3d& a, const Vec3d& b, const Vec3d& c) {
        const Vec3d u = b - a, v = c - a;
        if (!(u.lengthSqr() > 0.0) || !(v.lengthSqr() > 0.0)) return 0.0;
        const double angle = angle_degrees(u, v);
        return std::isfinite(angle) ? angle : 0.0;
    };
    auto tri_min_angle = [&](unsigned i, unsigned j, unsigned k) {
        const Vec3d &a = mesh.points[i], &b = mesh.points[j], &c = mesh.points[k];
        return std::min({corner_angle(a, b, c), corner_angle(b, c, a), corner_angle(c, a, b)});
    };
    parallel_indices(nt, [&](std::size_t t) {
        const auto c = split_triangle(mesh, t);
        min_angle[t] = tri_min_angle(c[0], c[1], c[2]);
    });
    TriangleQuality out;
    out.triangle_count = nt;
    if (nt == 0) return out;
    double sum = 0;
    std::size_t below = 0;
    out.min_angle_min_degrees = min_angle[0];
    for (double a : min_angle) {
        sum += a;
        if (a < 10.0) ++below;
        out.min_angle_min_degrees = std::min(out.min_angle_min_degrees, a);
    }
    out.min_angle_mean_degrees = sum / double(nt);
    out.fraction_below_10_degrees = double(below) / double(nt);
    const std::size_t rank = std::max<std::size_t>(1, static_cast<std::size_t>(std::ceil(0.05 * double(nt))));
    std::nth_element(min_angle.begin(), min_angle.begin() + std::ptrdiff_t(rank - 1), min_angle.end());
    out.min_angle_p05_degrees = min_angle[rank - 1];
    return out;
}

DistanceStats measure_distance(const Mesh& mesh, const ScalarField& field, const FieldDistanceOptions& options) {
    validate(options);
    const std::size_t n = mesh.points.size();
    std::vector<double> signed_distance(n, 0.0);
    std::vector<char> valid(n, 0), unreliable(n, 0);
    parallel_indices(n, [&](std::size_t i) {
        const Vec3d& p = mesh.points[i];
        if (!finite(p)) return;
        const double f = field.value(p);
        if (!std::isfinite(f)) return;
        valid[i] = 1;
        Vec3d q;
        double d;
        if (project_to_surface(field, p, options, q)) {
            d = (p - q).length();
        } else {
            d = fallback_distance(field, p, f);
            unreliable[i] = 1;
        }
        signed_distance[i] = f < 0.0 ? -d : d;
    });
    const std::size_t unreliable_count = static_cast<std::size_t>(std::count(unreliable.begin(), unreliable.end(), 1));
    return summarize_distances(signed_distance, valid, unreliable_count);
}

DistanceStats measure_distance(const Mesh& mesh, const openvdb::FloatGrid& level_set) {
    if (level_set.getGridClass() == openvdb::GRID_FOG_VOLUME) {
        throw input_error("grid '" + level_set.getName() +
                          "' is a fog volume; distances need a level set (values = signed world distance)");
    }
    const std::size_t n = mesh.points.size();
    const double background = std::abs(double(level_set.background()));
    std::vector<double> signed_distance(n, 0.0);
    std::vector<char> valid(n, 0), unreliable(n, 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096), [&](const tbb::blocked_range<std::size_t>& r) {
        openvdb::FloatGrid::ConstAccessor accessor = level_set.getConstAccessor();
        openvdb::tools::GridSampler<openvdb::FloatGrid::ConstAccessor, openvdb::tools::BoxSampler> sampler(
            accessor, level_set.transform());
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            const Vec3d& p = mesh.points[i];
            if (!finite(p)) continue;
            const double v = double(sampler.wsSample(p));
            if (!std::isfinite(v)) continue;
            valid[i] = 1;
            signed_distance[i] = v;
            if (background > 0.0 && std::abs(v) >= background * (1.0 - 1e-6)) unreliable[i] = 1;
        }
    });
    const std::size_t unreliable_count = static_cast<std::size_t>(std::count(unreliable.begin(), unreliable.end(), 1));
    return summarize_distances(signed_distance, valid, unreliable_count);
}

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

NormalDeviation measure_normal_deviation(const Mesh& mesh, const ScalarField& field, NormalSampling sampling,
                                         const FieldDistanceOptions& options) {
    validate(options);
    check_indices(mesh);
    const FaceView faces(mesh);
    const double nan = std::numeric_limits<double>::quiet_NaN();
    auto deviation = [&](const Vec3d& normal, const Vec3d& p) {
        if (!(normal.lengthSqr() > 0.0) || !finite(normal) || !finite(p)) return nan;
        Vec3d q;
        if (!project_to_surface(field, p, options, q)) q = p;
        const Vec3d g = field.gradient(q);
        if (!(g.lengthSqr() > 0.0) || !finite(g)) return nan;
        return angle_degrees(normal, g);
    };
    std::vector<double> angles;
    if (sampling == NormalSampling::per_face) {
        angles.resize(faces.size());
        parallel_indices(faces.size(), [&](std::size_t f) {
            angles[f] = deviation(faces.area_vector2(f), faces.centroid(f));
        });
    } else {
        // Serial accumulation keeps the sums' rounding independent of threads.
        std::vector<Vec3d> normals(mesh.points.size(), Vec3d(0.0));
        std::vector<char> referenced(mesh.points.size(), 0);
        for (std::size_t f = 0; f < faces.size(); ++f) {
            const Vec3d a = faces.area_vector2(f);
            for (int k = 0; k < faces.corners(f); ++k) {
                normals[faces.vertex(f, k)] += a;
                referenced[faces.vertex(f, k)] = 1;
            }
        }
        angles.resize(mesh.points.size());
        parallel_indices(mesh.points.size(), [&](std::size_t v) {
            angles[v] = referenced[v] ? deviation(normals[v], mesh.points[v]) : -1.0;
        });
        angles.erase(std::remove(angles.begin(), angles.end(), -1.0), angles.end());
    }
    return summarize_angles(angles);
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

std::string to_json(const TopologyReport& r) {
    return JsonObject()
        .add("vertex_count", r.vertex_count)
        .add("unreferenced_vertex_count", r.unreferenced_vertex_count)
        .add("triangle_count", r.triangle_count)
        .add("quad_count", r.quad_count)
        .add("edge_count", r.edge_count)
        .add("boundary_edge_count", r.boundary_edge_count)
        .add("non_manifold_edge_count", r.non_manifold_edge_count)
        .add("inconsistent_edge_count", r.inconsistent_edge_count)
        .add("non_manifold_vertex_count", r.non_manifold_vertex_count)
        .add("degenerate_face_count", r.degenerate_face_count)
        .add("non_finite_point_count", r.non_finite_point_count)
        .add("connected_component_count", r.connected_component_count)
        .add("euler_characteristic", r.euler_characteristic)
        .add("edge_manifold", r.edge_manifold())
        .add("vertex_manifold", r.vertex_manifold())
        .add("consistently_oriented", r.consistently_oriented())
        .add("closed", r.closed())
        .str();
}

std::string to_json(const TriangleQuality& q) {
    return JsonObject()
        .add("triangle_count", q.triangle_count)
        .add("min_angle_mean_degrees", q.min_angle_mean_degrees)
        .add("min_angle_min_degrees", q.min_angle_min_degrees)
        .add("min_angle_p05_degrees", q.min_angle_p05_degrees)
        .add("fraction_below_10_degrees", q.fraction_below_10_degrees)
        .str();
}

std::string to_json(const DistanceStats& s) {
    return JsonObject()
        .add("sample_count", s.sample_count)
        .add("mean", s.mean)
        .add("rms", s.rms)
        .add("max", s.max)
        .add("mean_signed", s.mean_signed)
        .add("unreliable_count", s.unreliable_count)
        .str();
}

std::string to_json(const NormalDeviation& d) {
    return JsonObject()
        .add("sample_count", d.sample_count)
        .add("mean_degrees", d.mean_degrees)
        .add("rms_degrees", d.rms_degrees)
        .add("max_degrees", d.max_degrees)
        .add("skipped_count", d.skipped_count)
        .str();
}

}  // namespace pqdc
