// pqdc::decimate: topology and geometry guarantees, determinism, errors,
// the exact predicates, and the pqdc-decimate CLI.

#include "pqdc/decimate.hpp"
#include "pqdc/exceptions.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/measure.hpp"
#include "pqdc/mesh_io.hpp"
#include "pqdc/procedural.hpp"
#include "pqdc/self_intersections.hpp"

#include "../src/decimate/decimate_internal.hpp"
#include "../src/decimate/exact_predicates.hpp"
#include "cli_runner.hpp"

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"  // GCC 12 inside cpp_int's limbs
#include <boost/multiprecision/cpp_int.hpp>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <random>
#include <regex>
#include <set>

namespace {

using pqdc::exact::point;

pqdc::Mesh dc_sphere(int resolution) {
    auto field = pqdc::make_procedural("sphere");
    pqdc::ProceduralSampling s;
    s.resolution = resolution;
    pqdc::ExtractOptions o;
    return pqdc::extract(*field, s, o);
}

/// A torus (genus 1) as a u-v grid, radii R and r, with optional radial noise.
pqdc::Mesh torus(int nu, int nv, double R, double r, double noise = 0, unsigned seed = 1) {
    pqdc::Mesh m;
    std::mt19937 rng(seed);
    std::normal_distribution<double> g(0, 1);
    for (int i = 0; i < nu; ++i)
        for (int j = 0; j < nv; ++j) {
            const double u = 2 * M_PI * i / nu, v = 2 * M_PI * j / nv;
            const double rr = r + noise * g(rng);
            m.points.emplace_back((R + rr * std::cos(v)) * std::cos(u), (R + rr * std::cos(v)) * std::sin(u), rr * std::sin(v));
        }
    auto id = [&](int i, int j) { return unsigned(((i + nu) % nu) * nv + (j + nv) % nv); };
    for (int i = 0; i < nu; ++i)
        for (int j = 0; j < nv; ++j) m.quads.emplace_back(id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
    return m;
}

/// UV sphere with its z squashed: two sheets much closer than an edge.
pqdc::Mesh pancake(int nu, int nv, double thickness) {
    pqdc::Mesh m;
    m.points.emplace_back(0, 0, -thickness);
    for (int j = 1; j < nv; ++j)
        for (int i = 0; i < nu; ++i) {
            const double th = M_PI * j / nv, ph = 2 * M_PI * i / nu;
            m.points.emplace_back(std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), -thickness * std::cos(th));
        }
    m.points.emplace_back(0, 0, thickness);
    const unsigned top = unsigned(m.points.size() - 1);
    auto id = [&](int j, int i) { return unsigned(1 + (j - 1) * nu + (i + nu) % nu); };
    for (int i = 0; i < nu; ++i) m.triangles.emplace_back(0, id(1, i + 1), id(1, i));
    for (int j = 1; j + 1 < nv; ++j)
        for (int i = 0; i < nu; ++i) m.quads.emplace_back(id(j, i), id(j, i + 1), id(j + 1, i + 1), id(j + 1, i));
    for (int i = 0; i < nu; ++i) m.triangles.emplace_back(top, id(nv - 1, i), id(nv - 1, i + 1));
    return m;
}

/// Pairs of triangles that meet beyond their shared vertices (all pairs, exact).
std::size_t self_intersections(const pqdc::Mesh& m) {
    std::size_t hits = 0;
    const auto& t = m.triangles;
    auto P = [&](unsigned v) { const auto& p = m.points[v]; return point{p[0], p[1], p[2]}; };
    std::vector<std::array<openvdb::Vec3d, 2>> box(t.size());
    for (std::size_t i = 0; i < t.size(); ++i) {
        box[i] = {m.points[t[i][0]], m.points[t[i][0]]};
        for (int k = 1; k < 3; ++k) {
            box[i][0] = openvdb::math::minComponent(box[i][0], m.points[t[i][k]]);
            box[i][1] = openvdb::math::maxComponent(box[i][1], m.points[t[i][k]]);
        }
    }
    for (std::size_t i = 0; i < t.size(); ++i)
        for (std::size_t j = i + 1; j < t.size(); ++j) {
            bool apart = false;  // boxes apart: no common point (a prune, not a predicate)
            for (int k = 0; k < 3; ++k)
                apart = apart || box[i][1][k] < box[j][0][k] || box[j][1][k] < box[i][0][k];
            if (apart) continue;
            const unsigned a[3] = {t[i][0], t[i][1], t[i][2]}, b[3] = {t[j][0], t[j][1], t[j][2]};
            int shared = 0, si[3], sj[3];
            for (int x = 0; x < 3; ++x)
                for (int y = 0; y < 3; ++y)
                    if (a[x] == b[y]) { si[shared] = x; sj[shared] = y; ++shared; }
            const point pa[3] = {P(a[0]), P(a[1]), P(a[2])}, pb[3] = {P(b[0]), P(b[1]), P(b[2])};
            bool hit;
            if (shared == 0) hit = pqdc::exact::triangles_intersect(pa, pb);
            else if (shared == 1) hit = pqdc::exact::triangles_intersect_sharing_vertex(pa[si[0]], pa[(si[0] + 1) % 3], pa[(si[0] + 2) % 3], pb[(sj[0] + 1) % 3], pb[(sj[0] + 2) % 3]);
            else if (shared == 2) hit = pqdc::exact::triangles_overlap_sharing_edge(pa[si[0]], pa[si[1]], pa[3 - si[0] - si[1]], pb[3 - sj[0] - sj[1]]);
            else hit = true;
            hits += hit;
        }
    return hits;
}

void check_closed_same_topology(const pqdc::Mesh& in, const pqdc::Mesh& out) {
    const pqdc::TopologyReport a = pqdc::measure_topology(in), b = pqdc::measure_topology(out);
    CHECK(b.closed());
    CHECK(b.edge_manifold());
    CHECK(b.vertex_manifold());
    CHECK(b.consistently_oriented());
    CHECK(b.degenerate_face_count == 0);
    CHECK(b.euler_characteristic == a.euler_characteristic);
    CHECK(b.connected_component_count == a.connected_component_count);
}

bool same_bytes(const pqdc::Mesh& a, const pqdc::Mesh& b) {
    return a.points.size() == b.points.size() && a.triangles.size() == b.triangles.size() &&
           std::memcmp(a.points.data(), b.points.data(), a.points.size() * sizeof(a.points[0])) == 0 &&
           std::memcmp(a.triangles.data(), b.triangles.data(), a.triangles.size() * sizeof(a.triangles[0])) == 0;
}

}  // namespace

