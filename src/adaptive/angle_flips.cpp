// Edge flips that raise the smallest angle of nearly flat triangle pairs:
// the classic Delaunay flip (Lawson 1977) restricted to a surface, as in
// remeshing (Botsch & Kobbelt 2004, "A remeshing approach to multiresolution
// modeling"; pmp-library's remeshing.cpp flips for valence instead). Only
// pairs whose normals agree within a small fold angle are flipped, so
// creases and corners that the quadrics placed stay where they are. The one
// exception is a fold (Flipper::unfolds): a flap, tilted or facing inward,
// told from a crease by the field's gradient.
//
// Half-edge h = 3 t + k runs from tris[t][k] to tris[t][(k + 1) % 3]; twins
// are found once by sorting, and a flip rewires the four outer twins. Each
// vertex keeps its triangles (with some slack), which tells whether the new
// edge exists already, also around border and non-manifold vertices. Sweeps
// visit, in index order, the triangles that changed or border a change in
// the previous sweep (all of them in the first).

#include "adaptive/angle_flips.hpp"

#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace pqdc::adaptive_detail {
namespace {

using Vec3d = openvdb::Vec3d;
constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();
constexpr std::uint32_t kFanSlack = 4;  // room for triangles a vertex gains by flips
constexpr double kGradientStep = 1.0 / 64;  // voxels; see Flipper::unfolds

/// Cosine of the triangle's smallest angle (1 when degenerate): the larger,
/// the thinner.
double thinness(const Vec3d& p, const Vec3d& q, const Vec3d& r) {
    const Vec3d corner[3] = {p, q, r};
    double worst = -1;
    for (int k = 0; k < 3; ++k) {
        const Vec3d u = corner[(k + 1) % 3] - corner[k], v = corner[(k + 2) % 3] - corner[k];
        const double len = std::sqrt(u.lengthSqr() * v.lengthSqr());
        if (!(len > 0)) return 1;
        worst = std::max(worst, u.dot(v) / len);
    }
    return worst;
}

Vec3d unit_normal(const Vec3d& p, const Vec3d& q, const Vec3d& r) {
    const Vec3d n = (q - p).cross(r - p);
    const double len = n.length();
    return len > 0 ? n / len : Vec3d(0.0);
}

class Flipper {
public:
    Flipper(const std::vector<Vec3d>& points, std::vector<openvdb::Vec3I>& tris, const std::vector<std::uint8_t>& alive,
            FieldProbe* field, const AngleFlipLimits& limits)
        : points_(points), tris_(tris), field_(field), min_cos_(std::cos(limits.max_fold_degrees * M_PI / 180)) {
        find_twins(alive);
        build_fans(alive);
    }

    std::uint32_t twin(std::uint32_t h) const { return twin_[h]; }
    std::uint32_t from(std::uint32_t h) const { return tris_[h / 3][h % 3]; }
    std::uint32_t to(std::uint32_t h) const { return tris_[h / 3][(h % 3 + 1) % 3]; }

