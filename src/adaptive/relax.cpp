// Feature-aware tangential relaxation (see relax.hpp).
//
// Per sweep, for every movable vertex p with triangles t (unit normals n_t,
// areas a_t): the normal tensor T = sum a_t n_t n_t^T has one large
// eigenvalue on a flat part (free: the other two directions, the tangent
// plane), two on a crease (free: the edge direction), three at a corner
// (nothing free). The move is the free part of (centroid of the neighbours
// - p), times `step`, at most `max_move_voxels` long; it is refused if it
// turns a triangle of p by more than `max_turn_degrees`. All vertices move at
// once; a triangle that two simultaneous moves turned too far gets its moved
// corners put back, until none does.
//
// Defaults, on bench_quality --meshers adapt (noise 0.1-0.3 voxel, five
// shapes): the 5th-percentile smallest angle went from 16.8-23.0 to
// 23.6-29.3 at 128 cells. free_ratio 0.1 gained 2 degrees more but cost up
// to 7% of feature error on the box; 0.02 costs at most 1.4%. A third sweep
// gained nothing. The caller (polygonize.cpp) moves only vertices near
// merged leaves; the README's quality section has the measured suite.
#include "adaptive/relax.hpp"

#include "adaptive/triangle_fans.hpp"

#include "pqdc/quadric.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cmath>