TEST_CASE("exact predicates: separated, crossing, touching and neighbouring triangles", "[decimate]") {
    using namespace pqdc::exact;
    const point t[3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
    const point above[3] = {{0, 0, 1}, {1, 0, 1}, {0, 1, 1}};
    const point pierce[3] = {{0.2, 0.2, -1}, {0.3, 0.2, 1}, {0.2, 0.3, 1}};
    const point touch[3] = {{1, 0, 0}, {2, 0, 1}, {2, 0, -1}};  // meets t only at its corner (1,0,0)
    const point coplanar_overlap[3] = {{0.2, 0.2, 0}, {2, 0.2, 0}, {0.2, 2, 0}};
    const point coplanar_apart[3] = {{2, 2, 0}, {3, 2, 0}, {2, 3, 0}};
    CHECK_FALSE(triangles_intersect(t, above));
    CHECK(triangles_intersect(t, pierce));
    CHECK(triangles_intersect(t, touch));
    CHECK(triangles_intersect(t, coplanar_overlap));
    CHECK_FALSE(triangles_intersect(t, coplanar_apart));
    // Orientation decided exactly where doubles round: points 1e-300 apart.
    CHECK(orient3d({0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0.25, 0.25, 1e-300}) != 0);
    // Sharing a vertex s = (0,0,0): a fan neighbour is fine, a folded one is not.
    const point s{0, 0, 0}, a{1, 0, 0}, b{0, 1, 0};
    CHECK_FALSE(triangles_intersect_sharing_vertex(s, a, b, {-1, 0, 0}, {0, -1, 0.5}));
    CHECK(triangles_intersect_sharing_vertex(s, a, b, {0.5, 0.5, -1}, {0.5, 0.5, 1}));  // ab pierces the other
    CHECK(triangles_intersect_sharing_vertex(s, a, b, {0.5, 0.1, 0}, {0.1, 0.5, 0}));    // coplanar, inside
    CHECK_FALSE(triangles_intersect_sharing_vertex(s, a, b, {-1, 0.1, 0}, {-1, -0.5, 0}));  // coplanar, apart
    // Degenerate but legal patterns of mesh neighbours: a side in the other's
    // plane, opposite wedges of a flat grid vertex, collinear sides.
    CHECK_FALSE(triangles_intersect_sharing_vertex(s, a, {1, 1, 0.1}, {0, 1, 0}, {-1, 0, 0}));
    CHECK_FALSE(triangles_intersect_sharing_vertex(s, a, {1, 1, 0}, {-1, 0, 0}, {-1, -1, 0}));
    CHECK(triangles_intersect_sharing_vertex(s, a, {1, 1, 0}, {2, 0, 0}, {1, -1, 0}));     // sides overlap
    CHECK(triangles_intersect_sharing_vertex(s, a, {1, 1, 0}, {0.5, 0, 0}, {0, 0, 1}));    // a side lies in the other
    CHECK_FALSE(triangles_intersect_sharing_vertex(s, a, {1, 1, 0}, {-0.5, 0, 0}, {0, 0, 1}));
    // Sharing an edge: a flat neighbour on the other side is fine, a fold is not.
    CHECK_FALSE(triangles_overlap_sharing_edge(s, a, b, {0.5, -1, 0}));
    CHECK(triangles_overlap_sharing_edge(s, a, b, {0.5, 0.2, 0}));
    CHECK_FALSE(triangles_overlap_sharing_edge(s, a, b, {0.5, 0.2, 0.1}));
}

TEST_CASE("exact predicates: signs equal integer arithmetic on near-degenerate input", "[decimate]") {
    // Integer coordinates (exact in double) whose determinants exceed 2^53:
    // __int128 gives the true sign, plain double arithmetic often does not.
    std::mt19937_64 rng(7);
    std::uniform_int_distribution<long long> big(-(1LL << 30), 1LL << 30), small(-2, 2), step(-3, 3);
    int mismatches = 0, zeros = 0;
    for (int n = 0; n < 2000; ++n) {
        const long long a[3] = {big(rng), big(rng), big(rng)}, b[3] = {big(rng), big(rng), big(rng)},
                        c[3] = {big(rng), big(rng), big(rng)};
        const long long s = step(rng), t = step(rng);
        long long d[3];
        for (int k = 0; k < 3; ++k) d[k] = a[k] + s * (b[k] - a[k]) + t * (c[k] - a[k]) + (n % 2 ? small(rng) : 0);
        __int128 m[3][3];
        for (int k = 0; k < 3; ++k) {
            m[0][k] = a[k] - d[k];
            m[1][k] = b[k] - d[k];
            m[2][k] = c[k] - d[k];
        }
        const __int128 det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
                             m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
                             m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
        const int expect = det > 0 ? 1 : (det < 0 ? -1 : 0);
        zeros += expect == 0;
        auto P = [](const long long* v) { return point{double(v[0]), double(v[1]), double(v[2])}; };
        mismatches += pqdc::exact::orient3d(P(a), P(b), P(c), P(d)) != expect;
    }
    CHECK(mismatches == 0);
    CHECK(zeros > 500);  // the exact fallback was exercised on true zeros
}

TEST_CASE("exact predicates: expansions and the plane filter agree with rational arithmetic", "[decimate]") {
    // Fractional coordinates far from the origin: the differences are not
    // exact in double (unlike the integer case above), and points made
    // coplanar in floating point sit within rounding of the plane, so the
    // exact fallback decides. The oracle is boost's cpp_rational.
    using rational = boost::multiprecision::cpp_rational;
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> unit(-1, 1), coef(-2, 2);
    int mismatches = 0, filter_wrong = 0, zeros = 0, undecided = 0;
    for (int n = 0; n < 3000; ++n) {
        const double scale = std::ldexp(1.0, int(n % 40) - 20), offset = (n % 3) * 1000.0 + 0.1;
        auto rnd = [&] { return point{offset + scale * unit(rng), offset + scale * unit(rng), offset - scale * unit(rng)}; };
        const point a = rnd(), b = rnd(), c = rnd();
        const double s = coef(rng), t = coef(rng);
        point d = a + (b - a) * s + (c - a) * t;
        if (n % 4 == 1) d.x = std::nextafter(d.x, 1e300);
        if (n % 4 == 2) d = a;  // a repeated point: a true zero
        auto R = [](double v) { return rational(v); };
        const rational m[3][3] = {{R(a.x) - R(d.x), R(a.y) - R(d.y), R(a.z) - R(d.z)},
                                  {R(b.x) - R(d.x), R(b.y) - R(d.y), R(b.z) - R(d.z)},
                                  {R(c.x) - R(d.x), R(c.y) - R(d.y), R(c.z) - R(d.z)}};
        const rational det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
                             m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
                             m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
        const int expect = det > 0 ? 1 : (det < 0 ? -1 : 0);
        zeros += expect == 0;
        mismatches += pqdc::exact::orient3d(a, b, c, d) != expect;
        const point tri[3] = {a, b, c};
        const int side = pqdc::exact::plane_filter(tri).side(d);
        undecided += side == 0;
        filter_wrong += side != 0 && side != -expect;  // the filter's convention is -orient3d
        const double ex = offset + scale * unit(rng), ey = offset + scale * unit(rng), fx = ex + (b.x - a.x) * s,
                     fy = ey + (b.y - a.y) * s;
        const rational d2 = (R(a.x) - R(fx)) * (R(ex) - R(fy)) - (R(a.y) - R(fy)) * (R(ey) - R(fx));
        mismatches += pqdc::exact::orient2d(a.x, a.y, ey, ex, fx, fy) != (d2 > 0 ? 1 : (d2 < 0 ? -1 : 0));
    }
    CHECK(mismatches == 0);
    CHECK(filter_wrong == 0);
    CHECK(zeros >= 700);        // the repeated points, at least
    CHECK(undecided > 1000);    // the near-coplanar points reached the exact path
}

TEST_CASE("decimate's float boxes contain their double boxes, one float step out at most", "[decimate]") {
    namespace dd = pqdc::decimate_detail;
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> mantissa(-1, 1);
    std::uniform_int_distribution<int> exponent(-160, 140);
    std::vector<double> values = {0.0, -0.0, 1.0, -1.0, 1e-300, -1e-300, 1e-45, -1e-45, 0.1, -0.1, 3.4e38, -3.4e38};
    for (int i = 0; i < 100000; ++i) values.push_back(std::ldexp(mantissa(rng), exponent(rng)));
    std::size_t moved = 0;
    for (double v : values) {
        const float lo = dd::float_below(v), hi = dd::float_above(v);
        INFO(v);
        REQUIRE(double(lo) <= v);
        REQUIRE(double(hi) >= v);
        // At most one step from the nearest float, and exact where v is a float.
        REQUIRE(std::nextafter(lo, std::numeric_limits<float>::infinity()) >= float(v));
        REQUIRE(std::nextafter(hi, -std::numeric_limits<float>::infinity()) <= float(v));
        if (double(float(v)) == v) REQUIRE((lo == float(v) && hi == float(v)));
        moved += lo != float(v) || hi != float(v);
    }
    CHECK(moved > 50000);  // most doubles are no float: the rounding direction mattered
}

TEST_CASE("decimate's triangle grid reports exactly the boxes that meet the query, each once", "[decimate]") {
    namespace dd = pqdc::decimate_detail;
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> where(-50, 50), unit(0, 1);
    std::vector<dd::FloatBox> boxes;
    std::vector<dd::BoxPair> exact;
    for (int i = 0; i < 20000; ++i) {
        // Mostly small boxes, some 10-100x larger (they go to coarser
        // levels), a few spanning everything, some degenerate (points).
        const double r = unit(rng);
        const double size = r < 0.9 ? 0.5 * unit(rng) : (r < 0.995 ? 30 * unit(rng) : 200 * unit(rng));
        const dd::vec lo{where(rng), where(rng), where(rng)};
        const dd::vec hi = i % 97 == 0 ? lo : lo + dd::vec{size * unit(rng), size * unit(rng), size * unit(rng)};
        exact.push_back({lo, hi});
        boxes.push_back(dd::float_box({lo, hi}));
    }
    const std::vector<dd::FloatBox> all = boxes;
    dd::TriangleGrid grid;
    grid.build(boxes);
    std::vector<std::uint32_t> found;
    for (int q = 0; q < 400; ++q) {
        const double size = q % 3 == 0 ? 20 * unit(rng) : 2 * unit(rng);
        const dd::vec lo{where(rng), where(rng), where(rng)};
        const dd::vec hi = q % 50 == 0 ? lo : lo + dd::vec{size, size * unit(rng), size};
        grid.query(lo, hi, found);
        // The float boxes meeting the query rounded outwards: exactly these.
        std::vector<std::uint32_t> expected;
        for (std::uint32_t i = 0; i < all.size(); ++i)
            if (dd::boxes_meet(all[i], dd::float_box({lo, hi}))) expected.push_back(i);
        std::sort(found.begin(), found.end());
        REQUIRE(found == expected);  // sorted equality: none missed, none extra, no repeats
        // Every double box that meets the query is among them.
        for (std::uint32_t i = 0; i < exact.size(); ++i)
            if (dd::boxes_meet(exact[i], {lo, hi})) REQUIRE(std::binary_search(found.begin(), found.end(), i));
    }
    // Rebuilt from the returned buffer, and on a flat (zero-thickness) set.
    for (auto& b : boxes) b.lo[2] = b.hi[2] = 0;
    const std::vector<dd::FloatBox> flat = boxes;
    grid.build(boxes);
    grid.query({-10, -10, 0}, {10, 10, 0}, found);
    std::size_t expected = 0;
    for (const auto& b : flat) expected += dd::boxes_meet(b, dd::float_box({dd::vec{-10, -10, 0}, dd::vec{10, 10, 0}}));
    CHECK(found.size() == expected);
}

TEST_CASE("decimate's local disc certificate never passes a disc whose faces meet", "[decimate]") {
    // A noisy torus (folds everywhere at the largest noise), candidate
    // positions scattered around each edge, and vertices next to the link
    // pulled across the created faces: whenever local_disc_embeds()
    // certifies a collapse, the exact pair tests it replaces (created faces
    // with each other and with every other face at the link) find nothing.
    namespace dd = pqdc::decimate_detail;
    std::size_t certified = 0, refused = 0, refused_meeting = 0;
    for (double noise : {0.01, 0.06, 0.15}) {
        const pqdc::Mesh in = torus(40, 20, 2.0, 0.7, noise, 5);
        dd::WorkMesh m;
        for (const auto& p : in.points) m.pos.push_back({p[0], p[1], p[2]});
        for (const auto& q : in.quads) {
            m.tris.push_back({q[0], q[1], q[2]});
            m.tris.push_back({q[0], q[2], q[3]});
        }
        dd::rebuild_fans(m);
        m.locked.assign(m.pos.size(), 0);
        std::mt19937 rng(11);
        std::normal_distribution<double> g(0, 1);
        std::vector<dd::Tri> tris(64);
        std::vector<std::array<dd::vec, 3>> points(64);
        std::vector<dd::FloatBox> boxes(64);
        for (const dd::Tri& t : m.tris)
            for (int k = 0; k < 3; ++k) {
                const std::uint32_t a = t[k], b = t[(k + 1) % 3];
                if (a > b || !dd::link_condition_holds(m, a, b)) continue;
                for (int trial = 0; trial < 3; ++trial) {
                    const double spread = trial == 0 ? 0.02 : 0.15;
                    dd::Candidate c{a, b, (m.pos[a] + m.pos[b]) * 0.5 + dd::vec{g(rng), g(rng), g(rng)} * spread, 0};
                    const std::size_t n = dd::created_face_count(m, c);
                    REQUIRE(n <= tris.size());
                    const dd::BoxPair all = dd::write_created_faces(m, c, tris.data(), points.data(), boxes.data());
                    const dd::CreatedFaces created{tris.data(), points.data(), boxes.data(), n, all};
                    std::uint32_t link[dd::kMaxLink];
                    const std::size_t link_size = dd::created_link(c, created, link);
                    REQUIRE(link_size == n);
                    // Third trial: a vertex just outside the link is pulled
                    // onto a created face, folding its faces over the disc.
                    std::uint32_t moved = std::uint32_t(-1);
                    dd::vec kept{};
                    if (trial == 2) {
                        const std::uint32_t w = link[rng() % link_size];
                        const dd::Tri& u = m.tris[m.fan_of(w)[rng() % m.fan_size(w)]];
                        for (std::uint32_t y : u)
                            if (y != a && y != b && std::find(link, link + link_size, y) == link + link_size) moved = y;
                        if (moved == std::uint32_t(-1)) continue;
                        const std::array<dd::vec, 3>& f = points[rng() % n];
                        kept = m.pos[moved];
                        m.pos[moved] = (f[0] + f[1] + f[2]) / 3.0 + dd::vec{g(rng), g(rng), g(rng)} * 0.05;
                    }
                    // Every pair the certificate stands for, tested exactly.
                    bool meet = false;
                    for (std::size_t i = 0; i < n; ++i)
                        for (std::size_t j = i + 1; j < n; ++j)
                            meet = meet || dd::faces_intersect(tris[i], points[i].data(), tris[j], points[j].data());
                    for (std::size_t l = 0; l < link_size; ++l)
                        for (std::size_t f = 0; f < m.fan_size(link[l]); ++f) {
                            const dd::Tri& u = m.tris[m.fan_of(link[l])[f]];
                            if (std::count(u.begin(), u.end(), a) || std::count(u.begin(), u.end(), b)) continue;
                            const dd::vec pu[3] = {m.pos[u[0]], m.pos[u[1]], m.pos[u[2]]};
                            for (std::size_t i = 0; i < n; ++i)
                                meet = meet || dd::faces_intersect(tris[i], points[i].data(), u, pu);
                        }
                    if (dd::local_disc_embeds(m, c, created, link, link_size)) {
                        ++certified;
                        INFO("edge " << a << "-" << b << " spread " << spread << " noise " << noise);
                        REQUIRE_FALSE(meet);
                    } else {
                        ++refused;
                        refused_meeting += meet;
                    }
                    if (moved != std::uint32_t(-1)) m.pos[moved] = kept;
                }
            }
    }
    // Both outcomes occur, and the refused ones include real intersections
    // (the test has cases the certificate must turn down).
    CHECK(certified > 1000);
    CHECK(refused > 100);
    CHECK(refused_meeting > 20);
}

TEST_CASE("decimate: target_ratio keeps at most ratio x input faces", "[decimate]") {
    // ceil(ratio x faces) stopped one face above it (6420 of 52000 at 0.12345),
    // and the CLI then warned that every further collapse was refused.
    const pqdc::Mesh in = dc_sphere(20);
    for (double ratio : {0.12345, 0.33333, 0.29, 0.5}) {
        pqdc::Mesh out = in;
        pqdc::DecimateOptions o;
        o.target_ratio = ratio;
        pqdc::decimate(out, o);
        INFO("ratio " << ratio << " of " << in.triangles.size());
        CHECK(double(out.triangles.size()) <= ratio * double(in.triangles.size()) + 1e-6);
        CHECK(double(out.triangles.size()) >= ratio * double(in.triangles.size()) - 2.0);  // a collapse takes 2
    }
}

TEST_CASE("decimate: a closed sphere stays closed, manifold, genus 0, free of intersections", "[decimate]") {
    const pqdc::Mesh in = dc_sphere(20);
    REQUIRE(in.triangles.size() > 1000);
    for (auto metric : {pqdc::DecimateMetric::triangle, pqdc::DecimateMetric::plane, pqdc::DecimateMetric::curvature}) {
        pqdc::Mesh out = in;
        pqdc::DecimateOptions o;
        o.target_ratio = 0.1;
        o.metric = metric;
        pqdc::DecimateStats st;
        pqdc::decimate(out, o, &st);
        INFO("metric " << int(metric));
        CHECK(st.input_faces == in.triangles.size());
        CHECK(out.triangles.size() <= std::size_t(std::ceil(0.1 * double(in.triangles.size()))));
        CHECK(out.triangles.size() >= std::size_t(0.08 * double(in.triangles.size())));
        CHECK(st.collapses * 2 == in.triangles.size() - out.triangles.size());
        check_closed_same_topology(in, out);
        CHECK(self_intersections(out) == 0);
        auto field = pqdc::make_procedural("sphere");
        const pqdc::DistanceStats d = pqdc::measure_distance(out, *field);
        CHECK(d.max < 0.05);  // unit sphere, 20 cells: a voxel is ~0.12
    }
}

namespace {

/// The input's triangles as decimate() sees them: quads split along the
/// shorter diagonal.
pqdc::Mesh split_quads(const pqdc::Mesh& m) {
    pqdc::Mesh t{m.points, m.triangles, {}, {}};
    for (const auto& q : m.quads) {
        if ((m.points[q[0]] - m.points[q[2]]).lengthSqr() <= (m.points[q[1]] - m.points[q[3]]).lengthSqr()) {
            t.triangles.emplace_back(q[0], q[1], q[2]);
            t.triangles.emplace_back(q[0], q[2], q[3]);
        } else {
            t.triangles.emplace_back(q[0], q[1], q[3]);
            t.triangles.emplace_back(q[1], q[2], q[3]);
        }
    }
    return t;
}

}  // namespace

// Random inputs (noisy tori, thin pancakes, a ball nested just under a
// surface) and random options: every guarantee of decimate.hpp on each.
// PQDC_DECIMATE_PROPERTY_CASES=N runs more cases (a local bug hunt).
TEST_CASE("decimate: random inputs and options keep every guarantee", "[decimate]") {
    const char* env = std::getenv("PQDC_DECIMATE_PROPERTY_CASES");
    const int cases = env ? std::max(1, std::atoi(env)) : 32;
    std::size_t clean_inputs = 0;
    for (int seed = 1; seed <= cases; ++seed) {
        std::mt19937 rng{unsigned(seed)};
        auto uniform = [&rng](double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); };
        auto pick = [&rng](int n) { return int(std::uniform_int_distribution<int>(0, n - 1)(rng)); };
        pqdc::Mesh in;
        double voxel = 0.1;
        switch (pick(4)) {
            case 3: {  // dual contouring output: sharp edges, thin parts, several components
                auto field = pqdc::make_procedural(pick(2) ? "box" : "figure3");
                pqdc::ProceduralSampling sampling;
                sampling.resolution = 16 + pick(32);
                in = pqdc::extract(*field, sampling, pqdc::ExtractOptions{});
                voxel = 0;  // the mean edge length
                break;
            }
            case 0: {
                const int nu = 12 + pick(30), nv = 8 + pick(14);
                const double r = uniform(0.3, 0.9);
                voxel = 2 * M_PI * r / nv;
                in = torus(nu, nv, 2.0, r, uniform(0, 0.3) * voxel, unsigned(seed));
                break;
            }
            case 1: in = pancake(24 + pick(32), 12 + pick(16), uniform(0.003, 0.1)); break;
            default: {
                in = pancake(32 + pick(16), 16 + pick(8), 1.0);
                const pqdc::Mesh ball = pancake(12 + pick(8), 6 + pick(4), 1.0);
                const double size = uniform(0.05, 0.2), gap = uniform(0.001, 0.02);
                const unsigned offset = unsigned(in.points.size());
                for (const auto& p : ball.points) in.points.push_back(p * size + openvdb::Vec3d(0, 0, 1 - size - gap));
                for (const auto& t : ball.triangles) in.triangles.emplace_back(t[0] + offset, t[1] + offset, t[2] + offset);
                for (const auto& q : ball.quads)
                    in.quads.emplace_back(q[0] + offset, q[1] + offset, q[2] + offset, q[3] + offset);
                voxel = 0.05;
            }
        }
        pqdc::DecimateOptions o;
        const pqdc::DecimateMetric metrics[] = {pqdc::DecimateMetric::triangle, pqdc::DecimateMetric::plane,
                                                pqdc::DecimateMetric::curvature};
        o.metric = metrics[pick(3)];
        if (pick(2)) o.target_ratio = uniform(0.02, 0.5);
        else o.target_faces = std::size_t(8 + pick(200));
        if (pick(3) == 0) o.max_distance_voxels = uniform(0.05, 2);
        if (pick(2)) o.sigma_position_voxels = uniform(0.01, 0.3);
        o.max_normal_change_degrees = uniform(30, 179);
        o.min_triangle_quality = uniform(0, 0.3);
        o.voxel_size = voxel;
        o.threads = 1;
        if (voxel == 0) {
            pqdc::DecimateStats probe;  // the voxel the lengths are in, for the distance check
            pqdc::Mesh copy = in;
            pqdc::DecimateOptions once = o;
            once.max_distance_voxels = 0;
            once.target_faces = 0;
            once.target_ratio = 1;
            pqdc::decimate(copy, once, &probe);
            voxel = probe.voxel_size;
        }
        INFO("seed " << seed << ", " << in.points.size() << " points, metric " << int(o.metric) << ", ratio "
                     << o.target_ratio << ", faces " << o.target_faces << ", max distance " << o.max_distance_voxels
                     << ", sigma " << o.sigma_position_voxels << ", normal change " << o.max_normal_change_degrees
                     << ", quality " << o.min_triangle_quality);
        pqdc::Mesh out = in;
        pqdc::decimate(out, o);
        check_closed_same_topology(in, out);
        CHECK(out.triangles.size() < in.triangles.size() + 2 * in.quads.size());
        // No intersection created: where the input has none, the output has none.
        if (self_intersections(split_quads(in)) == 0) {
            ++clean_inputs;
            CHECK(self_intersections(out) == 0);
        }
        if (o.max_distance_voxels > 0) {
            const pqdc::MeshDistance surface(split_quads(in));
            double farthest = 0;
            for (const auto& p : out.points) farthest = std::max(farthest, surface(p));
            CHECK(farthest <= o.max_distance_voxels * voxel);
        }
        pqdc::Mesh threaded = in;
        o.threads = 3;
        pqdc::decimate(threaded, o);
        CHECK(same_bytes(out, threaded));
    }
    CHECK(clean_inputs * 4 >= std::size_t(cases) * 3);  // the intersection check ran on most cases
}

