#include "pqdc/self_intersections.hpp"

#include "pqdc/exceptions.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/procedural.hpp"

#include "geometry/exact_predicates.hpp"
#include "measure/flat_stars.hpp"
#include "measure/mesh_internal.hpp"

#include <catch2/catch.hpp>

#include <openvdb/tree/LeafManager.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <set>
#include <utility>
#include <vector>

#ifdef PQDC_HAVE_CGAL
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/self_intersections.h>
#include <CGAL/Surface_mesh.h>
#endif

namespace {

using openvdb::Vec3d;
using Pairs = std::vector<std::pair<std::size_t, std::size_t>>;

pqdc::Mesh two_triangles(const std::vector<Vec3d>& points, openvdb::Vec3I a, openvdb::Vec3I b) {
    pqdc::Mesh m;
    m.points = points;
    m.triangles = {a, b};
    return m;
}

bool pair_intersects(const std::vector<Vec3d>& points, openvdb::Vec3I a, openvdb::Vec3I b) {
    const pqdc::SelfIntersections r = pqdc::find_self_intersections(two_triangles(points, a, b));
    REQUIRE(r.degenerate_triangles.empty());
    return r.pair_count == 1;
}

/// Brute force: every pair alone, as a two-triangle mesh (same point array,
/// so shared indices stay shared). Independent of the tree.
Pairs brute_force(const pqdc::Mesh& mesh, const std::vector<std::size_t>& degenerate) {
    const std::set<std::size_t> skip(degenerate.begin(), degenerate.end());
    Pairs pairs;
    for (std::size_t i = 0; i < mesh.triangles.size(); ++i)
        for (std::size_t j = i + 1; j < mesh.triangles.size(); ++j) {
            if (skip.count(i) || skip.count(j)) continue;
            if (pqdc::find_self_intersections(two_triangles(mesh.points, mesh.triangles[i], mesh.triangles[j])).pair_count)
                pairs.emplace_back(i, j);
        }
    return pairs;
}

/// Triangles over a pool of points. Snapped pools put points on a coarse
/// dyadic lattice, so exact coplanarity, collinearity, touching and shared
/// positions under different indices are common.
pqdc::Mesh random_soup(std::mt19937& rng, std::size_t triangles, std::size_t pool, bool snapped) {
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::uniform_int_distribution<unsigned> pick(0, unsigned(pool - 1));
    pqdc::Mesh m;
    for (std::size_t i = 0; i < pool; ++i) {
        Vec3d p(u(rng), u(rng), u(rng));
        if (snapped)
            for (int k = 0; k < 3; ++k) p[k] = std::round(p[k] * 4.0) / 4.0;
        m.points.push_back(p);
    }
    for (std::size_t t = 0; t < triangles; ++t) {
        const unsigned a = pick(rng), b = pick(rng), c = pick(rng);
        // Small triangles, so the tree has something to prune: the other two
        // corners near the first one (or, snapped, within one lattice step).
        if (snapped || t % 3 == 0) {
            m.triangles.emplace_back(a, b, c);
        } else {
            const Vec3d base = m.points[a];
            const unsigned nb = unsigned(m.points.size());
            for (int k = 0; k < 2; ++k)
                m.points.push_back(base + Vec3d(u(rng) - 0.5, u(rng) - 0.5, u(rng) - 0.5) * 0.3);
            m.triangles.emplace_back(a, nb, t % 3 == 1 ? nb + 1 : b);
        }
    }
    return m;
}

}  // namespace

