// Stage "untangle" (src/lattice/untangle.hpp): outputs free of
// self-intersections, checked with the exact finder, in both modes.
#include "pqdc/adaptive.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/noise.hpp"
#include "pqdc/procedural.hpp"
#include "pqdc/exceptions.hpp"
#include "pqdc/self_intersections.hpp"
#include "adaptive/untangle.hpp"
#include "lattice/untangle.hpp"
#include "measure/mesh_internal.hpp"
#include "uniform/quad_star_check.hpp"
#include "uniform/safe_positions.hpp"
#include "random.hpp"

#include <catch2/catch.hpp>
#include <openvdb/tools/LevelSetSphere.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <set>
#include <sstream>
#include <vector>

namespace {

using openvdb::Coord;
using openvdb::Vec3d;

/// The quads (cyclic vertex lists) around the crossing edges of one cell at
/// the origin with the given configuration: the cell's patch vertices at
/// their safe positions, every neighbour cell a single vertex at its center.
pqdc::Mesh local_patch_mesh(std::uint8_t config, std::uint8_t joined) {
    using namespace pqdc::detail;
    pqdc::Mesh m;
    const EdgeGroups groups = edge_groups(config, joined);
    for (int g = 0; g < groups.count; ++g) m.points.push_back(safe_patch_position(Coord(0), config, joined, g));
    std::map<Coord, unsigned> neighbour;
    auto vertex = [&](const Coord& c) {
        auto it = neighbour.find(c);
        if (it != neighbour.end()) return it->second;
        m.points.push_back(c.asVec3d() + Vec3d(0.5));
        return neighbour[c] = unsigned(m.points.size() - 1);
    };
    for (int e = 0; e < 12; ++e) {
        if (groups.group[e] < 0) continue;
        const int axis = e >> 2, u = e & 1, v = (e >> 1) & 1, nu = (axis + 1) % 3, nv = (axis + 2) % 3;
        const int du[4] = {u - 1, u, u, u - 1}, dv[4] = {v - 1, v - 1, v, v};
        openvdb::Vec4I q;
        for (int k = 0; k < 4; ++k) {
            Coord c(0);
            c[nu] = du[k];
            c[nv] = dv[k];
            q[k] = c == Coord(0) ? unsigned(groups.group[e]) : vertex(c);
        }
        m.quads.push_back(q);
    }
    return m;
}

/// Every pair of the mesh's quads, each split along either diagonal.
std::string check_all_splits(const pqdc::Mesh& m) {
    auto split = [](const openvdb::Vec4I& q, int d, std::vector<openvdb::Vec3I>& out) {
        if (d == 0) {
            out.emplace_back(q[0], q[1], q[2]);
            out.emplace_back(q[0], q[2], q[3]);
        } else {
            out.emplace_back(q[0], q[1], q[3]);
            out.emplace_back(q[1], q[2], q[3]);
        }
    };
    for (std::size_t i = 0; i < m.quads.size(); ++i)
        for (std::size_t j = i; j < m.quads.size(); ++j)
            for (int di = 0; di < 2; ++di)
                for (int dj = 0; dj < 2; ++dj) {
                    if (i == j && dj != di) continue;
                    pqdc::Mesh t;
                    t.points = m.points;
                    split(m.quads[i], di, t.triangles);
                    if (j != i) split(m.quads[j], dj, t.triangles);
                    if (!pqdc::find_self_intersections(t).none())
                        return "quads " + std::to_string(i) + ", " + std::to_string(j) + " splits " +
                               std::to_string(di) + std::to_string(dj);
                }
    return "";
}

openvdb::FloatGrid::Ptr dense_grid(int n, const std::function<double(const Vec3d&)>& f) {
    auto grid = openvdb::FloatGrid::create(3.0f);
    grid->setGridClass(openvdb::GRID_LEVEL_SET);
    auto acc = grid->getAccessor();
    for (int x = -2; x <= n + 2; ++x)
        for (int y = -2; y <= n + 2; ++y)
            for (int z = -2; z <= n + 2; ++z)
                acc.setValue(Coord(x, y, z), float(std::max(-3.0, std::min(3.0, f(Vec3d(x, y, z))))));
    return grid;
}

struct Case {
    std::string name;
    openvdb::FloatGrid::Ptr grid;
};

std::vector<Case> hard_cases() {
    std::vector<Case> cases;
    pqdc_test::Random rng(11);
    // Pure noise: signs at random, nearly every cell ambiguous.
    cases.push_back({"random signs", dense_grid(14, [&](const Vec3d&) { return rng.uniform(-1.0, 1.0); })});
    // A sphere with 0.3 voxel noise on every active value.
    auto sphere = dense_grid(20, [](const Vec3d& p) { return (p - Vec3d(10.2, 9.7, 10.1)).length() - 7.3; });
    pqdc::add_gaussian_noise(*sphere, 0.3, 5);
    cases.push_back({"noisy sphere", sphere});
    // A tilted plate thinner than a voxel (two sheets in single cells).
    const Vec3d n = Vec3d(1.0, 0.37, 0.21).unit();
    cases.push_back({"thin sheet", dense_grid(16, [&](const Vec3d& p) { return std::abs((p - Vec3d(8.1)).dot(n)) - 0.3; })});
    // Two spheres 0.2 voxel apart.
    cases.push_back({"near-touching spheres", dense_grid(20, [](const Vec3d& p) {
                         return std::min((p - Vec3d(5.6, 10.1, 9.8)).length() - 4.9,
                                         (p - Vec3d(15.6, 10.3, 10.1)).length() - 4.9);
                     })});
    return cases;
}

}  // namespace