TEST_CASE("decimate: coordinates beyond float's range decimate as scaled ones do", "[decimate]") {
    // The per-face boxes are floats rounded outwards, infinite here: the
    // grid then lists every box in one cell. The collapses are the same as
    // at unit scale (costs and checks scale along).
    const pqdc::Mesh in = dc_sphere(12);
    pqdc::DecimateOptions o;
    o.target_ratio = 0.2;
    pqdc::Mesh unit = in;
    pqdc::DecimateStats unit_stats;
    pqdc::decimate(unit, o, &unit_stats);
    pqdc::Mesh huge = in;
    for (auto& p : huge.points) p *= 1e39;
    pqdc::DecimateStats huge_stats;
    pqdc::decimate(huge, o, &huge_stats);
    CHECK(huge_stats.collapses == unit_stats.collapses);
    CHECK(huge.triangles.size() == unit.triangles.size());
    check_closed_same_topology(in, huge);
}

TEST_CASE("decimate: a noisy torus keeps genus 1 down to a few faces", "[decimate]") {
    const pqdc::Mesh in = torus(48, 24, 2.0, 0.7, 0.02);
    pqdc::Mesh out = in;
    pqdc::DecimateOptions o;
    o.target_faces = 60;
    pqdc::decimate(out, o);
    CHECK(out.triangles.size() <= 200);
    pqdc::Mesh tri_in = in;  // measure_topology counts quads too; Euler characteristic is 0 either way
    check_closed_same_topology(tri_in, out);
    CHECK(pqdc::measure_topology(out).euler_characteristic == 0);
    CHECK(self_intersections(out) == 0);
}