TEST_CASE("orientation predicates are exact near degeneracy", "[self-intersections]") {
    using pqdc::detail::orient2d;
    using pqdc::detail::orient3d;
    // Kettner et al., "Classroom examples of robustness problems": p near the
    // line through q and r, one ulp steps apart. The exact sign is sign(j - i)
    // (the determinant is 12 u (j - i)); plain double evaluation gets many wrong.
    const double ulp = 0x1.0p-53;
    int naive_wrong = 0;
    for (int i = 0; i < 64; ++i)
        for (int j = 0; j < 64; ++j) {
            const double px = 0.5 + i * ulp, py = 0.5 + j * ulp;
            const int expected = (j > i) - (j < i);
            CHECK(orient2d(px, py, 12, 12, 24, 24) == expected);
            CHECK(pqdc::detail::orient2d_exact(px, py, 12, 12, 24, 24) == expected);
            const double naive = (px - 24) * (12 - 24) - (py - 24) * (12 - 24);
            naive_wrong += ((naive > 0) - (naive < 0)) != expected;
        }
    CHECK(naive_wrong > 0);  // the case really needs the exact path

    // orient3d against the plane z = x: linear in p, zero on the plane, so
    // its sign is a fixed sign times sign(pz - px).
    const Vec3d a(12, 0, 12), b(24, 0, 24), c(0, 7, 0);
    const int k = orient3d(a, b, c, Vec3d(0, 0, 1));
    REQUIRE(k != 0);
    for (int i = -20; i <= 20; ++i)
        for (int j = -20; j <= 20; ++j) {
            const Vec3d p(0.5 + i * ulp, 0.25 + (i + j) * ulp, 0.5 + j * ulp);
            CHECK(orient3d(a, b, c, p) == k * ((j > i) - (j < i)));
        }
    // Extreme magnitudes skip the filter (no overflow or underflow assumed):
    // a point 1e-300 above the plane z = 0 is on the side of (0, 0, 1).
    CHECK(orient3d(Vec3d(0, 0, 0), Vec3d(1e300, 0, 0), Vec3d(0, 1e300, 0), Vec3d(1e-300, 1e-300, 1e-300)) ==
          orient3d(Vec3d(0, 0, 0), Vec3d(1, 0, 0), Vec3d(0, 1, 0), Vec3d(0, 0, 1)));
    CHECK(orient3d(Vec3d(0, 0, 0), Vec3d(1e300, 0, 0), Vec3d(0, 1e300, 0), Vec3d(5, 5, 0)) == 0);
    CHECK(orient3d(Vec3d(0, 0, 0), Vec3d(1e300, 0, 0), Vec3d(0, 1e300, 0), Vec3d(5, 5, -4.9e-324)) ==
          -orient3d(Vec3d(0, 0, 0), Vec3d(1, 0, 0), Vec3d(0, 1, 0), Vec3d(0, 0, 1)));
    CHECK(orient2d(0, 0, 4.9e-324, 0, 0, 4.9e-324) == 1);
    CHECK(orient2d(1e308, 1e308, -1e308, -1e308, 0, 0) == 0);

    // Filter + fallback agrees with the exact arithmetic on nearly coplanar
    // points (a corner rebuilt from the others by rounded affine sums).
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u(-1, 1);
    int zeros = 0;
    for (int n = 0; n < 4000; ++n) {
        const Vec3d p(u(rng), u(rng), u(rng)), q(u(rng), u(rng), u(rng)), r(u(rng), u(rng), u(rng));
        const double s = u(rng), t = u(rng);
        const Vec3d d = p + (q - p) * s + (r - p) * t;
        const int filtered = orient3d(p, q, r, d);
        REQUIRE(filtered == pqdc::detail::orient3d_exact(p, q, r, d));
        zeros += filtered == 0;
        const int f2 = orient2d(p[0], p[1], q[0], q[1], d[0], d[1]);
        REQUIRE(f2 == pqdc::detail::orient2d_exact(p[0], p[1], q[0], q[1], d[0], d[1]));
    }
    INFO("exactly coplanar cases: " << zeros);
}

TEST_CASE("the box-bounded orient2d filter agrees with exact signs at every scale", "[self-intersections]") {
    using pqdc::detail::BoxOrient2d;
    using pqdc::detail::orient2d_exact;
    // Kettner's near-collinear grid, at scales from tiny to huge and far from
    // the origin: the one bound per box must never decide a sign wrongly.
    const double ulp = 0x1.0p-53;
    int filter_decided = 0;
    for (double scale : {0x1.0p-260, 0x1.0p-200, 1e-9, 1.0, 3e5, 0x1.0p200, 0x1.0p260})
        for (double offset : {0.0, 1e6}) {
            const Vec3d q(offset + 12 * scale, offset + 12 * scale, 0), r(offset + 24 * scale, offset + 24 * scale, 0);
            const double width = (offset + 24 * scale) - (offset + 0.5 * scale);
            const BoxOrient2d orient(0, 1, width);
            for (int i = 0; i < 24; ++i)
                for (int j = 0; j < 24; ++j) {
                    const Vec3d p(offset + 0.5 * scale + i * ulp * scale, offset + 0.5 * scale + j * ulp * scale, 0);
                    REQUIRE(orient(p, q, r) == orient2d_exact(p[0], p[1], q[0], q[1], r[0], r[1]));
                }
        }
    // Random stars: nearly collinear triples (a point rebuilt by rounded
    // affine sums) and general ones, against the exact sign.
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> u(-1, 1);
    for (int n = 0; n < 20000; ++n) {
        const double scale = std::ldexp(1.0, int(u(rng) * 40));
        const Vec3d c(5 + u(rng) * scale, -3 + u(rng) * scale, 0), a(5 + u(rng) * scale, -3 + u(rng) * scale, 0);
        const double t = u(rng);
        const Vec3d b = n % 2 ? c + (a - c) * t : Vec3d(5 + u(rng) * scale, -3 + u(rng) * scale, 0);
        const double width = std::max({std::max({a[0], b[0], c[0]}) - std::min({a[0], b[0], c[0]}),
                                       std::max({a[1], b[1], c[1]}) - std::min({a[1], b[1], c[1]})});
        const BoxOrient2d orient(0, 1, width);
        const int exact = orient2d_exact(c[0], c[1], a[0], a[1], b[0], b[1]);
        REQUIRE(orient(c, a, b) == exact);
        // Decided by the filter alone where the determinant is clearly away from 0.
        const double det = (c[0] - b[0]) * (a[1] - b[1]) - (c[1] - b[1]) * (a[0] - b[0]);
        filter_decided += std::abs(det) > 1e-12 * width * width;
    }
    CHECK(filter_decided > 5000);
    // Non-finite widths and points go to the adaptive predicate.
    const double inf = std::numeric_limits<double>::infinity(), nan = std::numeric_limits<double>::quiet_NaN();
    CHECK(BoxOrient2d(0, 1, inf)(Vec3d(0, 0, 0), Vec3d(1, 0, 0), Vec3d(0, 1, 0)) == 1);
    CHECK(BoxOrient2d(0, 1, nan)(Vec3d(0, 0, 0), Vec3d(0, 1, 0), Vec3d(1, 0, 0)) == -1);
    CHECK(BoxOrient2d(0, 1, 1.0)(Vec3d(0, 0, 0), Vec3d(nan, 0, 0), Vec3d(1, 0, 0)) == 0);
}