TEST_CASE("points as stored in float are rounded in every coordinate", "[untangle]") {
    // GCC 12.2 at -O2/-O3 folds Vec3d(Vec3f(p)) into a copy of x and y in
    // some contexts (a function returning the rounded vector: only z was
    // rounded), which would have the float check test points no float file
    // holds. A guard: the loop here was not seen miscompiled.
    std::vector<openvdb::Vec3d> points;
    for (int i = 1; i <= 64; ++i) points.emplace_back(1.0 / (3 * i), 2.0 / (7 * i) + 1000, -1.0 / (11 * i) + 4096.1);
    const std::vector<openvdb::Vec3d> stored = pqdc::detail::points_as_stored(points, pqdc::VertexPrecision::float32);
    REQUIRE(stored.size() == points.size());
    for (std::size_t i = 0; i < points.size(); ++i)
        for (int k = 0; k < 3; ++k) {
            const volatile float f = float(points[i][k]);
            const float expected = f;
            CHECK(stored[i][k] == double(expected));
            CHECK(stored[i][k] != points[i][k]);  // none of them is a float
        }
    CHECK(pqdc::detail::points_as_stored(points, pqdc::VertexPrecision::float64) == points);
}

TEST_CASE("safe patch positions: every configuration and ambiguity choice, every split, is intersection-free",
          "[untangle]") {
    int variants = 0, multi = 0;
    for (int config = 1; config < 255; ++config) {
        std::set<std::vector<int>> seen;
        for (int joined = 0; joined < 64; ++joined) {
            const auto g = pqdc::detail::edge_groups(std::uint8_t(config), std::uint8_t(joined));
            if (!seen.insert(std::vector<int>(g.group, g.group + 12)).second) continue;
            ++variants;
            multi += g.count > 1;
            INFO("config " << config << " joined " << joined);
            CHECK(check_all_splits(local_patch_mesh(std::uint8_t(config), std::uint8_t(joined))) == "");
        }
    }
    CHECK(variants > 254);
    CHECK(multi > 20);  // the ambiguous configurations were exercised
}

TEST_CASE("untangle: contract violations are reported, not hidden", "[untangle]") {
    // Two crossing triangles whose safe positions still cross.
    pqdc::Mesh m;
    m.points = {Vec3d(0, 0, 0), Vec3d(2, 0, 0), Vec3d(0, 2, 0), Vec3d(0.5, 0.5, -1), Vec3d(0.5, 0.5, 1),
                Vec3d(1.5, 1.5, 1)};
    m.triangles = {openvdb::Vec3I(0, 1, 2), openvdb::Vec3I(3, 4, 5)};
    pqdc::detail::UntangleCounters c;
    pqdc::Mesh bad = m;
    CHECK_FALSE(pqdc::detail::untangle(bad, m.points, 1.0, {}, c));
    CHECK(c.unresolved == 1);
    // Safe positions that pull the second triangle away: repaired, and the
    // number of rounds stays within the bound (partial steps, then a snap).
    std::vector<Vec3d> safe = m.points;
    for (int k = 3; k < 6; ++k) safe[k] += Vec3d(0, 0, 5);
    pqdc::detail::UntangleCounters d;
    CHECK(pqdc::detail::untangle(m, safe, 1.0, {}, d));
    CHECK(d.pairs_before == 1);
    CHECK(d.rounds >= 1);
    CHECK(d.rounds <= std::uint64_t(pqdc::detail::kPartialSteps + 1) * 6);
    CHECK(pqdc::find_self_intersections(m).none());
}