TEST_CASE("decimate: two sheets closer than an edge do not cross", "[decimate]") {
    {  // a thin pancake: two sheets 0.02 apart, edges about 0.13
        const pqdc::Mesh in = pancake(48, 24, 0.01);
        pqdc::Mesh out = in;
        pqdc::DecimateOptions o;
        o.target_ratio = 0.05;
        o.voxel_size = 0.1;
        o.max_normal_change_degrees = 179;
        o.min_triangle_quality = 0;
        pqdc::decimate(out, o);
        check_closed_same_topology(in, out);
        CHECK(self_intersections(out) == 0);
    }
    // A small ball just under the surface of a big one: the chords that
    // coarse faces of the big ball would cut pass through the small ball.
    pqdc::Mesh in = pancake(64, 32, 1.0);
    const pqdc::Mesh ball = pancake(16, 8, 1.0);
    const unsigned offset = unsigned(in.points.size());
    for (const auto& p : ball.points) in.points.push_back(p * 0.1 + openvdb::Vec3d(0, 0, 1 - 0.1 - 0.002));
    for (const auto& t : ball.triangles) in.triangles.emplace_back(t[0] + offset, t[1] + offset, t[2] + offset);
    for (const auto& q : ball.quads) in.quads.emplace_back(q[0] + offset, q[1] + offset, q[2] + offset, q[3] + offset);
    REQUIRE(self_intersections(pqdc::Mesh{in.points, [&] {
                std::vector<openvdb::Vec3I> t = in.triangles;
                for (const auto& q : in.quads) {
                    t.emplace_back(q[0], q[1], q[2]);
                    t.emplace_back(q[0], q[2], q[3]);
                }
                return t;
            }(), {}, {}}) == 0);
    pqdc::Mesh out = in;
    pqdc::DecimateOptions o;
    o.target_ratio = 0.03;
    o.voxel_size = 0.05;
    pqdc::DecimateStats st;
    pqdc::decimate(out, o, &st);
    check_closed_same_topology(in, out);
    CHECK(self_intersections(out) == 0);
    CHECK(st.rejected_intersection > 0);  // the exact test, not luck, kept them apart
    CHECK(out.triangles.size() < in.face_count() / 5);
}

TEST_CASE("decimate: float output is checked as float, far from the origin too", "[decimate]") {
    // A unit sphere and a reversed inner copy a quarter voxel below it (a
    // shell), far from the origin: float's spacing there is about a tenth of
    // the gap. Collapses checked in double and rounded by a float writer made
    // the sheets cross and left the distance bound.
    const pqdc::Mesh uv = pancake(96, 48, 1.0);
    const double voxel = 0.05;
    const openvdb::Vec3d shift(8192, 0, 0);
    pqdc::Mesh in;
    const unsigned n = unsigned(uv.points.size());
    for (const double scale : {1.0, 1.0 - 0.25 * voxel})
        for (const auto& p : uv.points) in.points.push_back(p * scale + shift);
    for (const unsigned base : {0u, n}) {
        auto add = [&](unsigned a, unsigned b, unsigned c) {
            if (base == 0) in.triangles.emplace_back(a, b, c);
            else in.triangles.emplace_back(a + n, c + n, b + n);  // the inner sheet faces inward
        };
        for (const auto& t : uv.triangles) add(t[0], t[1], t[2]);
        for (const auto& q : uv.quads) {
            add(q[0], q[1], q[2]);
            add(q[0], q[2], q[3]);
        }
    }
    auto as_float = [](pqdc::Mesh m) {
        for (auto& p : m.points)
            for (int k = 0; k < 3; ++k) {
                const volatile float f = float(p[k]);  // not double(float(x)): GCC 12 folds it when vectorized
                p[k] = f;
            }
        return m;
    };
    auto pairs = [](const pqdc::Mesh& m) { return pqdc::find_self_intersections(m).pair_count; };
    in = as_float(in);  // what a float file holds
    REQUIRE(pairs(in) == 0);
    const pqdc::MeshDistance to_input(in);
    for (const auto stored : {pqdc::VertexPrecision::float32, pqdc::VertexPrecision::float64}) {
        pqdc::Mesh out = in;
        pqdc::DecimateOptions o;
        o.target_ratio = 0.05;
        o.max_distance_voxels = 0.3;
        o.voxel_size = voxel;
        o.stored_precision = stored;
        pqdc::decimate(out, o);
        const pqdc::Mesh written = as_float(out);
        double farthest = 0;
        for (const auto& p : written.points) farthest = std::max(farthest, to_input(p));
        INFO((stored == pqdc::VertexPrecision::float32 ? "float32" : "float64")
             << ": " << out.triangles.size() << " triangles, " << pairs(written) << " pairs, farthest "
             << farthest / voxel << " voxel");
        if (stored == pqdc::VertexPrecision::float32) {
            CHECK(same_bytes(written, out));  // its points are floats already
            CHECK(pairs(written) == 0);
            CHECK(farthest <= 0.3 * voxel);
            CHECK(out.triangles.size() < in.triangles.size() / 4);
        } else {
            // The same run checked in double: rounding it breaks a guarantee
            // (if this ever holds, the case has lost its point).
            CHECK((pairs(written) > 0 || farthest > 0.3 * voxel));
        }
    }
}