TEST_CASE("turns_once_around: one turn, one direction, exactly", "[self-intersections]") {
    using pqdc::detail::BoxOrient2d;
    using pqdc::detail::turns_once_around;
    auto ring = [](int n, int turns, double radius, int skip_from = -1) {
        std::vector<Vec3d> out;
        for (int k = 0; k < n; ++k) {
            const double a = 2 * M_PI * turns * k / n + (k == skip_from ? M_PI : 0.0);
            out.emplace_back(radius * std::cos(a), radius * std::sin(a), 0.0);
        }
        return out;
    };
    const Vec3d c(0, 0, 0);
    auto turns = [&](const std::vector<Vec3d>& pts) {
        return turns_once_around(BoxOrient2d(0, 1, 4.0), c, pts.size(), [&](std::size_t k) -> const Vec3d& { return pts[k]; });
    };
    CHECK(turns(ring(6, 1, 1)) == 1);
    std::vector<Vec3d> reversed = ring(6, 1, 1);
    std::reverse(reversed.begin(), reversed.end());
    CHECK(turns(reversed) == -1);
    CHECK(turns(ring(9, 2, 1)) == 0);     // winds twice
    CHECK(turns(ring(8, 1, 1, 3)) == 0);  // one corner thrown across: an edge turns back
    // Corners exactly on c's horizontal line, on both sides (the half-open rule).
    const std::vector<Vec3d> square{{1, 0, 0}, {0, 1, 0}, {-1, 0, 0}, {0, -1, 0}};
    CHECK(turns(square) == 1);
    const std::vector<Vec3d> off{{2, 0, 0}, {3, 1, 0}, {2, 2, 0}};  // c outside the triangle
    CHECK(turns(off) == 0);
}