    /// Flips half-edge h and its twin when that makes the pair fatter and
    /// the limits allow it.
    bool try_flip(std::uint32_t h) {
        const std::uint32_t g = twin_[h];
        if (g == kNone) return false;
        const std::uint32_t t = h / 3, u = g / 3;
        const int k = int(h % 3), j = int(g % 3);
        const std::uint32_t a = tris_[t][k], b = tris_[t][(k + 1) % 3], c = tris_[t][(k + 2) % 3];
        const std::uint32_t d = tris_[u][(j + 2) % 3];
        if (t == u || c == d || connected(c, d) || !fan_has_room(c) || !fan_has_room(d)) return false;
        const Vec3d &pa = points_[a], &pb = points_[b], &pc = points_[c], &pd = points_[d];
        const Vec3d n1 = unit_normal(pa, pb, pc), n2 = unit_normal(pb, pa, pd);
        const Vec3d m1 = unit_normal(pc, pa, pd), m2 = unit_normal(pd, pb, pc);
        if (!(m1.dot(m2) >= min_cos_)) return false;
        if (n1.dot(n2) >= min_cos_) {
            if (!(m1.dot(n1) >= min_cos_ && m1.dot(n2) >= min_cos_ && m2.dot(n1) >= min_cos_ && m2.dot(n2) >= min_cos_))
                return false;
            const double before = std::max(thinness(pa, pb, pc), thinness(pb, pa, pd));
            const double after = std::max(thinness(pc, pa, pd), thinness(pd, pb, pc));
            if (!(after < before - 1e-12)) return false;
        } else if (!unfolds(pa, pb, pc, pd, n1, n2, m1, m2)) {
            return false;
        }
        // Outer twins: t's b->c and c->a, u's a->d and d->b.
        const std::uint32_t bc = twin_[3 * t + std::uint32_t((k + 1) % 3)], ca = twin_[3 * t + std::uint32_t((k + 2) % 3)];
        const std::uint32_t ad = twin_[3 * u + std::uint32_t((j + 1) % 3)], db = twin_[3 * u + std::uint32_t((j + 2) % 3)];
        tris_[t] = openvdb::Vec3I(c, a, d);  // c->a, a->d, d->c
        tris_[u] = openvdb::Vec3I(d, b, c);  // d->b, b->c, c->d
        link(3 * t + 0, ca);
        link(3 * t + 1, ad);
        link(3 * t + 2, 3 * u + 2);
        link(3 * u + 0, db);
        link(3 * u + 1, bc);
        fan_remove(a, u);
        fan_remove(b, t);
        fan_add(c, u);
        fan_add(d, t);
        return true;
    }

private:
    /// Whether the pair (a, b, c), (b, a, d), whose normals differ by more
    /// than the limit while the flipped pair's do not, is a fold: the
    /// flipped pair follows the field better, its worse face normal closer
    /// to the field's gradient than the old pair's worse one. Dual cells of
    /// different sizes leave such flaps, tilted or facing inward, the four
    /// corners nearly coplanar and split along the diagonal outside their
    /// quadrilateral. A crease along a-b also has a flat flipped pair (the
    /// chamfer) when c and d lie across from each other, but its two faces
    /// follow the field and the chamfer does not: it stays. The gradient's
    /// differences are kGradientStep apart, so that near a crease they see
    /// its side of it (half a voxel blended both sides and flipped a
    /// 90-degree crease in the unit test).
    bool unfolds(const Vec3d& pa, const Vec3d& pb, const Vec3d& pc, const Vec3d& pd, const Vec3d& n1,
                 const Vec3d& n2, const Vec3d& m1, const Vec3d& m2) const {
        if (!field_) return false;
        // Cosine of the angle between unit normal n and the gradient at the
        // triangle's centroid (-2 where the gradient vanishes: no evidence).
        auto follows = [this](const Vec3d& p, const Vec3d& q, const Vec3d& r, const Vec3d& n) {
            const Vec3d g = field_gradient(*field_, (p + q + r) / 3.0, kGradientStep);
            const double len = g.length();
            return len > 0 && std::isfinite(len) ? n.dot(g) / len : -2.0;
        };
        const double now = std::min(follows(pa, pb, pc, n1), follows(pb, pa, pd, n2));
        const double flipped = std::min(follows(pc, pa, pd, m1), follows(pd, pb, pc, m2));
        return flipped > now + 1e-9 && flipped > 0;
    }

    void link(std::uint32_t h, std::uint32_t g) {
        twin_[h] = g;
        if (g != kNone) twin_[g] = h;
    }

    /// Whether an edge c-d exists: d is a corner of a triangle around c.
    bool connected(std::uint32_t c, std::uint32_t d) const {
        for (std::uint32_t i = 0; i < fan_count_[c]; ++i) {
            const openvdb::Vec3I& x = tris_[fan_[fan_begin_[c] + i]];
            if (x[0] == d || x[1] == d || x[2] == d) return true;
        }
        return false;
    }
    bool fan_has_room(std::uint32_t v) const { return fan_count_[v] < fan_begin_[v + 1] - fan_begin_[v]; }
    void fan_remove(std::uint32_t v, std::uint32_t t) {
        std::uint32_t* f = fan_.data() + fan_begin_[v];
        std::uint32_t& n = fan_count_[v];
        for (std::uint32_t i = 0; i < n; ++i)
            if (f[i] == t) {
                f[i] = f[--n];
                return;
            }
    }
    void fan_add(std::uint32_t v, std::uint32_t t) { fan_[fan_begin_[v] + fan_count_[v]++] = t; }