TEST_CASE("uniform output is free of self-intersections on hard volumes, any sigma_n and containment",
          "[untangle]") {
    const double inf = std::numeric_limits<double>::infinity();
    std::uint64_t found_uniform = 0;
    for (const Case& c : hard_cases())
        for (double sigma : {0.0, 0.1, inf})
            for (auto contain : {pqdc::Containment::clamp_to_cell, pqdc::Containment::unconstrained}) {
                pqdc::ExtractOptions o;
                o.sigma_n = sigma;
                o.containment = contain;
                o.faces = sigma == 0.1 ? pqdc::FaceType::quads : pqdc::FaceType::triangles;
                INFO(c.name << ", sigma_n " << sigma << ", unconstrained " << (contain != pqdc::Containment::clamp_to_cell));
                pqdc::ExtractStats s;
                const pqdc::Mesh m = pqdc::extract(*c.grid, o, &s);
                CHECK(!m.empty());
                CHECK(pqdc::find_self_intersections(m).none());
                CHECK(s.seconds("untangle") >= 0.0);
                found_uniform += s.untangle_found;
            }
    // The inputs had intersections to repair: the test is not vacuous.
    CHECK(found_uniform > 0);
}

TEST_CASE("adaptive output is free of self-intersections on hard volumes, any sigma_n and max error",
          "[untangle][adaptive]") {
    const double inf = std::numeric_limits<double>::infinity();
    std::uint64_t found = 0, pinned = 0, moved = 0, fallbacks = 0;
    for (const Case& c : hard_cases())
        for (double sigma : {0.0, 0.1, inf})
            for (double max_error : {0.1, inf}) {
                pqdc::AdaptiveOptions o;
                o.base.sigma_n = sigma;
                o.max_error_voxels = max_error;
                o.base.faces = sigma == 0.1 ? pqdc::FaceType::quads : pqdc::FaceType::triangles;
                INFO(c.name << ", sigma_n " << sigma << ", max error " << max_error);
                pqdc::AdaptiveStats s;
                const pqdc::Mesh m = pqdc::extract_adaptive(*c.grid, o, &s);
                CHECK(!m.empty());
                CHECK(pqdc::find_self_intersections(m).none());
                CHECK(s.seconds("untangle") >= 0.0);
                found += s.untangle_found;
                pinned += s.untangle_pinned_cells;
                moved += s.untangle_moved;
                fallbacks += s.untangle_fallback;
            }
    // Not vacuous: the inputs had intersections, and both the refinement
    // and the moves took part; none needed the uniform mesh.
    CHECK(found > 0);
    CHECK(pinned > 0);
    CHECK(moved > 0);
    CHECK(fallbacks == 0);
}

namespace {

/// Two crossing triangles that still cross with every corner at the center
/// of its cell.
pqdc::Mesh crossing_pair() {
    pqdc::Mesh m;
    m.points = {Vec3d(0.2, 0.3, 0.2), Vec3d(4.6, 0.4, 0.3), Vec3d(0.3, 4.7, 0.6),
                Vec3d(1.4, 1.2, -1.6), Vec3d(1.6, 1.3, 2.4), Vec3d(2.2, 2.6, 2.7)};
    m.triangles = {openvdb::Vec3I(0, 1, 2), openvdb::Vec3I(3, 4, 5)};
    return m;
}

/// An octree frame around the origin with unit voxels, for untangle_adaptive.
struct UntangleFrame {
    pqdc::adaptive_detail::Octree frame;
    openvdb::math::Transform::Ptr transform = openvdb::math::Transform::createLinearTransform(1.0);
    pqdc::detail::LatticeTransform xf = pqdc::detail::check_transform(*transform, "test");
    pqdc::ExtractOptions options;
    pqdc::detail::Progress progress{options};
    UntangleFrame() {
        frame.top = 6;
        frame.offset = Coord(-64);
        frame.levels.resize(std::size_t(frame.top) + 1);
    }
};

}  // namespace