TEST_CASE("decimate: a concave quad is split along its inside diagonal", "[decimate]") {
    // A prism whose caps are concave darts: the shorter diagonal of a dart
    // runs outside it, and splitting along it gave two triangles facing
    // opposite ways, overlapping (8 intersecting pairs from a clean input).
    const openvdb::Vec3d dart[4] = {{0, 0, 0}, {10, -0.5, 0}, {2, 0, 0}, {10, 0.5, 0}};
    pqdc::Mesh in;
    for (double z : {0.0, 1.0})
        for (const auto& p : dart) in.points.push_back(p + openvdb::Vec3d(0, 0, z));
    in.quads.emplace_back(4, 5, 6, 7);  // top, facing +z
    in.quads.emplace_back(0, 3, 2, 1);  // bottom, facing -z
    for (unsigned i = 0; i < 4; ++i) in.quads.emplace_back(i, (i + 1) % 4, (i + 1) % 4 + 4, i + 4);
    REQUIRE(pqdc::find_self_intersections(in).pair_count == 0);
    pqdc::Mesh out = in;
    pqdc::DecimateOptions o;
    o.target_ratio = 1;  // split only
    pqdc::decimate(out, o);
    REQUIRE(out.triangles.size() == 12);
    CHECK(pqdc::find_self_intersections(out).pair_count == 0);
    check_closed_same_topology(in, out);
    for (const auto& t : out.triangles) {  // the caps' triangles face their cap's way
        const openvdb::Vec3d n = (out.points[t[1]] - out.points[t[0]]).cross(out.points[t[2]] - out.points[t[0]]);
        const bool top = t[0] >= 4 && t[1] >= 4 && t[2] >= 4, bottom = t[0] < 4 && t[1] < 4 && t[2] < 4;
        if (top) CHECK(n.z() > 0);
        if (bottom) CHECK(n.z() < 0);
    }
}

TEST_CASE("decimate: same bytes for any thread count", "[decimate]") {
    const pqdc::Mesh in = dc_sphere(24);
    pqdc::Mesh one = in, two = in, four = in;
    pqdc::DecimateOptions o;
    o.target_ratio = 0.05;
    o.threads = 1;
    pqdc::decimate(one, o);
    o.threads = 2;
    pqdc::decimate(two, o);
    o.threads = 4;
    pqdc::decimate(four, o);
    CHECK(same_bytes(one, two));
    CHECK(same_bytes(one, four));
}

TEST_CASE("decimate: progress rises to 1 and false cancels, leaving the mesh as it was", "[decimate]") {
    const pqdc::Mesh in = dc_sphere(24);
    pqdc::DecimateOptions o;
    o.target_ratio = 0.05;
    std::vector<double> seen;
    o.progress = [&seen](double f) {
        seen.push_back(f);
        return true;
    };
    pqdc::Mesh reported = in;
    pqdc::DecimateStats st;
    pqdc::decimate(reported, o, &st);
    REQUIRE(seen.size() > st.passes);  // before each pass, between its stages, and once at the end
    CHECK(seen.front() == 0.0);
    CHECK(seen.back() == 1.0);
    CHECK(std::is_sorted(seen.begin(), seen.end()));
    CHECK(seen[seen.size() / 2] > 0.0);
    // It moves within the passes too (their checks report in slices), not only between them.
    const std::size_t distinct = std::set<double>(seen.begin(), seen.end()).size();
    CHECK(distinct > 4 * st.passes);
    pqdc::Mesh plain = in;
    o.progress = nullptr;
    pqdc::decimate(plain, o);
    CHECK(same_bytes(plain, reported));  // reporting does not change the result

    int calls = 0;
    o.progress = [&calls](double) { return ++calls < 3; };  // cancel at the third call, in the set-up
    pqdc::Mesh cancelled = in;
    CHECK_THROWS_AS(pqdc::decimate(cancelled, o), pqdc::cancelled_error);
    CHECK(calls == 3);
    CHECK(same_bytes(cancelled, in));
}

TEST_CASE("decimate: max distance holds at every vertex", "[decimate]") {
    // Triangles: the bound is to the input surface as decimate triangulates
    // it (quads along the shorter diagonal), which for non-planar quads is
    // not MeshDistance's 0-1-2 / 0-2-3 split.
    const pqdc::Mesh noisy = torus(64, 32, 2.0, 0.7, 0.01, 3);
    pqdc::Mesh in;
    in.points = noisy.points;
    for (const auto& q : noisy.quads) {
        const auto& p = in.points;
        if ((p[q[0]] - p[q[2]]).lengthSqr() <= (p[q[1]] - p[q[3]]).lengthSqr()) {
            in.triangles.emplace_back(q[0], q[1], q[2]);
            in.triangles.emplace_back(q[0], q[2], q[3]);
        } else {
            in.triangles.emplace_back(q[0], q[1], q[3]);
            in.triangles.emplace_back(q[1], q[2], q[3]);
        }
    }
    pqdc::Mesh out = in;
    pqdc::DecimateOptions o;
    o.voxel_size = 0.1;
    o.max_distance_voxels = 0.2;  // 0.02 world units
    pqdc::DecimateStats st;
    pqdc::decimate(out, o, &st);
    CHECK(out.triangles.size() < in.triangles.size() / 3);
    CHECK(st.rejected_distance > 0);  // the limit, not the face count, stopped it
    const pqdc::MeshDistance dist(in);
    double worst = 0;
    for (const auto& p : out.points) worst = std::max(worst, dist(p));
    CHECK(worst <= 0.02);
}

TEST_CASE("decimate: boundaries and non-manifold places stay where they are", "[decimate]") {
    // An open grid (boundary) plus a fin: a third face on one interior edge.
    pqdc::Mesh m;
    const int n = 20;
    for (int j = 0; j <= n; ++j)
        for (int i = 0; i <= n; ++i) m.points.emplace_back(i, j, 0.1 * std::sin(i * 0.7) * std::cos(j * 0.5));
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            const unsigned a = unsigned(j * (n + 1) + i);
            m.triangles.emplace_back(a, a + 1, a + n + 2);
            m.triangles.emplace_back(a, a + n + 2, a + n + 1);
        }
    const unsigned e0 = unsigned(10 * (n + 1) + 10), e1 = e0 + 1;  // an interior edge
    m.points.emplace_back(10.5, 10, 3);
    m.triangles.emplace_back(e0, e1, unsigned(m.points.size() - 1));
    const pqdc::TopologyReport before = pqdc::measure_topology(m);
    pqdc::Mesh out = m;
    pqdc::DecimateOptions o;
    o.target_ratio = 0.2;
    pqdc::DecimateStats st;
    pqdc::decimate(out, o, &st);
    CHECK(out.triangles.size() < m.triangles.size());
    CHECK(st.locked_vertices >= std::size_t(4 * n + 3));
    const pqdc::TopologyReport after = pqdc::measure_topology(out);
    CHECK(after.boundary_edge_count == before.boundary_edge_count);
    CHECK(after.non_manifold_edge_count == before.non_manifold_edge_count);
    std::set<std::array<double, 3>> kept;
    for (const auto& p : out.points) kept.insert({p[0], p[1], p[2]});
    for (int i = 0; i <= n; ++i) {  // boundary points, bit for bit
        CHECK(kept.count({double(i), 0.0, m.points[i][2]}) == 1);
    }
    CHECK(kept.count({10.5, 10.0, 3.0}) == 1);
    CHECK(self_intersections(out) == 0);
}

namespace {

/// Area-weighted vertex normals of a mesh's faces (quads split 0-1-2 / 0-2-3), unit.
std::vector<openvdb::Vec3d> face_vertex_normals(const pqdc::Mesh& m) {
    std::vector<openvdb::Vec3d> n(m.points.size(), openvdb::Vec3d(0.0));
    auto add = [&](unsigned a, unsigned b, unsigned c) {
        const openvdb::Vec3d f = (m.points[b] - m.points[a]).cross(m.points[c] - m.points[a]);
        n[a] += f;
        n[b] += f;
        n[c] += f;
    };
    for (const auto& t : m.triangles) add(t[0], t[1], t[2]);
    for (const auto& q : m.quads) {
        add(q[0], q[1], q[2]);
        add(q[0], q[2], q[3]);
    }
    for (auto& v : n) v.normalize();
    return n;
}

double degrees_between(const openvdb::Vec3d& a, const openvdb::Vec3d& b) {
    return std::acos(std::clamp(a.dot(b) / (a.length() * b.length()), -1.0, 1.0)) * 180 / M_PI;
}

}  // namespace