TEST_CASE("self-intersections: pairs with known answers", "[self-intersections]") {
    const double e = 1e-15;
    SECTION("disjoint, crossing, touching at a point") {
        const std::vector<Vec3d> p{{0, 0, 0}, {1, 0, 0}, {0, 1, 0},
                                   {0.2, 0.2, -1}, {0.3, 0.2, 1}, {0.25, 0.3, 1}};
        CHECK(pair_intersects(p, {0, 1, 2}, {3, 4, 5}));  // pierces
        std::vector<Vec3d> q = p;
        for (int k = 3; k < 6; ++k) q[k][0] += 2.0;
        CHECK_FALSE(pair_intersects(q, {0, 1, 2}, {3, 4, 5}));
        // A corner exactly on the other's interior, then 1e-15 above it.
        std::vector<Vec3d> t{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0.25, 0.25, 0}, {0.3, 0.3, 1}, {0.2, 0.4, 1}};
        CHECK(pair_intersects(t, {0, 1, 2}, {3, 4, 5}));
        t[3][2] = e;
        CHECK_FALSE(pair_intersects(t, {0, 1, 2}, {3, 4, 5}));
        t[3][2] = -e;
        CHECK(pair_intersects(t, {0, 1, 2}, {3, 4, 5}));
        // A corner exactly on the other's edge (different indices).
        t[3] = Vec3d(0.5, 0.5, 0);
        CHECK(pair_intersects(t, {0, 1, 2}, {3, 4, 5}));
        t[3] = Vec3d(0.5 + e, 0.5, 0);
        CHECK_FALSE(pair_intersects(t, {0, 1, 2}, {3, 4, 5}));
        // Same position, different index: they touch.
        std::vector<Vec3d> s{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 0, 0}, {2, 0, 0}, {2, 1, 1}};
        CHECK(pair_intersects(s, {0, 1, 2}, {3, 4, 5}));
    }
    SECTION("coplanar") {
        // On the tilted plane x + 2y + 4z = 1 with dyadic coordinates (exact).
        auto on_plane = [](double x, double y) { return Vec3d(x, y, (1 - x - 2 * y) / 4); };
        std::vector<Vec3d> p{on_plane(0, 0), on_plane(1, 0), on_plane(0, 1),
                             on_plane(0.25, 0.25), on_plane(2, 0.25), on_plane(0.25, 2)};
        CHECK(pair_intersects(p, {0, 1, 2}, {3, 4, 5}));  // overlapping
        p[3] = on_plane(0.5, 0.5);                         // corner on the hypotenuse
        p[4] = on_plane(2, 0.5);
        p[5] = on_plane(0.5, 2);
        CHECK(pair_intersects(p, {0, 1, 2}, {3, 4, 5}));
        p[3] = on_plane(0.5 + 0x1.0p-40, 0.5);  // a hair beyond it, same plane
        CHECK_FALSE(pair_intersects(p, {0, 1, 2}, {3, 4, 5}));
    }
    SECTION("shared edge") {
        std::vector<Vec3d> p{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}};
        CHECK_FALSE(pair_intersects(p, {0, 1, 2}, {2, 1, 3}));  // flat, opposite sides
        p[3] = Vec3d(1, 1, 0.5);
        CHECK_FALSE(pair_intersects(p, {0, 1, 2}, {2, 1, 3}));  // bent
        p[3] = Vec3d(0.25, 0.25, 0);                            // folded onto the first
        CHECK(pair_intersects(p, {0, 1, 2}, {2, 1, 3}));
        p[3] = Vec3d(0.25, 0.25, e);  // folded, 1e-15 above: only the edge is shared
        CHECK_FALSE(pair_intersects(p, {0, 1, 2}, {2, 1, 3}));
        CHECK(pair_intersects(p, {0, 1, 2}, {0, 1, 2}));  // duplicated face
    }
    SECTION("shared vertex") {
        std::vector<Vec3d> p{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0.2, 0.2, -1}, {0.3, 0.2, 1}};
        CHECK(pair_intersects(p, {0, 1, 2}, {0, 3, 4}));  // the opposite side pierces
        p[3] = Vec3d(-1, -0.5, 0.3);
        p[4] = Vec3d(-0.5, -1, 0.3);
        CHECK_FALSE(pair_intersects(p, {0, 1, 2}, {0, 3, 4}));  // fan around the vertex
        p[3] = Vec3d(0.5, 0.25, 0);  // coplanar, overlapping sector
        p[4] = Vec3d(0.25, 0.5, 0);
        CHECK(pair_intersects(p, {0, 1, 2}, {0, 3, 4}));
        p[3] = Vec3d(0.5, 0, 0);  // a side along the other's side: overlap on a segment
        p[4] = Vec3d(0.25, -0.5, 0);
        CHECK(pair_intersects(p, {0, 1, 2}, {0, 3, 4}));
        p[3] = Vec3d(0.5, -e, 0);  // 1e-15 off that side: only the vertex is shared
        CHECK_FALSE(pair_intersects(p, {0, 1, 2}, {0, 3, 4}));
        p[3] = Vec3d(-0.5, 0, 0);  // collinear sides pointing apart
        CHECK_FALSE(pair_intersects(p, {0, 1, 2}, {0, 3, 4}));
    }
}

TEST_CASE("self-intersections: degenerate triangles, quads, errors", "[self-intersections]") {
    pqdc::Mesh m;
    m.points = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {0, 1, 0}, {1, 1, 1e-15}};
    m.triangles = {{0, 1, 2}, {0, 0, 3}, {0, 1, 3}};  // collinear, repeated index, fine
    pqdc::SelfIntersections r = pqdc::find_self_intersections(m);
    CHECK(r.degenerate_triangles == std::vector<std::size_t>{0, 1});
    CHECK(r.pair_count == 0);
    CHECK_FALSE(r.none());

    pqdc::Mesh q;  // a quad is its triangles 0-1-2 and 0-2-3
    q.points = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
    q.quads = {{0, 1, 2, 3}};
    CHECK(pqdc::find_self_intersections(q).none());
    q.points[3] = Vec3d(0.75, 0.25, 0);  // folded over its 0-2 diagonal
    r = pqdc::find_self_intersections(q);
    CHECK(r.pair_count == 1);
    CHECK(r.pairs == Pairs{{0, 1}});
    CHECK(pqdc::face_of_triangle(q, 1) == 0);

    q.points[0][1] = std::numeric_limits<double>::quiet_NaN();  // both halves use point 0
    r = pqdc::find_self_intersections(q);
    CHECK(r.non_finite_triangle_count == 2);
    CHECK(r.pair_count == 0);
    CHECK_FALSE(r.none());
    q.points[0][1] = 0;
    q.quads[0][2] = 9;
    CHECK_THROWS_AS(pqdc::find_self_intersections(q), pqdc::input_error);
    pqdc::SelfIntersectionOptions bad;
    bad.leaf_triangles = 0;
    CHECK_THROWS_AS(pqdc::find_self_intersections(m, bad), pqdc::option_error);
}