TEST_CASE("adaptive untangle: refinement stops when it pins nothing new, then moves, then the uniform mesh",
          "[untangle][adaptive]") {
    namespace ad = pqdc::adaptive_detail;
    // Two crossing triangles that still cross with every corner at the
    // center of its cell, and a "rebuild" that always returns them.
    const pqdc::Mesh crossing = crossing_pair();
    REQUIRE(pqdc::find_self_intersections(crossing).pair_count == 1);
    const UntangleFrame f;
    const ad::Octree& frame = f.frame;
    int rebuilds = 0;
    std::size_t pinned_at_rebuild = 0;
    const ad::Rebuild rebuild = [&](const ad::PinnedCells& pinned, const ad::ShapeLimits&,
                                    const pqdc::detail::ProgressSpan&, pqdc::AdaptiveStats&) {
        ++rebuilds;
        pinned_at_rebuild = pinned.size();
        // Every corner's own cell is pinned.
        for (const Vec3d& p : crossing.points) {
            const Coord cell(int(std::floor(p.x())), int(std::floor(p.y())), int(std::floor(p.z())));
            CHECK(pinned.pinned(frame, cell));
        }
        return crossing;
    };
    pqdc::Mesh uniform;
    uniform.points = {Vec3d(0, 0, 0), Vec3d(1, 0, 0), Vec3d(0, 1, 0)};
    uniform.triangles = {openvdb::Vec3I(0, 1, 2)};
    int fallbacks = 0;
    const ad::UniformFallback fallback = [&](pqdc::ExtractStats& u, double) {
        ++fallbacks;
        u.vertices = 3;
        u.triangles = 1;
        return uniform;
    };
    pqdc::AdaptiveStats stats;
    const pqdc::Mesh out =
        ad::untangle_adaptive(crossing, rebuild, f.xf, frame, f.options, ad::PinnedCells{}, fallback, f.progress, stats);
    CHECK(rebuilds == 1);  // the second round pinned nothing new
    CHECK(pinned_at_rebuild == stats.untangle_pinned_cells);
    CHECK(stats.untangle_found == 1);
    CHECK(stats.untangle_moved == 6);
    CHECK(stats.untangle_snapped == 6);
    CHECK(stats.untangle_unresolved == 1);
    CHECK(fallbacks == 1);
    CHECK(stats.untangle_fallback);
    CHECK(out.points == uniform.points);
    CHECK(stats.triangles == 1);
    REQUIRE(stats.warnings.size() == 1);
    CHECK(stats.warnings[0].find("uniform mesh") != std::string::npos);

}

TEST_CASE("adaptive untangle: a mesh with angle flips it cannot repair is built again without them",
          "[untangle][adaptive]") {
    namespace ad = pqdc::adaptive_detail;
    // "Rebuilds" with flips always return two crossing triangles; without
    // flips, two separate ones. The retry must give the latter, not the
    // uniform fallback.
    const pqdc::Mesh crossing = crossing_pair();
    pqdc::Mesh apart = crossing;
    for (int k = 3; k < 6; ++k) apart.points[std::size_t(k)] += Vec3d(0, 0, 10);
    REQUIRE(pqdc::find_self_intersections(apart).none());
    const UntangleFrame f;
    const ad::Octree& frame = f.frame;
    int with_flips = 0, without_flips = 0;
    const ad::Rebuild rebuild = [&](const ad::PinnedCells&, const ad::ShapeLimits& shape,
                                    const pqdc::detail::ProgressSpan&, pqdc::AdaptiveStats& round) {
        if (shape.any()) {
            ++with_flips;
            round.angle_flips = 3;
            return crossing;
        }
        ++without_flips;
        return apart;
    };
    int fallbacks = 0;
    const ad::UniformFallback fallback = [&](pqdc::ExtractStats&, double) {
        ++fallbacks;
        return pqdc::Mesh{};
    };
    pqdc::AdaptiveStats stats;
    stats.angle_flips = 3;  // the first build flipped
    const pqdc::Mesh out =
        ad::untangle_adaptive(crossing, rebuild, f.xf, frame, f.options, ad::PinnedCells{}, fallback, f.progress, stats);
    CHECK(with_flips == 1);
    CHECK(without_flips == 1);
    CHECK(fallbacks == 0);
    CHECK(stats.untangle_flips_dropped);
    CHECK_FALSE(stats.untangle_fallback);
    CHECK(stats.angle_flips == 0);
    CHECK(out.points == apart.points);
    CHECK(pqdc::find_self_intersections(out).none());
}