TEST_CASE("decimate: the input's vertex normals are carried over, interpolated where vertices moved", "[decimate]") {
    SECTION("a sphere with exact normals: radial after decimation, far closer than the facets'") {
        pqdc::Mesh in = dc_sphere(32);
        for (const auto& p : in.points) in.normals.push_back(p.unitSafe());  // the procedural sphere is centred at 0
        pqdc::Mesh out = in;
        pqdc::DecimateOptions o;
        o.target_ratio = 0.1;
        o.threads = 1;
        pqdc::decimate(out, o);
        REQUIRE(out.normals.size() == out.points.size());
        const std::vector<openvdb::Vec3d> facets = face_vertex_normals(out);
        double worst = 0, worst_facets = 0;
        for (std::size_t i = 0; i < out.points.size(); ++i) {
            CHECK(std::abs(out.normals[i].length() - 1) < 1e-12);
            worst = std::max(worst, degrees_between(out.normals[i], out.points[i]));
            worst_facets = std::max(worst_facets, degrees_between(facets[i], out.points[i]));
        }
        CHECK(worst < 0.5);
        CHECK(worst < 0.25 * worst_facets);
        pqdc::Mesh two = in;
        o.threads = 2;
        pqdc::decimate(two, o);
        CHECK(same_bytes(out, two));
        CHECK(std::memcmp(out.normals.data(), two.normals.data(), out.normals.size() * sizeof(out.normals[0])) == 0);
        // The positions are those of a decimation without normals.
        pqdc::Mesh plain = in;
        plain.normals.clear();
        pqdc::decimate(plain, o);
        CHECK(same_bytes(out, plain));
        CHECK(plain.normals.empty());
    }
    SECTION("vertices that stay (an open boundary) keep their normals bit for bit") {
        pqdc::Mesh m;
        const int n = 16;
        for (int j = 0; j <= n; ++j)
            for (int i = 0; i <= n; ++i) {
                m.points.emplace_back(i, j, 0.2 * std::sin(i * 0.4));
                m.normals.push_back(openvdb::Vec3d(-0.08 * std::cos(i * 0.4), 0.001 * j, 1).unitSafe());
            }
        for (int j = 0; j < n; ++j)
            for (int i = 0; i < n; ++i) {
                const unsigned a = unsigned(j * (n + 1) + i);
                m.triangles.emplace_back(a, a + 1, a + n + 2);
                m.triangles.emplace_back(a, a + n + 2, a + n + 1);
            }
        pqdc::Mesh out = m;
        pqdc::DecimateOptions o;
        o.target_ratio = 0.2;
        pqdc::decimate(out, o);
        REQUIRE(out.normals.size() == out.points.size());
        std::size_t kept = 0, moved = 0;
        for (std::size_t i = 0; i < out.points.size(); ++i) {
            const auto at = std::find(m.points.begin(), m.points.end(), out.points[i]);
            if (at != m.points.end()) {
                ++kept;
                CHECK(out.normals[i] == m.normals[std::size_t(at - m.points.begin())]);
            } else {
                ++moved;
                CHECK(out.normals[i].z() > 0.99);  // between the input's, which lean at most 4.6 degrees
            }
        }
        CHECK(kept >= std::size_t(4 * n));  // the boundary
        CHECK(moved > 0);
    }
    SECTION("two sheets 0.02 apart: no vertex takes the other sheet's normal") {
        pqdc::Mesh in = pancake(48, 24, 0.01);
        in.normals = face_vertex_normals(in);
        pqdc::Mesh out = in;
        pqdc::DecimateOptions o;
        o.target_ratio = 0.1;
        o.voxel_size = 0.1;
        pqdc::decimate(out, o);
        // Away from the rim (where the normal turns over within 0.01), each
        // sheet's normals point away from the other sheet.
        std::size_t sheet = 0, wrong_side = 0;
        for (std::size_t i = 0; i < out.points.size(); ++i) {
            const auto& p = out.points[i];
            if (p.x() * p.x() + p.y() * p.y() > 0.8) continue;
            ++sheet;
            wrong_side += !(out.normals[i].z() * p.z() > 0 && std::abs(out.normals[i].z()) > 0.9);
        }
        CHECK(sheet > 50);
        CHECK(wrong_side == 0);
    }
    SECTION("a normal count other than the point count is refused, the mesh left as it was") {
        pqdc::Mesh m = torus(8, 6, 2, 0.5);
        m.normals.assign(m.points.size() - 1, openvdb::Vec3d(0, 0, 1));
        const pqdc::Mesh copy = m;
        pqdc::DecimateOptions o;
        o.target_ratio = 0.5;
        CHECK_THROWS_AS(pqdc::decimate(m, o), pqdc::input_error);
        CHECK_THROWS_WITH(pqdc::decimate(m, o), Catch::Contains("47 vertex normals for 48 points"));
        CHECK(same_bytes(m, copy));
        CHECK(m.normals.size() == copy.normals.size());
    }
}

TEST_CASE("decimate: sigma_position_auto reads the input's noise", "[decimate]") {
    // A dual-contouring sphere (radius 25 voxels), clean and with Gaussian
    // noise of 0.3 voxel along the vertex normals (the unit is the mean edge
    // length, about a voxel here, as pqdc-decimate's default).
    const pqdc::Mesh clean = dc_sphere(64);
    pqdc::DecimateOptions o;
    o.target_ratio = 0.5;
    REQUIRE(o.sigma_position_voxels == pqdc::sigma_position_auto);
    pqdc::DecimateStats st;
    pqdc::Mesh m = clean;
    pqdc::decimate(m, o, &st);
    CHECK(st.noise_voxels < 0.05);            // curvature only: about 1 / (2 x 25)
    CHECK(st.sigma_position_voxels == 0.02);  // the floor

    pqdc::Mesh noisy = clean;
    std::mt19937 rng(7);
    std::normal_distribution<double> g(0, 1);
    double edge = 0;
    for (const auto& q : clean.triangles) edge += (clean.points[q[0]] - clean.points[q[1]]).length();
    edge /= double(clean.triangles.size());
    for (auto& p : noisy.points) p += p.unitSafe() * (0.3 * edge * g(rng));  // the sphere's normal
    m = noisy;
    pqdc::decimate(m, o, &st);
    CHECK(st.noise_voxels == Approx(0.3).epsilon(0.2));
    CHECK(st.sigma_position_voxels == Approx(0.7 * st.noise_voxels));

    o.sigma_position_voxels = 0.1;  // an explicit value is used as given, nothing estimated
    m = noisy;
    pqdc::decimate(m, o, &st);
    CHECK(st.sigma_position_voxels == 0.1);
    CHECK(st.noise_voxels == 0);
}

TEST_CASE("decimate: option and input errors name the problem", "[decimate]") {
    pqdc::Mesh m = torus(8, 6, 2, 0.5);
    pqdc::DecimateOptions none;
    CHECK_THROWS_AS(pqdc::decimate(m, none), pqdc::option_error);
    CHECK_THROWS_WITH(pqdc::decimate(m, none), Catch::Contains("no target"));
    pqdc::DecimateOptions o;
    o.target_ratio = 1.5;
    CHECK_THROWS_WITH(pqdc::decimate(m, o), Catch::Contains("target_ratio"));
    o.target_ratio = 0.5;
    o.metric = static_cast<pqdc::DecimateMetric>(9);  // a cast integer picked a metric silently
    CHECK_THROWS_WITH(pqdc::decimate(m, o), Catch::Contains("metric holds 9"));
    o.metric = pqdc::DecimateMetric::triangle;
    o.sigma_position_voxels = 0;
    CHECK_THROWS_WITH(pqdc::decimate(m, o), Catch::Contains("sigma_position_voxels"));
    o.sigma_position_voxels = 0.1;
    o.max_normal_change_degrees = 180;
    CHECK_THROWS_WITH(pqdc::decimate(m, o), Catch::Contains("max_normal_change_degrees"));
    o.max_normal_change_degrees = 60;
    pqdc::Mesh bad = m;
    bad.triangles.emplace_back(0, 1, 9999);
    CHECK_THROWS_AS(pqdc::decimate(bad, o), pqdc::input_error);
    CHECK_THROWS_WITH(pqdc::decimate(bad, o), Catch::Contains("point 9999"));
    bad = m;  // faces repeating a point (welded STL needles) are left out, not refused
    bad.triangles.emplace_back(0, 1, 1);
    bad.quads.emplace_back(2, 2, 2, 2);
    pqdc::Mesh needles = bad;
    pqdc::DecimateStats dropped;
    pqdc::decimate(needles, o, &dropped);
    CHECK(dropped.dropped_faces == 2);
    pqdc::Mesh clean = m;
    pqdc::DecimateStats kept;
    pqdc::decimate(clean, o, &kept);
    CHECK(same_bytes(needles, clean));
    CHECK(dropped.input_faces == kept.input_faces);
    bad = m;  // a quad with a corner repeated next to itself is a triangle
    bad.quads.emplace_back(0, 0, 1, 2);
    pqdc::decimate(bad, o, &dropped);
    CHECK(dropped.dropped_faces == 0);
    CHECK(dropped.input_faces == kept.input_faces + 1);
    bad = m;
    bad.points[3] = openvdb::Vec3d(NAN, 0, 0);
    const pqdc::Mesh copy = bad;
    CHECK_THROWS_WITH(pqdc::decimate(bad, o), Catch::Contains("NaN"));
    CHECK(bad.quads.size() == copy.quads.size());  // untouched on error

    // Over the memory limit: refused before anything is allocated, the mesh as it was.
    pqdc::Mesh big = m;
    const std::size_t triangles = big.triangles.size() + 2 * big.quads.size();
    o.memory_limit_bytes = triangles * pqdc::kDecimateBytesPerTriangle - 1;
    CHECK_THROWS_AS(pqdc::decimate(big, o), pqdc::resource_error);
    CHECK_THROWS_WITH(pqdc::decimate(big, o), Catch::Contains(std::to_string(triangles) + " triangles") &&
                                                  Catch::Contains("raise the memory limit"));
    CHECK(same_bytes(big, m));
    // The same check for callers that know only the count (pqdc-decimate from a header).
    CHECK_THROWS_AS(pqdc::check_decimate_memory(triangles, o), pqdc::resource_error);
    CHECK_NOTHROW(pqdc::check_decimate_memory(triangles - 1, o));
    o.memory_limit_bytes = triangles * pqdc::kDecimateBytesPerTriangle;  // just enough
    CHECK_NOTHROW(pqdc::decimate(big, o));
}

