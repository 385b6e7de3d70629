// Why this step exists: surface leaves count as inside in the dual marching
// cubes step (polygonize.cpp, step 1), so a crossing sits on a surface leaf
// only where the leaf borders an outside leaf. Along a concave crease the
// crease cells' neighbours across the crease are surface leaves too: the
// loops there join the two faces' vertices directly and cut the crease off,
// the crease cells' vertices (which the quadrics put on the crease) unused.
// Measured on the clean CSG part and fandisk before this step: convex
// creases 0.03-0.05 voxel off, concave ones 0.51-0.90 (uniform quads: 0.04-0.08).
// Relabelling those leaves outside instead gave the uniform quads where the
// crease runs along the lattice, but along oblique creases it made thin
// outside tubes whose crossings all sit on the tube's leaves (pinched,
// back-to-back triangles that no collapse may merge). An edge split keeps
// the mesh a closed 2-manifold whatever the configuration.
#include "adaptive/crease_splits.hpp"

#include "adaptive/triangle_fans.hpp"

#include "measure/box_grid.hpp"
#include "measure/mesh_internal.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace pqdc::adaptive_detail {
namespace {

using openvdb::Vec3d;
using openvdb::Vec3I;

constexpr double kOutsideVoxels = 0.1;  ///< an edge's midpoint must lie this far outside
constexpr double kReachVoxels = 1.5;    ///< how far from the edge a point may be
// Each pass splits a triangle at most once; a second pass reached the
// crease vertices whose edge the first had taken (one pass: CSG part 0.088
// instead of 0.076 voxel at 128 cells).
constexpr int kPasses = 2;

std::uint64_t cell_key(const Vec3d& p) {
    const openvdb::Coord c = openvdb::Coord::floor(p);
    auto axis = [](int v) { return std::uint64_t(std::uint32_t(v + (1 << 20)) & 0x1fffff); };
    return axis(c.x()) << 42 | axis(c.y()) << 21 | axis(c.z());
}

Vec3d normal_of(const Vec3d& a, const Vec3d& b, const Vec3d& c) { return (b - a).cross(c - a); }

/// Triangles around each vertex and vertices by voxel, rebuilt per pass.
class Neighbourhood {
public:
    Neighbourhood(const std::vector<Vec3d>& points, const std::vector<Vec3I>& tris, const std::vector<std::uint8_t>& alive)
        : fans_(build_fans(points.size(), tris, alive)) {
        for (std::uint32_t v = 0; v < points.size(); ++v)
            if (fans_.begin[v] < fans_.begin[v + 1]) cells_.emplace_back(cell_key(points[v]), v);
        std::sort(cells_.begin(), cells_.end());
    }

    /// Calls visit(v) for the vertices in the 27 voxels around p.
    template <class Visit>
    void near(const Vec3d& p, Visit&& visit) const {
        for (int dz = -1; dz <= 1; ++dz)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    const std::uint64_t key = cell_key(p + Vec3d(dx, dy, dz));
                    auto it = std::lower_bound(cells_.begin(), cells_.end(), std::make_pair(key, std::uint32_t(0)));
                    for (; it != cells_.end() && it->first == key; ++it) visit(it->second);
                }
    }
    const std::uint32_t* fan_begin(std::uint32_t v) const { return fans_.triangle.data() + fans_.begin[v]; }
    const std::uint32_t* fan_end(std::uint32_t v) const { return fans_.triangle.data() + fans_.begin[v + 1]; }

private:
    Fans fans_;
    std::vector<std::pair<std::uint64_t, std::uint32_t>> cells_;
};