TEST_CASE("untangle repairs a mesh that intersects before repair, the same on one thread", "[untangle]") {
    auto sphere = dense_grid(20, [](const Vec3d& p) { return (p - Vec3d(10.2, 9.7, 10.1)).length() - 7.3; });
    pqdc::add_gaussian_noise(*sphere, 0.3, 9);
    pqdc::ExtractOptions o;
    o.containment = pqdc::Containment::unconstrained;
    o.sigma_n = 0.0;
    pqdc::ExtractStats s;
    const pqdc::Mesh m = pqdc::extract(*sphere, o, &s);
    CHECK(s.untangle_found > 0);
    CHECK(s.untangle_moved > 0);
    CHECK(s.untangle_rounds >= 1);
    CHECK(pqdc::find_self_intersections(m).none());
    const tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    const pqdc::Mesh m1 = pqdc::extract(*sphere, o);
    CHECK(m1.points == m.points);
    CHECK(m1.triangles == m.triangles);
}

namespace {

/// The mesh as a single-precision file stores it.
pqdc::Mesh rounded_to_float(pqdc::Mesh m) {
    for (auto& p : m.points) p = Vec3d(openvdb::Vec3f(p));
    return m;
}

}  // namespace

TEST_CASE("untangle: with stored_precision float32 the rounded mesh has no self-intersections", "[untangle]") {
    // The untruncated classical quadric on a noisy fractal surface: nearly
    // touching folds, some of which cross once the points are rounded.
    pqdc::Figure3Params params;
    params.noise_amplitude = 0.12;
    params.noise_frequency = 2.0;
    const auto field = pqdc::make_figure3(params);
    pqdc::ProceduralSampling sampling;
    sampling.resolution = 96;
    pqdc::ExtractOptions options;
    options.sigma_n = 0.0;
    options.pseudo_inverse_cutoff = 1e-6;
    options.normals = pqdc::GridNormals::central;
    options.denoise = pqdc::Denoise::off;
    std::size_t rounding_pairs_in_double = 0;
    for (std::uint64_t seed = 1; seed <= 6; ++seed) {
        const openvdb::FloatGrid::Ptr grid = pqdc::sample_field(*field, sampling);
        pqdc::add_gaussian_noise(*grid, 0.25 * grid->voxelSize()[0], seed);
        options.stored_precision = pqdc::VertexPrecision::float64;
        const pqdc::Mesh in_double = pqdc::extract(*grid, options);
        REQUIRE(pqdc::find_self_intersections(in_double).none());
        rounding_pairs_in_double += pqdc::find_self_intersections(rounded_to_float(in_double)).pair_count;
        options.stored_precision = pqdc::VertexPrecision::float32;
        const pqdc::Mesh for_float = pqdc::extract(*grid, options);
        INFO("seed " << seed);
        CHECK(pqdc::find_self_intersections(rounded_to_float(for_float)).none());  // what is stored
    }
    // The case is only a test if rounding the double-checked mesh does break it somewhere.
    CHECK(rounding_pairs_in_double > 0);
}

TEST_CASE("untangle: its check reports progress and is a cancellation point", "[untangle]") {
    const auto sphere = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(60.0f, openvdb::Vec3f(0.0f), 1.0f);
    std::vector<double> seen;
    pqdc::ExtractOptions options;
    options.progress = [&](double f) {
        seen.push_back(f);
        return true;
    };
    const pqdc::Mesh mesh = pqdc::extract(*sphere, options);
    REQUIRE_FALSE(mesh.empty());
    CHECK(std::is_sorted(seen.begin(), seen.end()));
    // The second half of the range is the untangle stage's exact check.
    CHECK(std::count_if(seen.begin(), seen.end(), [](double f) { return f > 0.5 && f < 1.0; }) >= 5);
    options.progress = [](double f) { return f <= 0.7; };
    CHECK_THROWS_AS(pqdc::extract(*sphere, options), pqdc::cancelled_error);
}