TEST_CASE("self-intersections: the tree finds exactly the brute-force pairs", "[self-intersections]") {
    std::mt19937 rng(11);
    for (const bool snapped : {false, true}) {
        for (int round = 0; round < 3; ++round) {
            const pqdc::Mesh soup = random_soup(rng, snapped ? 120 : 220, snapped ? 40 : 300, snapped);
            const pqdc::SelfIntersections r = pqdc::find_self_intersections(soup);
            INFO("snapped " << snapped << " round " << round << " pairs " << r.pair_count);
            CHECK(r.pair_count == r.pairs.size());
            CHECK(r.pair_count > 0);
            CHECK(r.pairs == brute_force(soup, r.degenerate_triangles));
            pqdc::SelfIntersectionOptions tree;
            tree.broad_phase = pqdc::BroadPhase::tree;
            const pqdc::SelfIntersections t = pqdc::find_self_intersections(soup, tree);
            CHECK(t.broad_phase == pqdc::BroadPhase::tree);
            CHECK(t.pairs == r.pairs);
            pqdc::SelfIntersectionOptions options;
            options.leaf_triangles = 1;
            options.max_pairs = 5;
            const pqdc::SelfIntersections few = pqdc::find_self_intersections(soup, options);
            CHECK(few.pair_count == r.pair_count);
            CHECK(few.pairs == Pairs(r.pairs.begin(), r.pairs.begin() + std::min<std::size_t>(5, r.pairs.size())));
            {
                tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
                CHECK(pqdc::find_self_intersections(soup).pairs == r.pairs);
            }
        }
    }
}

/// Small triangles of similar size on a (jittered) lattice, many sharing
/// corners: the kind of mesh the grid broad phase is for.
pqdc::Mesh lattice_soup(std::mt19937& rng, int n, std::size_t triangles, double jitter, int nx = 0) {
    nx = nx ? nx : n;  // points along x
    std::uniform_real_distribution<double> u(-jitter, jitter);
    std::uniform_int_distribution<int> at(0, n - 1), at_x(0, nx - 1), step(-1, 1);
    pqdc::Mesh m;
    for (int i = 0; i < nx; ++i)
        for (int j = 0; j < n; ++j)
            for (int k = 0; k < n; ++k) m.points.push_back(Vec3d(i + u(rng), j + u(rng), k + u(rng)));
    auto id = [n](int i, int j, int k) { return unsigned((i * n + j) * n + k); };
    auto clampi = [n](int x) { return std::min(n - 1, std::max(0, x)); };
    auto clampx = [nx](int x) { return std::min(nx - 1, std::max(0, x)); };
    while (m.triangles.size() < triangles) {
        const int i = at_x(rng), j = at(rng), k = at(rng);
        const unsigned a = id(i, j, k);
        const unsigned b = id(clampx(i + step(rng)), clampi(j + step(rng)), clampi(k + step(rng)));
        const unsigned c = id(clampx(i + step(rng)), clampi(j + step(rng)), clampi(k + step(rng)));
        if (a != b && b != c && a != c) m.triangles.emplace_back(a, b, c);
    }
    return m;
}

TEST_CASE("self-intersections: the grid finds exactly the tree's and brute force's pairs", "[self-intersections]") {
    std::mt19937 rng(23);
    for (const double jitter : {0.0, 0.35}) {
        const pqdc::Mesh soup = lattice_soup(rng, 9, 1500, jitter);
        const pqdc::SelfIntersections grid = pqdc::find_self_intersections(soup);
        pqdc::SelfIntersectionOptions tree_options;
        tree_options.broad_phase = pqdc::BroadPhase::tree;
        const pqdc::SelfIntersections tree = pqdc::find_self_intersections(soup, tree_options);
        INFO("jitter " << jitter << " pairs " << grid.pair_count);
        CHECK(grid.broad_phase == pqdc::BroadPhase::grid);
        CHECK(grid.pair_count > 100);
        CHECK(grid.pairs == tree.pairs);
        CHECK(grid.degenerate_triangles == tree.degenerate_triangles);
        CHECK(grid.pairs == brute_force(soup, grid.degenerate_triangles));
        pqdc::SelfIntersectionOptions few;
        few.max_pairs = 7;
        const pqdc::SelfIntersections first = pqdc::find_self_intersections(soup, few);
        CHECK(first.pair_count == grid.pair_count);
        CHECK(first.pairs == Pairs(grid.pairs.begin(), grid.pairs.begin() + 7));
        tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
        CHECK(pqdc::find_self_intersections(soup).pairs == grid.pairs);
    }
    pqdc::SelfIntersectionOptions bad;
    bad.broad_phase = pqdc::BroadPhase::grid;
    CHECK_THROWS_AS(pqdc::find_self_intersections(lattice_soup(rng, 3, 5, 0.1), bad), pqdc::option_error);
}