/// The two triangles on edge a-b as (a, b, x) and (b, a, y), rotated so:
/// false unless exactly two alive, untouched triangles hold the edge, in
/// opposite directions.
bool edge_pair(const Neighbourhood& nb, const std::vector<Vec3I>& tris, const std::vector<std::uint8_t>& touched,
               std::uint32_t a, std::uint32_t b, std::uint32_t& t1, std::uint32_t& t2) {
    int found = 0;
    t1 = t2 = std::numeric_limits<std::uint32_t>::max();
    for (const std::uint32_t* t = nb.fan_begin(a); t != nb.fan_end(a); ++t) {
        const Vec3I& f = tris[*t];
        for (int k = 0; k < 3; ++k) {
            if (f[k] == a && f[(k + 1) % 3] == b) t1 = *t, ++found;
            if (f[k] == b && f[(k + 1) % 3] == a) t2 = *t, ++found;
        }
    }
    return found == 2 && t1 != std::numeric_limits<std::uint32_t>::max() &&
           t2 != std::numeric_limits<std::uint32_t>::max() && !touched[t1] && !touched[t2];
}

std::uint32_t apex(const Vec3I& f, std::uint32_t a, std::uint32_t b) {
    for (int k = 0; k < 3; ++k)
        if (f[k] != a && f[k] != b) return f[k];
    return f[0];
}

/// Whether one of the first `ours` triangles of `local` meets another of
/// its triangles: find_self_intersections' answer for the pairs that hold
/// one of ours (its classification and exact test; degenerate triangles take
/// part in no pair), without the finder's set-up for a few dozen triangles.
bool ours_meet_any(const Mesh& local, std::size_t ours) {
    const std::size_t n = local.triangles.size();
    std::vector<std::uint8_t> usable(n);
    std::vector<detail::Box> box(n);  // the finder's boxes: rounded outwards, so no meeting pair is missed
    for (std::size_t t = 0; t < n; ++t) {
        usable[t] = detail::classify_split_triangle(local, local.points, t) == 0;
        const Vec3I& c = local.triangles[t];
        box[t] = detail::bounding_box(local.points[c[0]], local.points[c[1]], local.points[c[2]]);
    }
    for (std::size_t a = 0; a < std::min(ours, n); ++a) {
        if (!usable[a]) continue;
        for (std::size_t b = a + 1; b < n; ++b)
            if (usable[b] && detail::boxes_overlap(box[a], box[b]) &&
                detail::split_triangles_intersect(local, local.points, a, b))
                return true;
    }
    return false;
}

/// Whether the triangles `changed` (as they are now in `tris`) and `extra`
/// intersect any alive triangle with a corner in the 27 voxels around p: a
/// split or flip is kept only when they do not.
bool meets_neighbours(const Neighbourhood& nb, const Vec3d& p, const std::vector<Vec3d>& points,
                      const std::vector<Vec3I>& tris, const std::vector<std::uint8_t>& alive,
                      const std::vector<std::uint32_t>& changed, const std::vector<Vec3I>& extra) {
    std::vector<std::uint32_t> faces(changed);
    nb.near(p, [&](std::uint32_t v) {
        for (const std::uint32_t* t = nb.fan_begin(v); t != nb.fan_end(v); ++t)
            if (alive[*t]) faces.push_back(*t);
    });
    std::sort(faces.begin() + std::ptrdiff_t(changed.size()), faces.end());
    faces.erase(std::unique(faces.begin() + std::ptrdiff_t(changed.size()), faces.end()), faces.end());
    Mesh local;
    std::vector<std::pair<std::uint32_t, std::uint32_t>> index;  // (global, local), sorted
    auto local_of = [&](std::uint32_t g) {
        auto it = std::lower_bound(index.begin(), index.end(), std::make_pair(g, std::uint32_t(0)));
        if (it != index.end() && it->first == g) return it->second;
        const std::uint32_t l = std::uint32_t(local.points.size());
        local.points.push_back(g < points.size() ? points[g] : p);  // a split's new vertex: p
        index.insert(it, {g, l});
        return l;
    };
    // The changed and extra triangles first (local numbers below `ours`),
    // then the others, each once.
    std::vector<Vec3I> ordered(extra);
    for (std::uint32_t t : changed) ordered.push_back(tris[t]);
    const std::size_t ours = ordered.size();
    for (std::size_t i = changed.size(); i < faces.size(); ++i)
        if (std::find(changed.begin(), changed.end(), faces[i]) == changed.end()) ordered.push_back(tris[faces[i]]);
    for (const Vec3I& t : ordered) local.triangles.emplace_back(local_of(t[0]), local_of(t[1]), local_of(t[2]));
    return ours_meet_any(local, ours);
}