namespace pqdc::adaptive_detail {
namespace {

using Vec3d = openvdb::Vec3d;

/// The alive triangles around each vertex, ascending (CSR).
/// Vertices that must stay: those not movable and the corners of edges that
/// do not have exactly two alive triangles (boundary, non-manifold).
std::vector<std::uint8_t> fixed_vertices(const std::vector<openvdb::Vec3I>& tris, const std::vector<std::uint8_t>& alive,
                                         const std::vector<std::uint8_t>& movable) {
    std::vector<std::uint8_t> fixed(movable.size(), 0);
    for (std::size_t v = 0; v < movable.size(); ++v) fixed[v] = !movable[v];
    std::vector<std::uint64_t> edges;
    edges.reserve(3 * tris.size());
    for (std::size_t t = 0; t < tris.size(); ++t) {
        if (!alive[t]) continue;
        for (int k = 0; k < 3; ++k) {
            const std::uint32_t a = tris[t][k], b = tris[t][(k + 1) % 3];
            edges.push_back(a < b ? std::uint64_t(a) << 32 | b : std::uint64_t(b) << 32 | a);
        }
    }
    tbb::parallel_sort(edges.begin(), edges.end());
    for (std::size_t i = 0; i < edges.size();) {
        std::size_t j = i + 1;
        while (j < edges.size() && edges[j] == edges[i]) ++j;
        if (j - i != 2) fixed[edges[i] >> 32] = fixed[edges[i] & 0xffffffffu] = 1;
        i = j;
    }
    return fixed;
}

Vec3d corner(const std::vector<Vec3d>& points, const openvdb::Vec3I& t, int k, std::uint32_t v, const Vec3d& at) {
    return std::uint32_t(t[k]) == v ? at : points[t[k]];
}

/// Unscaled normal of triangle t with vertex v at `at`.
Vec3d normal_with(const std::vector<Vec3d>& points, const openvdb::Vec3I& t, std::uint32_t v, const Vec3d& at) {
    const Vec3d a = corner(points, t, 0, v, at), b = corner(points, t, 1, v, at), c = corner(points, t, 2, v, at);
    return (b - a).cross(c - a);
}

/// Does the triangle turn by at most acos(min_cos) (and stay non-degenerate)
/// from normal `before` to `after`?
bool turn_ok(const Vec3d& before, const Vec3d& after, double min_cos) {
    const double lb = before.length(), la = after.length();
    if (!(lb > 0) || !(la > 1e-12 * lb)) return false;
    return before.dot(after) >= min_cos * lb * la;
}

/// The relaxed position of vertex v (or its current one).
Vec3d relaxed(std::uint32_t v, const std::vector<Vec3d>& points, const std::vector<openvdb::Vec3I>& tris,
              const Fans& fans, const RelaxLimits& limits, double min_cos, std::vector<std::uint32_t>& ring) {
    const Vec3d& p = points[v];
    sym3<double> tensor{};
    ring.clear();
    for (std::uint32_t e = fans.begin[v]; e < fans.begin[v + 1]; ++e) {
        const openvdb::Vec3I& t = tris[fans.triangle[e]];
        const Vec3d n = normal_with(points, t, v, p);
        const double len = n.length();
        if (!(len > 0)) return p;
        const vec3<double> u{n[0] / len, n[1] / len, n[2] / len};
        tensor += sym3<double>::outer(u) * (0.5 * len);  // area-weighted
        for (int k = 0; k < 3; ++k)
            if (std::uint32_t(t[k]) != v) ring.push_back(std::uint32_t(t[k]));
    }
    if (ring.empty()) return p;
    std::sort(ring.begin(), ring.end());
    ring.erase(std::unique(ring.begin(), ring.end()), ring.end());
    Vec3d centroid(0.0);
    for (std::uint32_t u : ring) centroid += points[u];
    centroid /= double(ring.size());

    const sym3_eigen eig = eigen_decompose(tensor);
    const double largest = std::max({eig.values[0], eig.values[1], eig.values[2]});
    if (!(largest > 0)) return p;
    const Vec3d to_centroid = centroid - p;
    Vec3d move(0.0);
    for (int i = 0; i < 3; ++i) {
        if (!(eig.values[i] < limits.free_ratio * largest)) continue;
        const Vec3d d(eig.vectors[i].x, eig.vectors[i].y, eig.vectors[i].z);
        move += d * d.dot(to_centroid);
    }
    move *= limits.step;
    const double len = move.length();
    if (!(len > 0)) return p;
    if (len > limits.max_move_voxels) move *= limits.max_move_voxels / len;
    const Vec3d q = p + move;
    for (std::uint32_t e = fans.begin[v]; e < fans.begin[v + 1]; ++e) {
        const openvdb::Vec3I& t = tris[fans.triangle[e]];
        if (!turn_ok(normal_with(points, t, v, p), normal_with(points, t, v, q), min_cos)) return p;
    }
    return q;
}

/// Puts back the moved corners of every triangle that the simultaneous
/// moves turned too far, until there is none. Each round puts back at least
/// one vertex, so this ends.
void undo_joint_turns(const std::vector<Vec3d>& before, std::vector<Vec3d>& after,
                      const std::vector<openvdb::Vec3I>& tris, const std::vector<std::uint8_t>& alive,
                      double min_cos) {
    for (;;) {
        std::vector<std::uint32_t> undo;
        for (std::size_t t = 0; t < tris.size(); ++t) {
            if (!alive[t]) continue;
            const openvdb::Vec3I& c = tris[t];
            bool moved = false;
            for (int k = 0; k < 3; ++k) moved = moved || after[c[k]] != before[c[k]];
            if (!moved) continue;
            const Vec3d nb = (before[c[1]] - before[c[0]]).cross(before[c[2]] - before[c[0]]);
            const Vec3d na = (after[c[1]] - after[c[0]]).cross(after[c[2]] - after[c[0]]);
            if (turn_ok(nb, na, min_cos)) continue;
            for (int k = 0; k < 3; ++k)
                if (after[c[k]] != before[c[k]]) undo.push_back(std::uint32_t(c[k]));
        }
        if (undo.empty()) return;
        for (std::uint32_t v : undo) after[v] = before[v];
    }
}

}  // namespace

std::size_t relax_tangentially(std::vector<Vec3d>& points, const std::vector<openvdb::Vec3I>& tris,
                               const std::vector<std::uint8_t>& alive, const std::vector<std::uint8_t>& movable,
                               const RelaxLimits& limits) {
    if (limits.sweeps <= 0) return 0;
    const Fans fans = build_fans(points.size(), tris, alive);
    const std::vector<std::uint8_t> fixed = fixed_vertices(tris, alive, movable);
    const double min_cos = std::cos(limits.max_turn_degrees * M_PI / 180);
    std::vector<std::uint8_t> moved(points.size(), 0);
    for (int sweep = 0; sweep < limits.sweeps; ++sweep) {
        std::vector<Vec3d> next(points);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points.size(), 1024), [&](const auto& r) {
            std::vector<std::uint32_t> ring;
            for (std::size_t v = r.begin(); v != r.end(); ++v)
                if (!fixed[v] && fans.begin[v] < fans.begin[v + 1])
                    next[v] = relaxed(std::uint32_t(v), points, tris, fans, limits, min_cos, ring);
        });
        undo_joint_turns(points, next, tris, alive, min_cos);
        for (std::size_t v = 0; v < points.size(); ++v) moved[v] |= next[v] != points[v];
        points.swap(next);
    }
    return std::size_t(std::count(moved.begin(), moved.end(), std::uint8_t(1)));
}

}  // namespace pqdc::adaptive_detail