TEST_CASE("self-intersections: the grid in parts finds the same pairs for any part size", "[self-intersections]") {
    std::mt19937 rng(29);
    // A long strip in x order, as extracted meshes come in leaf order: a
    // part then meets only the next few, and parts pay.
    pqdc::Mesh strip = lattice_soup(rng, 4, 4000, 0.35, 80);
    auto min_x = [&](const openvdb::Vec3I& t) {
        return std::min({strip.points[t[0]][0], strip.points[t[1]][0], strip.points[t[2]][0]});
    };
    std::stable_sort(strip.triangles.begin(), strip.triangles.end(),
                     [&](const openvdb::Vec3I& a, const openvdb::Vec3I& b) { return min_x(a) < min_x(b); });
    pqdc::SelfIntersectionOptions tree_options;
    tree_options.broad_phase = pqdc::BroadPhase::tree;
    const pqdc::SelfIntersections tree = pqdc::find_self_intersections(strip, tree_options);
    REQUIRE(tree.pair_count > 100);
    for (const std::size_t part : {std::size_t(97), std::size_t(500), std::size_t(1333), std::size_t(4000)}) {
        std::size_t parts = 0;
        const pqdc::SelfIntersections r =
            pqdc::detail::find_self_intersections_at(strip, strip.points, {}, part, &parts);
        INFO("part size " << part);
        CHECK(parts == (strip.triangles.size() + part - 1) / part);
        CHECK(r.broad_phase == pqdc::BroadPhase::grid);
        CHECK(r.pairs == tree.pairs);
        CHECK(r.degenerate_triangles == tree.degenerate_triangles);
    }
    // A shuffled order makes every part meet every later one: one part.
    pqdc::Mesh shuffled = strip;
    std::shuffle(shuffled.triangles.begin(), shuffled.triangles.end(), rng);
    std::size_t parts = 0;
    const pqdc::SelfIntersections r =
        pqdc::detail::find_self_intersections_at(shuffled, shuffled.points, {}, 97, &parts);
    CHECK(parts == 1);
    CHECK(r.pair_count == tree.pair_count);
}

namespace {

/// A fan of n triangles around point 0 at the origin, corners 1..n on a
/// circle in the z = 0 plane turning `turns` times, z lifted by `lift`.
pqdc::Mesh fan(int n, int turns, double lift = 0.0) {
    pqdc::Mesh m;
    m.points.push_back(Vec3d(0.0));
    for (int i = 0; i < n; ++i) {
        const double angle = 2.0 * M_PI * turns * i / n;
        m.points.push_back(Vec3d(std::cos(angle), std::sin(angle), lift * (i % 2)));
    }
    for (int i = 0; i < n; ++i) m.triangles.emplace_back(0, 1 + i, 1 + (i + 1) % n);
    return m;
}

std::vector<std::uint8_t> flat_vertices(const pqdc::Mesh& m) {
    return pqdc::detail::find_flat_vertices(m, m.points, std::vector<char>(m.triangles.size() + 2 * m.quads.size(), 0));
}

/// Every pair of triangles whose boxes overlap, each tested alone as a
/// two-triangle mesh (no closed star, so no flat vertex takes part).
Pairs pairwise(const pqdc::Mesh& mesh, const std::vector<std::size_t>& degenerate) {
    const std::set<std::size_t> skip(degenerate.begin(), degenerate.end());
    std::vector<std::pair<Vec3d, Vec3d>> box;
    for (const auto& t : mesh.triangles) {
        Vec3d lo = mesh.points[t[0]], hi = lo;
        for (int k = 1; k < 3; ++k) {
            lo = openvdb::math::minComponent(lo, mesh.points[t[k]]);
            hi = openvdb::math::maxComponent(hi, mesh.points[t[k]]);
        }
        box.emplace_back(lo, hi);
    }
    Pairs pairs;
    for (std::size_t i = 0; i < mesh.triangles.size(); ++i)
        for (std::size_t j = i + 1; j < mesh.triangles.size(); ++j) {
            bool apart = skip.count(i) || skip.count(j);
            for (int k = 0; k < 3; ++k)
                apart = apart || box[i].second[k] < box[j].first[k] || box[j].second[k] < box[i].first[k];
            if (!apart && pqdc::find_self_intersections(two_triangles(mesh.points, mesh.triangles[i], mesh.triangles[j])).pair_count)
                pairs.emplace_back(i, j);
        }
    return pairs;
}

pqdc::Mesh as_triangles(const pqdc::Mesh& m) {
    pqdc::Mesh t;
    t.points = m.points;
    t.triangles = m.triangles;
    for (const auto& q : m.quads) {
        t.triangles.emplace_back(q[0], q[1], q[2]);
        t.triangles.emplace_back(q[0], q[2], q[3]);
    }
    return t;
}

}  // namespace

TEST_CASE("flat stars: one closed fan, one orientation, one turn", "[self-intersections]") {
    CHECK(flat_vertices(fan(6, 1))[0] == 1);
    CHECK(flat_vertices(fan(7, 1, 0.3))[0] == 1);  // lifted corners: still one turn in the z projection
    CHECK(flat_vertices(fan(9, 2))[0] == 0);       // turns twice: sectors overlap
    pqdc::Mesh flipped = fan(6, 1);
    std::swap(flipped.triangles[2][1], flipped.triangles[2][2]);
    CHECK(flat_vertices(flipped)[0] == 0);  // not consistently oriented
    pqdc::Mesh open = fan(6, 1);
    open.triangles.pop_back();
    CHECK(flat_vertices(open)[0] == 0);  // open fan (a boundary vertex)
    pqdc::Mesh folded = fan(8, 1);
    folded.points[3] = Vec3d(-0.2, -0.9, 0.0);  // corner 3 behind corner 2: sector (2, 3) turns backwards
    CHECK(flat_vertices(folded)[0] == 0);
    pqdc::Mesh two = fan(6, 1);  // two fans at one vertex (a pinched, non-manifold vertex)
    const pqdc::Mesh second = fan(6, 1, 0.0);
    for (int i = 1; i <= 6; ++i) two.points.push_back(second.points[i] * 0.5 + Vec3d(0, 0, 1));
    for (int i = 0; i < 6; ++i) two.triangles.emplace_back(0, 7 + i, 7 + (i + 1) % 6);
    CHECK(flat_vertices(two)[0] == 0);
}