/// Outside distance (voxels) of the midpoint of p-q, 0 when inside.
double outside_voxels(FieldProbe& probe, const Vec3d& p, const Vec3d& q) {
    const Vec3d m = 0.5 * (p + q);
    if (!(probe.value(m) > 0)) return 0;
    const double d = field_distance_voxels(probe, m, field_gradient_length(probe, m));
    return std::isfinite(d) ? d : 0;
}

/// The edge to split for point h: the nearest one whose midpoint lies
/// outside (reach: the distance from h to the edge).
struct Choice {
    std::uint32_t a = 0, b = 0;
    double reach = 0;
    bool found = false;
};

Choice choose_edge(const Vec3d& h, const Neighbourhood& nb, const std::vector<Vec3d>& points,
                   const std::vector<Vec3I>& tris, FieldProbe& probe) {
    Choice best;
    nb.near(h, [&](std::uint32_t v) {
        for (const std::uint32_t* t = nb.fan_begin(v); t != nb.fan_end(v); ++t) {
            const Vec3I& f = tris[*t];
            for (int k = 0; k < 3; ++k) {
                const std::uint32_t a = f[k], b = f[(k + 1) % 3];
                if (a != v || a > b) continue;  // each undirected edge once per vertex
                const Vec3d pa = points[a], pb = points[b], ab = pb - pa;
                const double len2 = ab.lengthSqr();
                if (!(len2 > 0)) continue;
                const double s = (h - pa).dot(ab) / len2;
                if (s < 0.15 || s > 0.85) continue;
                const double reach = (pa + ab * s - h).length();
                if (reach > kReachVoxels || (best.found && reach >= best.reach)) continue;
                if (outside_voxels(probe, pa, pb) > kOutsideVoxels) best = Choice{a, b, reach, true};
            }
        }
    });
    return best;
}

/// Around each split vertex v, the edges opposite v that still cut the
/// crease (midpoint more than kOutsideVoxels outside) are flipped to join v
/// to the vertex across, when that edge's midpoint lies within half as far
/// and both new triangles face as the old pair did: along a crease this
/// joins consecutive crease vertices. Returns the flips.
std::size_t flip_towards(const std::vector<std::uint32_t>& split_vertices, FieldProbe& probe,
                         const std::vector<Vec3d>& points, std::vector<Vec3I>& tris, const std::vector<std::uint8_t>& alive,
                         std::vector<std::uint8_t>& changed) {
    std::size_t flips = 0;
    for (int pass = 0; pass < 2; ++pass) {
        const Neighbourhood nb(points, tris, alive);
        std::vector<std::uint8_t> touched(tris.size(), 0);
        for (const std::uint32_t v : split_vertices)
            for (const std::uint32_t* it = nb.fan_begin(v); it != nb.fan_end(v); ++it) {
                if (touched[*it]) continue;
                const Vec3I f = tris[*it];
                int k = 0;
                while (f[k] != v) ++k;
                const std::uint32_t a = f[(k + 1) % 3], b = f[(k + 2) % 3];
                std::uint32_t t1, t2;
                if (!edge_pair(nb, tris, touched, a, b, t1, t2)) continue;
                const std::uint32_t d = apex(tris[t2], a, b);
                bool joined = d == v;
                for (const std::uint32_t* g = nb.fan_begin(v); g != nb.fan_end(v) && !joined; ++g)
                    joined = tris[*g][0] == d || tris[*g][1] == d || tris[*g][2] == d;
                if (joined) continue;
                const double cut = outside_voxels(probe, points[a], points[b]);
                if (!(cut > kOutsideVoxels) || !(outside_voxels(probe, points[v], points[d]) < 0.5 * cut)) continue;
                const Vec3d n = normal_of(points[a], points[b], points[v]) + normal_of(points[b], points[a], points[d]);
                if (!(normal_of(points[v], points[a], points[d]).dot(n) > 0 &&
                      normal_of(points[d], points[b], points[v]).dot(n) > 0))
                    continue;
                const Vec3I old1 = tris[t1], old2 = tris[t2];
                tris[t1] = Vec3I(v, a, d);
                tris[t2] = Vec3I(d, b, v);
                if (meets_neighbours(nb, points[v], points, tris, alive, {t1, t2}, {})) {
                    tris[t1] = old1;
                    tris[t2] = old2;
                    continue;
                }
                changed[t1] = changed[t2] = touched[t1] = touched[t2] = 1;
                ++flips;
            }
    }
    return flips;
}

}  // namespace