    /// Triangles around each vertex, with room for kFanSlack more: a flip
    /// adds one triangle to two fans, and a full fan refuses the flip.
    void build_fans(const std::vector<std::uint8_t>& alive) {
        fan_begin_.assign(points_.size() + 1, 0);
        fan_count_.assign(points_.size(), 0);
        for (std::uint32_t t = 0; t < tris_.size(); ++t)
            if (alive[t])
                for (int k = 0; k < 3; ++k) ++fan_begin_[tris_[t][k] + 1];
        for (std::size_t v = 0; v < points_.size(); ++v) fan_begin_[v + 1] += fan_begin_[v] + kFanSlack;
        fan_.resize(fan_begin_.back());
        for (std::uint32_t t = 0; t < tris_.size(); ++t)
            if (alive[t])
                for (int k = 0; k < 3; ++k) fan_add(tris_[t][k], t);
    }

    void find_twins(const std::vector<std::uint8_t>& alive) {
        twin_.assign(3 * tris_.size(), kNone);
        // (undirected edge, half-edge): an edge with exactly two opposite
        // half-edges gets twins; a non-manifold one (more) gets none.
        std::vector<std::pair<std::uint64_t, std::uint32_t>> edges;
        edges.reserve(3 * tris_.size());
        for (std::uint32_t t = 0; t < tris_.size(); ++t)
            if (alive[t])
                for (std::uint32_t k = 0; k < 3; ++k) {
                    const std::uint32_t a = tris_[t][k], b = tris_[t][(k + 1) % 3];
                    edges.emplace_back(std::uint64_t(std::min(a, b)) << 32 | std::max(a, b), 3 * t + k);
                }
        tbb::parallel_sort(edges.begin(), edges.end());
        for (std::size_t i = 0; i < edges.size();) {
            std::size_t j = i;
            while (j < edges.size() && edges[j].first == edges[i].first) ++j;
            const std::uint32_t h = edges[i].second, g = edges[i + 1 < j ? i + 1 : i].second;
            if (j - i == 2 && from(h) == to(g) && to(h) == from(g)) link(h, g);
            i = j;
        }
    }

    const std::vector<Vec3d>& points_;
    std::vector<openvdb::Vec3I>& tris_;
    FieldProbe* field_;
    double min_cos_;
    std::vector<std::uint32_t> twin_;
    std::vector<std::uint32_t> fan_begin_, fan_count_, fan_;
};

}  // namespace

std::size_t flip_for_angles(const std::vector<Vec3d>& points, std::vector<openvdb::Vec3I>& tris,
                            const std::vector<std::uint8_t>& alive, const std::vector<std::uint8_t>& frozen,
                            std::vector<std::uint8_t>& changed, FieldProbe* field, const AngleFlipLimits& limits) {
    Flipper flipper(points, tris, alive, field, limits);
    std::vector<std::uint32_t> sweep, next;
    for (std::uint32_t t = 0; t < tris.size(); ++t)
        if (alive[t] && !frozen[t]) sweep.push_back(t);
    std::vector<std::uint8_t> queued(tris.size(), 0);
    std::size_t flips = 0;
    for (int s = 0; s < limits.max_sweeps && !sweep.empty(); ++s) {
        next.clear();
        auto enqueue = [&](std::uint32_t t) {
            if (!queued[t] && !frozen[t]) {
                queued[t] = 1;
                next.push_back(t);
            }
        };
        for (std::uint32_t t : sweep)
            for (std::uint32_t k = 0; k < 3; ++k) {
                const std::uint32_t h = 3 * t + k, g = flipper.twin(h);
                if (g == kNone || frozen[g / 3] || !flipper.try_flip(h)) continue;
                ++flips;
                for (std::uint32_t x : {t, g / 3}) {
                    changed[x] = 1;
                    enqueue(x);
                    for (std::uint32_t i = 0; i < 3; ++i)
                        if (const std::uint32_t o = flipper.twin(3 * x + i); o != kNone) enqueue(o / 3);
                }
                break;  // t changed: its other edges wait for the next sweep
            }
        std::sort(next.begin(), next.end());
        for (std::uint32_t t : next) queued[t] = 0;
        sweep.swap(next);
    }
    return flips;
}

}  // namespace pqdc::adaptive_detail