TEST_CASE("flat stars settle only pairs that do not meet", "[self-intersections]") {
    // Folded meshes: extracted spheres (clean, and noisy with sigma_n = 0),
    // free of intersections as extracted, with jittered vertices. Most
    // vertices stay flat, the folds do not, and the pairs found must be
    // those of the pairwise test.
    pqdc::SphereParams sphere;
    pqdc::ProceduralSampling sampling;
    sampling.resolution = 16;
    openvdb::FloatGrid::Ptr grid = pqdc::sample_field(*pqdc::make_sphere(sphere), sampling);
    const double h = grid->voxelSize()[0];
    std::mt19937 rng(11);
    std::normal_distribution<float> noise(0.0f, float(0.3 * h));
    for (auto it = grid->beginValueOn(); it; ++it) it.setValue(*it + noise(rng));
    pqdc::ExtractOptions options;
    options.sigma_n = 0;
    pqdc::Mesh noisy = as_triangles(pqdc::extract(*grid, options));
    pqdc::Mesh jittered = as_triangles(pqdc::extract(*pqdc::make_sphere(sphere), sampling, pqdc::ExtractOptions{}));
    auto jitter = [&](pqdc::Mesh& m, double amplitude) {
        std::uniform_real_distribution<double> u(-amplitude * h, amplitude * h);
        for (Vec3d& p : m.points) p += Vec3d(u(rng), u(rng), u(rng));
    };
    jitter(noisy, 0.2);
    jitter(jittered, 0.35);
    for (const pqdc::Mesh* m : std::vector<const pqdc::Mesh*>{&noisy, &jittered}) {
        const std::vector<std::uint8_t> flat = flat_vertices(*m);
        const auto flat_count = std::size_t(std::count(flat.begin(), flat.end(), 1));
        const pqdc::SelfIntersections r = pqdc::find_self_intersections(*m);
        INFO("vertices " << m->points.size() << " flat " << flat_count << " pairs " << r.pair_count);
        CHECK(flat_count > m->points.size() / 2);
        CHECK(flat_count < m->points.size());
        CHECK(r.pair_count > 0);
        CHECK(r.pairs == pairwise(*m, r.degenerate_triangles));
        // Some pair found shares a corner: the flat test did not hide those.
        bool sharing = false;
        for (const auto& [a, b] : r.pairs)
            for (int k = 0; k < 3; ++k)
                for (int l = 0; l < 3; ++l) sharing = sharing || m->triangles[a][k] == m->triangles[b][l];
        CHECK(sharing);
    }
}

#ifdef PQDC_HAVE_CGAL
namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;

/// CGAL's own definition, pair by pair, with its exact kernel predicates
/// (the logic of PMP::internal::do_faces_intersect, for index-sharing soups).
bool cgal_pair(const pqdc::Mesh& m, std::size_t i, std::size_t j) {
    auto pt = [&](unsigned v) { return K::Point_3(m.points[v][0], m.points[v][1], m.points[v][2]); };
    const auto& a = m.triangles[i];
    const auto& b = m.triangles[j];
    int shared = 0, si = 0, sj = 0;
    for (int k = 0; k < 3; ++k)
        for (int l = 0; l < 3; ++l)
            if (a[k] == b[l]) ++shared, si = k, sj = l;
    const K::Triangle_3 ta(pt(a[0]), pt(a[1]), pt(a[2])), tb(pt(b[0]), pt(b[1]), pt(b[2]));
    if (shared == 3) return true;
    if (shared == 0) return CGAL::do_intersect(ta, tb);
    if (shared == 1)
        return CGAL::do_intersect(K::Segment_3(pt(a[(si + 1) % 3]), pt(a[(si + 2) % 3])), tb) ||
               CGAL::do_intersect(K::Segment_3(pt(b[(sj + 1) % 3]), pt(b[(sj + 2) % 3])), ta);
    int r = 0, w = 0;
    for (int k = 0; k < 3; ++k) {
        if (a[k] != b[0] && a[k] != b[1] && a[k] != b[2]) r = k;
        if (b[k] != a[0] && b[k] != a[1] && b[k] != a[2]) w = k;
    }
    const K::Point_3 p = pt(a[(r + 1) % 3]), q = pt(a[(r + 2) % 3]);
    return CGAL::coplanar(p, q, pt(a[r]), pt(b[w])) &&
           CGAL::coplanar_orientation(p, q, pt(a[r]), pt(b[w])) == CGAL::POSITIVE;
}