namespace {

/// A uniform-extractor-like mesh of a sign field on an n^3 lattice: a vertex
/// per (cell, patch) as edge_groups numbers them, a quad per crossing edge
/// wound as the face stage winds it, split along a random diagonal (or kept
/// as quads), and vertices at random places in their cells. `spread` is the
/// largest max-norm offset from the cell's center (0.5: anywhere in the
/// cell; more: beyond it); `clamped` is the share of vertices put on a face
/// of their cell (the extractor's clamped vertices).
struct LatticeMesh {
    pqdc::Mesh mesh;
    std::vector<Vec3d> safe;
    std::vector<std::uint8_t> patches;
};

LatticeMesh lattice_mesh(int n, const std::function<bool(const Coord&)>& inside, double spread, double clamped,
                         bool quads, const openvdb::math::Transform& xf, pqdc_test::Random& rng, double cornered = 0.0) {
    using namespace pqdc::detail;
    LatticeMesh out;
    std::map<Coord, std::pair<unsigned, std::uint8_t>> cells;  // first vertex, configuration
    auto config_of = [&](const Coord& c) {
        std::uint8_t config = 0;
        for (int i = 0; i < 8; ++i)
            if (inside(c.offsetBy(i & 1, (i >> 1) & 1, (i >> 2) & 1))) config |= std::uint8_t(1 << i);
        return config;
    };
    for (int x = 0; x < n; ++x)
        for (int y = 0; y < n; ++y)
            for (int z = 0; z < n; ++z) {
                const Coord c(x, y, z);
                const std::uint8_t config = config_of(c);
                const EdgeGroups& groups = edge_groups(config);
                if (groups.count == 0) continue;
                cells[c] = {unsigned(out.mesh.points.size()), config};
                for (int g = 0; g < groups.count; ++g) {
                    Vec3d p;
                    for (int k = 0; k < 3; ++k) p[k] = c[k] + 0.5 + rng.uniform(-spread, spread);
                    if (rng.unit() < clamped) {
                        const int a = rng.integer(0, 2);
                        p[a] = c[a] + rng.integer(0, 1);
                    }
                    if (rng.unit() < cornered)  // on a lattice corner, which other cells' vertices may share
                        for (int k = 0; k < 3; ++k) p[k] = c[k] + rng.integer(0, 1);
                    out.mesh.points.push_back(xf.indexToWorld(p));
                    out.safe.push_back(xf.indexToWorld(safe_patch_position(c, config, 0, g)));
                    out.patches.push_back(std::uint8_t(g | (groups.count << 4)));
                }
            }
    for (const auto& [c, first_config] : cells)
        for (int axis = 0; axis < 3; ++axis) {
            const std::uint8_t config = first_config.second;
            const bool inside0 = config & 1;
            if (inside0 == bool((config >> (1 << axis)) & 1)) continue;
            const int u = (axis + 1) % 3, v = (axis + 2) % 3;
            unsigned q[4];
            bool complete = true;
            const int du[4] = {1, 0, 0, 1}, dv[4] = {1, 1, 0, 0};  // cells -u-v, -v, self, -u
            for (int k = 0; k < 4 && complete; ++k) {
                Coord cell = c;
                cell[u] -= du[k];
                cell[v] -= dv[k];
                const auto it = cells.find(cell);
                if (it == cells.end()) {
                    complete = false;
                    break;
                }
                const int edge = 4 * axis + du[k] + 2 * dv[k];
                q[k] = it->second.first + unsigned(edge_groups(it->second.second).group[edge]);
            }
            if (!complete) continue;
            if (!inside0) std::swap(q[1], q[3]);
            if (quads) {
                out.mesh.quads.emplace_back(q[0], q[1], q[2], q[3]);
            } else if (rng.unit() < 0.5) {
                out.mesh.triangles.emplace_back(q[0], q[1], q[2]);
                out.mesh.triangles.emplace_back(q[0], q[2], q[3]);
            } else {
                out.mesh.triangles.emplace_back(q[0], q[1], q[3]);
                out.mesh.triangles.emplace_back(q[1], q[2], q[3]);
            }
        }
    return out;
}

/// A round of moves of random vertices towards their safe positions after
/// QuadStarCheck::whole(): near() must report every intersecting pair and
/// degenerate triangle at a moved vertex, and no pair that does not
/// intersect and no triangle that is not degenerate. Returns how many such pairs there were (0 when near() did not
/// apply and need not).
std::size_t check_moves(const LatticeMesh& lm, const pqdc::detail::LatticeVertices& lattice, bool must_apply,
                        pqdc_test::Random& rng) {
    pqdc::detail::QuadStarCheck check(lm.mesh, lattice);
    check.whole(lm.mesh.points, {});
    pqdc::Mesh moved_mesh = lm.mesh;
    std::vector<std::uint32_t> moved;
    for (std::uint32_t v = 0; v < moved_mesh.points.size(); ++v)
        if (rng.unit() < 0.2) {
            moved.push_back(v);
            moved_mesh.points[v] = lm.safe[v] + (moved_mesh.points[v] - lm.safe[v]) * rng.unit();
        }
    pqdc::SelfIntersections near;
    const bool applied = check.near(moved_mesh.points, moved, near);
    if (must_apply) REQUIRE(applied);
    if (!applied) return 0;
    const pqdc::SelfIntersections after = pqdc::find_self_intersections(moved_mesh);
    std::vector<char> at_moved(moved_mesh.points.size(), 0);
    for (std::uint32_t v : moved) at_moved[v] = 1;
    auto touches = [&](std::size_t t) {
        for (unsigned c : pqdc::detail::split_triangle(moved_mesh, t))
            if (at_moved[c]) return true;
        return false;
    };
    std::set<std::pair<std::size_t, std::size_t>> expected, all(after.pairs.begin(), after.pairs.end());
    for (const auto& pr : after.pairs)
        if (touches(pr.first) || touches(pr.second)) expected.insert(pr);
    std::size_t missing = 0, wrong = 0;
    for (const auto& pr : expected) missing += !std::binary_search(near.pairs.begin(), near.pairs.end(), pr);
    for (const auto& pr : near.pairs) wrong += !all.count(pr);
    CHECK(missing == 0);
    CHECK(wrong == 0);
    // Degenerate triangles: every one at a moved vertex, and only degenerate
    // ones (near() classifies every triangle of the quads around the moved
    // vertices, so the other triangle of such a quad may be reported too).
    std::size_t degenerate_missing = 0, degenerate_wrong = 0;
    for (std::size_t t : after.degenerate_triangles)
        degenerate_missing += touches(t) && !std::binary_search(near.degenerate_triangles.begin(),
                                                                near.degenerate_triangles.end(), t);
    for (std::size_t t : near.degenerate_triangles)
        degenerate_wrong += !std::binary_search(after.degenerate_triangles.begin(), after.degenerate_triangles.end(), t);
    CHECK(std::is_sorted(near.degenerate_triangles.begin(), near.degenerate_triangles.end()));
    CHECK(degenerate_missing == 0);
    CHECK(degenerate_wrong == 0);
    return expected.size();
}

}  // namespace