double concavity(FieldProbe& probe, const Vec3d& p) {
    const double g = field_gradient_length(probe, p);
    if (!(g > 0)) return 0;
    const double r = 1.0 / std::sqrt(3.0);
    const Vec3d dirs[14] = {{1, 0, 0},  {-1, 0, 0}, {0, 1, 0},   {0, -1, 0},  {0, 0, 1},   {0, 0, -1},  {r, r, r},
                            {r, r, -r}, {r, -r, r}, {r, -r, -r}, {-r, r, r}, {-r, r, -r}, {-r, -r, r}, {-r, -r, -r}};
    double sum = 0;
    for (const Vec3d& d : dirs) sum += probe.value(p + d);
    const double c = (probe.value(p) - sum / 14.0) / g;
    return std::isfinite(c) ? c : 0.0;
}

std::size_t split_at_concave_creases(const std::vector<Vec3d>& hidden, FieldProbe& probe, std::vector<Vec3d>& points,
                                     std::vector<Vec3I>& tris, std::vector<std::uint8_t>& alive,
                                     std::vector<std::uint8_t>& changed) {
    std::size_t splits = 0;
    if (hidden.empty()) return 0;
    std::vector<std::uint8_t> done(hidden.size(), 0);
    std::vector<std::uint32_t> split_vertices;
    for (int pass = 0; pass < kPasses; ++pass) {
        const Neighbourhood nb(points, tris, alive);
        std::vector<std::uint8_t> touched(tris.size(), 0);
        for (std::size_t i = 0; i < hidden.size(); ++i) {
            if (done[i]) continue;
            const Vec3d& h = hidden[i];
            const Choice c = choose_edge(h, nb, points, tris, probe);
            std::uint32_t t1, t2;
            if (!c.found || !edge_pair(nb, tris, touched, c.a, c.b, t1, t2)) continue;
            const std::uint32_t a = c.a, b = c.b, x = apex(tris[t1], a, b), y = apex(tris[t2], a, b);
            const Vec3d &pa = points[a], &pb = points[b], &px = points[x], &py = points[y];
            const Vec3d n1 = normal_of(pa, pb, px), n2 = normal_of(pb, pa, py);
            if (!(normal_of(pa, h, px).dot(n1) > 0 && normal_of(h, pb, px).dot(n1) > 0 &&
                  normal_of(pb, h, py).dot(n2) > 0 && normal_of(h, pa, py).dot(n2) > 0))
                continue;
            // The new vertex gets the next index: meets_neighbours places
            // an index past the points at h.
            const std::uint32_t v = std::uint32_t(points.size());
            const Vec3I old1 = tris[t1], old2 = tris[t2];
            tris[t1] = Vec3I(a, v, x);
            tris[t2] = Vec3I(b, v, y);
            if (meets_neighbours(nb, h, points, tris, alive, {t1, t2}, {Vec3I(v, b, x), Vec3I(v, a, y)})) {
                tris[t1] = old1;
                tris[t2] = old2;
                continue;
            }
            points.push_back(h);
            tris.emplace_back(v, b, x);
            tris.emplace_back(v, a, y);
            alive.resize(tris.size(), 1);
            changed.resize(tris.size(), 0);
            touched.resize(tris.size(), 0);
            for (std::uint32_t t : {t1, t2, std::uint32_t(tris.size() - 2), std::uint32_t(tris.size() - 1)})
                changed[t] = touched[t] = 1;
            done[i] = 1;
            split_vertices.push_back(v);
            ++splits;
        }
    }
    if (!split_vertices.empty()) flip_towards(split_vertices, probe, points, tris, alive, changed);
    return splits;
}

}  // namespace pqdc::adaptive_detail