#ifdef PQDC_DECIMATE_PATH
TEST_CASE("pqdc-decimate CLI: success and clear errors", "[decimate]") {
    pqdc_test::ScratchDir dir("decimate_cli");
    const std::string in = dir.path("torus.off"), out = dir.path("out.ply");
    pqdc::write_mesh(torus(32, 16, 2, 0.6, 0.01), in);
    auto run = [&](std::vector<std::string> args) {
        pqdc_test::RunSpec spec;
        spec.args = std::move(args);
        return pqdc_test::run_program(PQDC_DECIMATE_PATH, spec);
    };
    auto ok = run({in, "-o", out, "--target-ratio", "0.25", "--quiet"});
    REQUIRE(ok.exit_code == 0);
    const pqdc::Mesh m = pqdc::read_mesh(out);
    CHECK(m.triangles.size() <= 256);
    CHECK(pqdc::measure_topology(m).closed());

    // --opt=value as in every app, and double precision on request.
    const std::string precise = dir.path("double.ply");
    REQUIRE(run({in, "-o", precise, "--target-ratio=0.25", "--precision", "double", "-q"}).exit_code == 0);
    CHECK_THAT(pqdc_test::read_file(precise).substr(0, 256), Catch::Contains("property double x"));
    CHECK(pqdc::read_mesh(precise).triangles.size() == m.triangles.size());

    // STL input (a triangle soup on disk) is welded back into the closed torus.
    const std::string stl = dir.path("torus.stl"), from_stl = dir.path("from_stl.ply");
    pqdc::write_mesh(pqdc::read_mesh(in), stl);
    REQUIRE(run({stl, "-o", from_stl, "--target-ratio", "0.25", "-q"}).exit_code == 0);
    const pqdc::Mesh welded = pqdc::read_mesh(from_stl);
    CHECK(welded.triangles.size() <= 256);
    CHECK(pqdc::measure_topology(welded).closed());

    // A file with vertex normals gives one with normals: carried over, unit.
    const std::string with_normals = dir.path("normals.ply"), decimated = dir.path("normals_out.ply");
    pqdc::Mesh shaded = pqdc::read_mesh(in);
    for (const auto& p : shaded.points) shaded.normals.push_back((p - p.z() * openvdb::Vec3d(0, 0, 1)).unitSafe());
    pqdc::write_mesh(shaded, with_normals);
    REQUIRE(run({with_normals, "-o", decimated, "--target-ratio", "0.25", "-q"}).exit_code == 0);
    CHECK_THAT(pqdc_test::read_file(decimated).substr(0, 256), Catch::Contains("property float nx"));
    const pqdc::Mesh shaded_out = pqdc::read_mesh(decimated);
    REQUIRE(shaded_out.normals.size() == shaded_out.points.size());
    for (const auto& n : shaded_out.normals) CHECK(std::abs(n.length() - 1) < 1e-6);
    // The summary and --stats say so; a format without normals gets a warning.
    const std::string normals_stats = dir.path("normals.json");
    auto said = run({with_normals, "-o", decimated, "--target-ratio", "0.25", "--stats", normals_stats});
    CHECK_THAT(said.err, Catch::Contains("vertex normals carried over"));
    CHECK(nlohmann::json::parse(pqdc_test::read_file(normals_stats))["vertex_normals"] == true);
    said = run({with_normals, "-o", dir.path("normals.stl"), "--target-ratio", "0.25", "--stats", normals_stats});
    REQUIRE(said.exit_code == 0);
    CHECK_THAT(said.err, Catch::Contains("warning: the input's vertex normals are not written: STL holds none"));
    CHECK(nlohmann::json::parse(pqdc_test::read_file(normals_stats))["vertex_normals"] == false);

    // --stats: the figures as JSON, its triangle count the written mesh's.
    const std::string stats = dir.path("stats.json");
    REQUIRE(run({in, "-o", out, "--target-ratio", "0.25", "-q", "--stats", stats}).exit_code == 0);
    const auto j = nlohmann::json::parse(pqdc_test::read_file(stats));
    CHECK(j["decimate"]["output_triangles"] == m.triangles.size());
    CHECK(j["decimate"]["output_vertices"] == m.points.size());
    CHECK(j["decimate"]["input_triangles"] == 2 * 32 * 16);
    CHECK(j["decimate"]["input_triangles"].get<std::size_t>() - j["decimate"]["output_triangles"].get<std::size_t>() ==
          2 * j["decimate"]["collapses"].get<std::size_t>());
    CHECK(j["seconds"]["decimate"].get<double>() >= 0);
    CHECK(j["input"] == in);
    // An unwritable --stats or -o fails before any work, writing nothing.
    const std::string nowhere = dir.path("no/such/dir/s.json"), fresh = dir.path("fresh.ply");
    auto bad = run({in, "-o", fresh, "--target-ratio", "0.25", "--stats", nowhere});
    CHECK(bad.exit_code == 1);
    CHECK_THAT(bad.err, Catch::Contains("--stats") && Catch::Contains("does not exist"));
    CHECK_FALSE(std::filesystem::exists(fresh));
    bad = run({in, "-o", dir.path("no/such/dir/o.ply"), "--target-ratio", "0.25"});
    CHECK(bad.exit_code == 1);
    CHECK_THAT(bad.err, Catch::Contains("-o") && Catch::Contains("does not exist"));

    // -o - with --format: the same bytes on standard output as in a file.
    const auto piped = run({in, "-o", "-", "--format", "ply", "--target-ratio", "0.25", "-q"});
    REQUIRE(piped.exit_code == 0);
    CHECK(piped.out == pqdc_test::read_file(out));

    const std::string missing = dir.path("absent.ply");
    auto r = run({in, "-o", "-", "--target-faces", "10"});
    CHECK(r.exit_code == 2);
    CHECK_THAT(r.err, Catch::Contains("--format"));
    r = run({in, "-o", missing, "--target-faces", "10", "--precision", "half"});
    CHECK(r.exit_code == 2);
    CHECK_THAT(r.err, Catch::Contains("--precision"));
    r = run({in, "-o", missing});
    CHECK(r.exit_code == 2);
    CHECK_THAT(r.err, Catch::Contains("no target"));
    r = run({dir.path("nope.obj"), "-o", missing, "--target-faces", "10"});
    CHECK(r.exit_code == 1);
    CHECK_THAT(r.err, Catch::Contains("nope.obj"));
    r = run({in, "-o", dir.path("out.xyz"), "--target-faces", "10"});
    CHECK(r.exit_code == 2);
    CHECK_THAT(r.err, Catch::Contains("out.xyz"));
    r = run({in, "-o", missing, "--target-ratio", "2"});
    CHECK(r.exit_code == 2);
    CHECK_THAT(r.err, Catch::Contains("--target-ratio"));
    r = run({in, "-o", missing, "--metric", "cubic", "--target-faces", "10"});
    CHECK(r.exit_code == 2);
    CHECK_THAT(r.err, Catch::Contains("--metric"));
    r = run({in, "--target-faces", "10"});
    CHECK(r.exit_code == 2);
    CHECK_THAT(r.err, Catch::Contains("-o"));
    // A directory as input is named as such, not as one that -o "lies inside".
    r = run({dir.dir(), "-o", missing, "--target-ratio", "0.5"});
    CHECK(r.exit_code == 1);
    CHECK_THAT(r.err, Catch::Contains("not a regular file (a directory)"));
    // A bad point names the file and the fix; one beyond float's range names --precision.
    pqdc::Mesh broken = pqdc::read_mesh(in);
    broken.points[5][0] = std::nan("");
    const std::string with_nan = dir.path("nan.obj");
    pqdc::write_mesh(broken, with_nan);
    r = run({with_nan, "-o", missing, "--target-ratio", "0.5"});
    CHECK(r.exit_code == 1);
    CHECK_THAT(r.err, Catch::Contains("'" + with_nan + "': decimate: point 5") &&
                          Catch::Contains("fix the point or drop the faces using it"));
    broken.points[5][0] = 1e300;
    const std::string far = dir.path("far.obj");
    pqdc::write_mesh(broken, far, pqdc::MeshWriteOptions{pqdc::MeshFormat::obj, pqdc::VertexPrecision::float64});
    r = run({far, "-o", missing, "--target-ratio", "0.5"});
    CHECK(r.exit_code == 1);
    CHECK_THAT(r.err, Catch::Contains("beyond float's range; write it with double precision (--precision double: "));
    r = run({in, "-o", missing, "--target-faces", "10", "--memory-limit", "0"});
    CHECK(r.exit_code == 2);
    CHECK_THAT(r.err, Catch::Contains("--memory-limit"));
    CHECK_FALSE(std::filesystem::exists(missing));  // no partial output
}

