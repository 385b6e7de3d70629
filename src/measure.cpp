// Mesh quality measures. Per-sample values are computed in parallel into
// arrays indexed by sample and reduced serially in index order, so floating
// point sums do not depend on how TBB split the work.
#include "pqdc/measure.hpp"

#include "pqdc/exceptions.hpp"

#include <openvdb/tools/Interpolation.h>

#include <tbb/blocked_range.h>
#include <tbb/combinable.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <numeric>
#include <string>
#include <vector>

namespace pqdc {

namespace {

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

void check_indices(const Mesh& mesh) {
    const std::size_t n = mesh.points.size();
    const FaceView faces(mesh);
    for (std::size_t f = 0; f < faces.size(); ++f)
        for (int k = 0; k < faces.corners(f); ++k)
            if (faces.vertex(f, k) >= n)
                throw input_error("mesh face " + std::to_string(f) + " refers to vertex " +
                                  std::to_string(faces.vertex(f, k)) + " but the mesh has only " + std::to_string(n) +
                                  " points");
}

struct UnionFind {
    std::vector<std::uint32_t> parent;
    explicit UnionFind(std::size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0u); }
    std::uint32_t find(std::uint32_t x) {
        while (parent[x] != x) {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        return x;
    }
    void unite(std::uint32_t a, std::uint32_t b) {
        a = find(a);
        b = find(b);
        if (a == b) return;
        if (a < b) std::swap(a, b);
        parent[a] = b;  // smaller root wins: structure independent of call order details
    }
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
    const std::size_t nt = mesh.triangles.size() + 2 * mesh.quads.size();
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
    const std::size_t ntri = mesh.triangles.size();
    parallel_indices(nt, [&](std::size_t t) {
        if (t < ntri) {
            const auto& f = mesh.triangles[t];
            min_angle[t] = tri_min_angle(f[0], f[1], f[2]);
        } else {
            const auto& q = mesh.quads[(t - ntri) / 2];
            min_angle[t] = (t - ntri) % 2 == 0 ? tri_min_angle(q[0], q[1], q[2]) : tri_min_angle(q[0], q[2], q[3]);
        }
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