/// PMP::self_intersections on a CGAL Surface_mesh of the same triangles, in
/// the same order (face index = triangle number).
Pairs cgal_mesh_pairs(const pqdc::Mesh& m, std::size_t& degenerate) {
    CGAL::Surface_mesh<K::Point_3> sm;
    for (const Vec3d& p : m.points) sm.add_vertex(K::Point_3(p[0], p[1], p[2]));
    using V = CGAL::Surface_mesh<K::Point_3>::Vertex_index;
    for (const auto& t : m.triangles) REQUIRE(sm.add_face(V(t[0]), V(t[1]), V(t[2])) != sm.null_face());
    std::vector<std::pair<CGAL::Surface_mesh<K::Point_3>::Face_index, CGAL::Surface_mesh<K::Point_3>::Face_index>> out;
    CGAL::Polygon_mesh_processing::self_intersections(sm, std::back_inserter(out));
    Pairs pairs;
    degenerate = 0;
    for (const auto& [f, g] : out) {
        if (f == g) {
            ++degenerate;
            continue;
        }
        pairs.emplace_back(std::min<std::size_t>(f, g), std::max<std::size_t>(f, g));
    }
    std::sort(pairs.begin(), pairs.end());
    return pairs;
}

}  // namespace

TEST_CASE("self-intersections agree with CGAL", "[self-intersections][cgal]") {
    SECTION("random soups, pair by pair") {
        std::mt19937 rng(5);
        for (const bool snapped : {false, true}) {
            const pqdc::Mesh soup = random_soup(rng, 150, snapped ? 40 : 200, snapped);
            const pqdc::SelfIntersections r = pqdc::find_self_intersections(soup);
            const std::set<std::size_t> skip(r.degenerate_triangles.begin(), r.degenerate_triangles.end());
            Pairs expected;
            for (std::size_t i = 0; i < soup.triangles.size(); ++i)
                for (std::size_t j = i + 1; j < soup.triangles.size(); ++j)
                    if (!skip.count(i) && !skip.count(j) && cgal_pair(soup, i, j)) expected.emplace_back(i, j);
            INFO("snapped " << snapped);
            CHECK(r.pairs == expected);
        }
    }
    SECTION("extracted meshes with folds, PMP::self_intersections") {
        // A noisy sphere meshed with sigma_n = 0 and no clamping folds in
        // many places; jittering the vertices of a clean one folds it more.
        pqdc::SphereParams sphere;
        pqdc::ProceduralSampling sampling;
        sampling.resolution = 20;
        openvdb::FloatGrid::Ptr grid = pqdc::sample_field(*pqdc::make_sphere(sphere), sampling);
        std::mt19937 rng(3);
        std::normal_distribution<float> noise(0.0f, float(0.3 * grid->voxelSize()[0]));
        for (auto it = grid->beginValueOn(); it; ++it) it.setValue(*it + noise(rng));
        pqdc::ExtractOptions options;
        options.sigma_n = 0;
        options.containment = pqdc::Containment::unconstrained;
        pqdc::Mesh noisy = pqdc::extract(*grid, options);

        pqdc::Mesh jittered = pqdc::extract(*pqdc::make_sphere(sphere), sampling, pqdc::ExtractOptions{});
        std::uniform_real_distribution<double> u(-0.04, 0.04);
        for (Vec3d& p : jittered.points) p += Vec3d(u(rng), u(rng), u(rng));
        std::size_t total = 0;
        for (const pqdc::Mesh* m : {&noisy, &jittered}) {
            std::size_t cgal_degenerate = 0;
            const Pairs expected = cgal_mesh_pairs(*m, cgal_degenerate);
            const pqdc::SelfIntersections r = pqdc::find_self_intersections(*m);
            CHECK(r.pairs == expected);
            CHECK(r.degenerate_triangles.size() == cgal_degenerate);
            total += r.pair_count;
        }
        CHECK(total > 0);
    }
}
#endif

TEST_CASE("find_self_intersections tests the points as a float file stores them on request", "[self-intersections]") {
    // Far from the origin float's spacing (1/16 at 1e6) merges points a
    // millimetre apart: a fine triangle in double, degenerate in float, and
    // two triangles apart in double that cross once rounded.
    pqdc::Mesh m;
    m.points = {{1e6, 0, 0}, {1e6 + 1e-3, 0, 0}, {1e6, 1, 0}};
    m.triangles = {{0, 1, 2}};
    CHECK(pqdc::find_self_intersections(m).none());
    pqdc::SelfIntersectionOptions as_float;
    as_float.stored_precision = pqdc::VertexPrecision::float32;
    const pqdc::SelfIntersections f = pqdc::find_self_intersections(m, as_float);
    CHECK(f.degenerate_triangles.size() == 1);
    CHECK(m.points[1][0] == 1e6 + 1e-3);  // the mesh itself is not rounded
    as_float.stored_precision = static_cast<pqdc::VertexPrecision>(7);
    CHECK_THROWS_WITH(pqdc::find_self_intersections(m, as_float), Catch::Contains("stored_precision = 7"));
}