TEST_CASE("pqdc-decimate refuses a mesh over --memory-limit, with no output", "[decimate]") {
    pqdc_test::ScratchDir dir("decimate_memory");
    // About 8,600 triangles: 300 bytes each is 2.5 MiB, over a 1 MiB limit.
    const std::string in = dir.path("sphere.ply"), out = dir.path("out.ply");
    const pqdc::Mesh sphere = dc_sphere(32);
    REQUIRE(sphere.triangles.size() * pqdc::kDecimateBytesPerTriangle > (std::size_t(1) << 20));
    pqdc::write_mesh(sphere, in);
    pqdc_test::RunSpec spec;
    spec.args = {in, "-o", out, "--target-ratio", "0.1", "--memory-limit", "1"};
    auto r = pqdc_test::run_program(PQDC_DECIMATE_PATH, spec);
    CHECK(r.exit_code == 1);
    // Refused from the PLY header's face count, before the file is read.
    CHECK_THAT(r.err, Catch::Contains("'" + in + "' announces " + std::to_string(sphere.triangles.size()) +
                                      " faces in its header, refused before reading it") &&
                          Catch::Contains("triangles would need about") && Catch::Contains("--memory-limit"));
    CHECK_FALSE(std::filesystem::exists(out));
    // OBJ announces no count: refused after reading, by decimate() itself.
    const std::string obj = dir.path("sphere.obj");
    pqdc::write_mesh(sphere, obj);
    spec.args = {obj, "-o", out, "--target-ratio", "0.1", "--memory-limit", "1"};
    r = pqdc_test::run_program(PQDC_DECIMATE_PATH, spec);
    CHECK(r.exit_code == 1);
    CHECK_THAT(r.err, Catch::Contains("triangles would need about") && Catch::Contains("raise the memory limit"));
    CHECK(r.err.find("announces") == std::string::npos);
    CHECK_FALSE(std::filesystem::exists(out));
    spec.args = {in, "-o", out, "--target-ratio", "0.1", "--memory-limit", "64"};
    REQUIRE(pqdc_test::run_program(PQDC_DECIMATE_PATH, spec).exit_code == 0);
    CHECK(pqdc::read_mesh(out).triangles.size() <= sphere.triangles.size() / 10 + 1);
}
#endif

#if defined(PQDC_CLI_PATH)
TEST_CASE("pqdc-decimate: progress silent off a terminal, shown with --progress", "[decimate]") {
    pqdc_test::ScratchDir dir("decimate_progress");
    // About 0.4 M triangles: long enough a run for the line (drawn from 0.2 s on).
    const std::string in = dir.path("sphere.ply"), out = dir.path("out.ply");
    pqdc::write_mesh(dc_sphere(200), in);
    pqdc_test::RunSpec spec;
    spec.args = {in, "-o", out, "--target-ratio", "0.1"};
    auto r = pqdc_test::run_program(PQDC_DECIMATE_PATH, spec);
    REQUIRE(r.exit_code == 0);
    CHECK(r.err.find('%') == std::string::npos);
    const std::string quiet_bytes = pqdc_test::read_file(out);
    spec.args.push_back("--progress");
    r = pqdc_test::run_program(PQDC_DECIMATE_PATH, spec);
    REQUIRE(r.exit_code == 0);
    INFO(r.err);
    CHECK(std::regex_search(r.err, std::regex("pqdc-decimate: (reading|decimating|writing)[^\\r]* [0-9]+%")));
    CHECK(pqdc_test::read_file(out) == quiet_bytes);
}

TEST_CASE("pqdc --decimate: decimates the extracted mesh, refuses stray targets", "[decimate]") {
    pqdc_test::ScratchDir dir("decimate_pqdc_cli");
    auto run = [&](std::vector<std::string> args) {
        pqdc_test::RunSpec spec;
        spec.args = std::move(args);
        return pqdc_test::run_program(PQDC_CLI_PATH, spec);
    };
    const std::string full = dir.path("full.ply"), dec = dir.path("dec.ply");
    REQUIRE(run({"--procedural", "sphere", "--resolution", "24", "-o", full, "--quiet"}).exit_code == 0);
    const std::string stats = dir.path("dec.json");
    auto r = run({"--procedural", "sphere", "--resolution", "24", "-o", dec, "--decimate", "--target-ratio", "0.2",
                  "--stats", stats, "--quiet"});
    REQUIRE(r.exit_code == 0);
    const pqdc::Mesh a = pqdc::read_mesh(full), b = pqdc::read_mesh(dec);
    CHECK(b.triangles.size() <= (a.triangles.size() + 4) / 5);
    CHECK(pqdc::measure_topology(b).closed());
    // --stats describes the decimation too: its output is the written mesh.
    const auto j = nlohmann::json::parse(pqdc_test::read_file(stats));
    CHECK(j["triangles"].get<std::size_t>() == a.triangles.size());
    CHECK(j["decimate"]["input_triangles"].get<std::size_t>() == a.triangles.size());
    CHECK(j["decimate"]["output_triangles"].get<std::size_t>() == b.triangles.size());
    CHECK(j["decimate"]["output_vertices"].get<std::size_t>() == b.points.size());  // "vertices" is the extraction's
    CHECK(j["decimate"]["collapses"].get<std::size_t>() * 2 == a.triangles.size() - b.triangles.size());
    CHECK(j["seconds"]["decimate"].get<double>() > 0);
    // The summary's last line names the written mesh's count, not only the extraction's.
    r = run({"--procedural", "sphere", "--resolution", "24", "-o", dec, "--decimate", "--target-ratio", "0.2"});
    REQUIRE(r.exit_code == 0);
    CHECK_THAT(r.err, Catch::Contains("; decimated to " + std::to_string(b.triangles.size()) + " triangles and " +
                                      std::to_string(b.points.size()) + " vertices; wrote"));
    CHECK_THAT(r.err, !Catch::Contains("decimation stopped at"));
    // A target that the fixed border of a cut mesh keeps out of reach is named.
    r = run({"--procedural", "sphere", "--resolution", "24", "--bbox", "0,0,0,1,1,1", "-o", dec, "--decimate",
             "--target-faces", "10"});
    REQUIRE(r.exit_code == 0);
    CHECK_THAT(r.err, Catch::Contains("warning: decimation stopped at") && Catch::Contains("above --target-faces 10"));
    // A tiny ratio is named as given (it printed as 0.000000).
    r = run({"--procedural", "sphere", "--resolution", "24", "--bbox", "0,0,0,1,1,1", "-o", dec, "--decimate",
             "--target-ratio", "1e-300"});
    REQUIRE(r.exit_code == 0);
    CHECK_THAT(r.err, Catch::Contains("above --target-ratio 1e-300:"));
    // Over the memory limit for the decimation (not the extraction), the
    // refusal names the option (it said only "raise the memory limit").
    const std::string big = dir.path("big.ply");
    r = run({"--procedural", "sphere", "--resolution", "160", "-o", big, "--decimate", "--target-ratio", "0.1",
             "--memory-limit", "16"});
    CHECK(r.exit_code == 1);
    CHECK_THAT(r.err, Catch::Contains("decimate:") && Catch::Contains("--memory-limit MIB"));
    CHECK(!std::filesystem::exists(big));
    const std::string none = dir.path("none.ply");
    r = run({"--procedural", "sphere", "-o", none, "--target-faces", "100"});
    CHECK(r.exit_code == 2);
    CHECK_THAT(r.err, Catch::Contains("--decimate"));
    r = run({"--procedural", "sphere", "-o", none, "--decimate"});
    CHECK(r.exit_code == 2);
    CHECK_THAT(r.err, Catch::Contains("needs a target"));
    r = run({"--procedural", "sphere", "-o", none, "--decimate", "--max-distance", "-1"});
    CHECK(r.exit_code == 2);
    CHECK_THAT(r.err, Catch::Contains("--max-distance"));
    CHECK_FALSE(std::filesystem::exists(none));
}
#endif