TEST_CASE("untangle: the quad-star check finds exactly the pairs of the general finder, whole and after moves", "[untangle]") {
    pqdc_test::Random rng(29);
    const double n = 14;
    const std::vector<std::pair<std::string, std::function<bool(const Coord&)>>> fields{
        {"random signs", [](const Coord& p) {  // a fixed coin per lattice point
             std::uint64_t h = std::uint64_t(p[0] * 73856093) ^ std::uint64_t(p[1] * 19349663) ^
                               std::uint64_t(p[2] * 83492791);
             h *= 0x9E3779B97F4A7C15ull;
             return ((h >> 29) & 1) != 0;
         }},
        {"sphere", [&](const Coord& p) { return (p.asVec3d() - Vec3d(7.3, 6.8, 7.1)).length() < 5.2; }},
        {"thin sheet", [&](const Coord& p) { return std::abs((p.asVec3d() - Vec3d(7.1)).dot(Vec3d(1, 0.37, 0.21).unit())) < 0.6; }},
    };
    openvdb::math::Mat4d sheared = openvdb::math::Mat4d::identity();
    sheared.preScale(Vec3d(0.5, 1.0, 2.0));
    sheared.preRotate(openvdb::math::Y_AXIS, 0.4);
    sheared.setTranslation(Vec3d(-3.0, 100.25, 7.0));
    const auto unit = openvdb::math::Transform::createLinearTransform(1.0);
    const auto affine = openvdb::math::Transform::createLinearTransform(sheared);
    struct Placement {
        const char* name;
        double spread, clamped, cornered;
    };
    // On lattice corners, vertices of neighbouring cells coincide: degenerate triangles.
    const Placement placements[] = {{"near centers", 0.2, 0.0, 0.0},
                                    {"anywhere in the cell", 0.5, 0.0, 0.0},
                                    {"some clamped to faces", 0.5, 0.3, 0.0},
                                    {"some on lattice corners", 0.5, 0.0, 0.4},
                                    {"beyond the cell", 0.6, 0.0, 0.0}};
    std::uint64_t certified = 0, tested = 0, loose = 0, pairs = 0, moved_pairs = 0, degenerate = 0;
    for (const auto& [name, field] : fields)
        for (const Placement& placement : placements)
            for (int variant = 0; variant < 4; ++variant) {
                const bool quads = variant & 1;
                const openvdb::math::Transform& xf = (variant & 2) ? *affine : *unit;
                const LatticeMesh lm =
                    lattice_mesh(int(n), field, placement.spread, placement.clamped, quads, xf, rng, placement.cornered);
                pqdc::detail::LatticeTransform lattice_xf;
                lattice_xf.transform = &xf;
                const pqdc::detail::LatticeVertices lattice{&lm.safe, &lm.patches, &lattice_xf};
                pqdc::detail::QuadStarCounts counts;
                const pqdc::SelfIntersections fast =
                    pqdc::detail::find_self_intersections_by_quad_stars(lm.mesh, lm.mesh.points, lattice, {}, &counts);
                const pqdc::SelfIntersections full = pqdc::find_self_intersections(lm.mesh);
                INFO(name << ", " << placement.name << (quads ? ", quads" : ", triangles")
                          << ((variant & 2) ? ", affine" : ", unit voxels"));
                CHECK_FALSE(counts.general);
                CHECK(fast.pair_count == full.pair_count);
                CHECK(fast.pairs == full.pairs);
                CHECK(fast.degenerate_triangles == full.degenerate_triangles);
                moved_pairs += check_moves(lm, lattice, placement.spread <= 0.5, rng);
                certified += counts.certified_cells;
                tested += counts.tested_cells;
                loose += counts.loose_triangles;
                pairs += full.pair_count;
                degenerate += full.degenerate_triangles.size();
            }
    // Every path ran: stars proven, stars tested pair by pair, loose triangles, and pairs to find.
    CHECK(certified > 1000);
    CHECK(tested > 1000);
    CHECK(loose > 100);
    CHECK(pairs > 100);
    CHECK(moved_pairs > 100);
    CHECK(degenerate > 10);
}

TEST_CASE("adaptive untangle: corners step 2 leaves crossed outside the pinned cells are pinned in turn",
          "[untangle][adaptive]") {
    // The noisy CSG part of Figure 3 at 96 cells: step 2 (moving the pinned
    // cells' vertices) left 2 pairs crossed whose other corners lay outside
    // the pinned cells, and the run gave the uniform mesh instead (issue 11's
    // known defect). Pinning those corners and rebuilding resolves them.
    const auto field = pqdc::make_procedural("figure3");
    pqdc::ProceduralSampling sampling;
    sampling.resolution = 96;
    pqdc::AdaptiveStats stats;
    const pqdc::Mesh m = pqdc::extract_adaptive(*field, sampling, pqdc::AdaptiveOptions{}, &stats);
    CHECK(stats.untangle_found > 0);  // not vacuous: there was something to repair
    CHECK_FALSE(stats.untangle_fallback);
    CHECK(stats.untangle_unresolved == 0);
    CHECK(pqdc::find_self_intersections(m).none());
    pqdc::ExtractStats uniform;
    pqdc::extract(*field, sampling, pqdc::ExtractOptions{}, &uniform);
    CHECK(m.points.size() < uniform.vertices * 3 / 4);  // the adaptive mesh, not the uniform one
}
