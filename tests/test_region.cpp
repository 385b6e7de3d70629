// Meshing a region (issue 12, item 4): a world-space box and a surface mask
// restrict the output to the cells whose centres lie inside, the mesh is open
// exactly there, and inside it equals the whole grid's mesh.
#include "pqdc/adaptive.hpp"
#include "pqdc/bricks.hpp"
#include "pqdc/exceptions.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/measure.hpp"
#include "pqdc/procedural.hpp"

#include "mesh_checks.hpp"

#include <catch2/catch.hpp>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>

#include <array>
#include <cmath>
#include <set>
#include <string>

using openvdb::Vec3d;

namespace {

struct Init {
    Init() { openvdb::initialize(); }
} init_openvdb;

using Key = std::array<double, 3>;
Key key(const Vec3d& v) { return {v.x(), v.y(), v.z()}; }

std::set<Key> point_set(const pqdc::Mesh& m) {
    std::set<Key> s;
    for (const Vec3d& v : m.points) s.insert(key(v));
    return s;
}

/// Each triangle as its sorted corner positions.
std::set<std::array<Key, 3>> triangle_set(const pqdc::Mesh& m) {
    std::set<std::array<Key, 3>> s;
    for (const auto& t : m.triangles) {
        std::array<Key, 3> k{key(m.points[t[0]]), key(m.points[t[1]]), key(m.points[t[2]])};
        // Rotate so the smallest corner comes first: keeps the winding.
        while (!(k[0] < k[1] && k[0] < k[2])) std::rotate(k.begin(), k.begin() + 1, k.end());
        s.insert(k);
    }
    return s;
}

openvdb::FloatGrid::Ptr sphere(double voxel = 0.5) {
    auto g = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(10.f, openvdb::Vec3f(0.2f, -0.1f, 0.3f),
                                                                      float(voxel), 3.f);
    g->setName("sphere");
    return g;
}

/// The region mesh is a piece of the full one: its triangles are full-mesh
/// triangles with the same winding; its boundary is where the region cuts.
void check_piece(const pqdc::Mesh& piece, const pqdc::Mesh& full) {
    const auto tris = triangle_set(full);
    std::size_t foreign = 0;
    for (const auto& t : triangle_set(piece)) foreign += !tris.count(t);
    CHECK(foreign == 0);
    const pqdc::TopologyReport t = pqdc::measure_topology(piece);
    CHECK(t.boundary_edge_count > 0);
    CHECK(t.edge_manifold());
    CHECK(t.consistently_oriented());
    CHECK(t.unreferenced_vertex_count == 0);
}

}  // namespace

TEST_CASE("a world box keeps exactly the full mesh's cells whose centres lie inside", "[region]") {
    const auto g = sphere();
    const pqdc::Mesh full = pqdc::extract(*g, pqdc::ExtractOptions{});
    pqdc::ExtractOptions o;
    const double cut = 3.1;  // world x; voxel 0.5
    o.region.bbox = openvdb::BBoxd(Vec3d(-100.0), Vec3d(cut, 100.0, 100.0));
    pqdc::ExtractStats s;
    const pqdc::Mesh piece = pqdc::extract(*g, o, &s);
    check_piece(piece, full);
    CHECK(s.boundary_crossings > 0);
    // Vertices lie in cells whose centre is inside: at most half a cell past the cut.
    double max_x = -1e9;
    for (const Vec3d& v : piece.points) max_x = std::max(max_x, v.x());
    CHECK(max_x <= cut + 0.25 + 1e-9);
    // Every full-mesh triangle whose corners lie a cell inside the cut is kept.
    const auto kept = triangle_set(piece);
    std::size_t inside = 0, missing = 0;
    for (const auto& t : triangle_set(full))
        if (t[0][0] < cut - 0.75 && t[1][0] < cut - 0.75 && t[2][0] < cut - 0.75) {
            ++inside;
            missing += !kept.count(t);
        }
    CHECK(inside > 1000);
    CHECK(missing == 0);
    // Adaptive mode: restricted to the box too, open there.
    pqdc::AdaptiveOptions ao;
    ao.base = o;
    const pqdc::Mesh a = pqdc::extract_adaptive(*g, ao);
    REQUIRE(!a.empty());
    double amax = -1e9;
    for (const Vec3d& v : a.points) amax = std::max(amax, v.x());
    INFO("adaptive max x " << amax);
    CHECK(amax <= cut);
    const pqdc::TopologyReport at = pqdc::measure_topology(a);
    CHECK(at.boundary_edge_count > 0);
    CHECK(at.edge_manifold());
    CHECK(at.consistently_oriented());
}

TEST_CASE("a mask with the grid's transform equals the box of the same cells, and inverted the rest", "[region]") {
    const auto g = sphere();
    const pqdc::Mesh full = pqdc::extract(*g, pqdc::ExtractOptions{});
    // Mask voxels x <= 6 (index) with the grid's transform: cells with minimum
    // corner x <= 6, whose centres lie at world x <= 6.5 * 0.5.
    auto mask = openvdb::BoolGrid::create(false);
    mask->setTransform(g->transform().copy());
    mask->setName("left");
    mask->fill(openvdb::CoordBBox(openvdb::Coord(-40), openvdb::Coord(6, 40, 40)), true, true);
    pqdc::ExtractOptions by_mask, by_box;
    by_mask.region.mask = mask;
    by_box.region.bbox = openvdb::BBoxd(Vec3d(-100.0), Vec3d(3.3, 100.0, 100.0));
    const pqdc::Mesh a = pqdc::extract(*g, by_mask), b = pqdc::extract(*g, by_box);
    CHECK(a.points == b.points);
    CHECK(a.triangles == b.triangles);
    check_piece(a, full);
    by_mask.region.invert_mask = true;
    const pqdc::Mesh rest = pqdc::extract(*g, by_mask);
    check_piece(rest, full);
    // The two pieces share no vertex and together hold every full-mesh triangle
    // but the ring of quads whose four cells straddle the cut.
    const auto pa = point_set(a), pr = point_set(rest);
    std::size_t shared = 0;
    for (const Key& k : pa) shared += pr.count(k);
    CHECK(shared == 0);
    const std::size_t split = a.triangles.size() + rest.triangles.size();
    CHECK(split < full.triangles.size());
    CHECK(split > full.triangles.size() * 95 / 100);
    // Both modes accept it; adaptive output stays on the mask's side.
    pqdc::AdaptiveOptions ao;
    ao.base.region.mask = mask;
    const pqdc::Mesh am = pqdc::extract_adaptive(*g, ao);
    REQUIRE(!am.empty());
    for (const Vec3d& v : am.points) REQUIRE(v.x() <= 3.25 + 1e-6);
}

TEST_CASE("a level-set mask with its own transform limits the surface to its inside", "[region]") {
    const auto g = sphere();
    // A ball of radius 4 around a point on the sphere, coarser voxels, shifted.
    const Vec3d c(10.2, -0.1, 0.3);
    auto ball = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(4.f, openvdb::Vec3f(c), 0.7f, 3.f);
    pqdc::ExtractOptions o;
    o.region.mask = ball;
    const pqdc::Mesh m = pqdc::extract(*g, o);
    const pqdc::Mesh full = pqdc::extract(*g, pqdc::ExtractOptions{});
    check_piece(m, full);
    double far = 0;
    for (const Vec3d& v : m.points) far = std::max(far, (v - c).length());
    CHECK(far < 4.0 + 0.7 + 0.5);  // mask voxel and grid cell of slack
    CHECK(m.triangles.size() > 300);
    CHECK(m.triangles.size() < full.triangles.size() / 5);
}

TEST_CASE("a box cuts a surface made of active tiles like one made of voxels", "[region]") {
    // A fog block of active 8^3 and 64^3 tiles (no voxels): the candidate
    // clip must keep the tiles' shells near the box.
    auto fog = openvdb::FloatGrid::create(0.f);
    fog->setGridClass(openvdb::GRID_FOG_VOLUME);
    fog->fill(openvdb::CoordBBox(openvdb::Coord(-72), openvdb::Coord(71)), 1.f, true);
    REQUIRE(fog->tree().leafCount() == 0);
    pqdc::ExtractOptions o;
    o.isovalue = 0.5;
    const pqdc::Mesh full = pqdc::extract(*fog, o);
    REQUIRE(!full.empty());
    o.region.bbox = openvdb::BBoxd(Vec3d(-100.0), Vec3d(10.3, 100.0, 100.0));
    const pqdc::Mesh piece = pqdc::extract(*fog, o);
    check_piece(piece, full);
    std::size_t expected = 0;
    for (const auto& t : triangle_set(full)) expected += t[0][0] < 9.5 && t[1][0] < 9.5 && t[2][0] < 9.5;
    const auto kept = triangle_set(piece);
    std::size_t found = 0;
    for (const auto& t : triangle_set(full))
        if (t[0][0] < 9.5 && t[1][0] < 9.5 && t[2][0] < 9.5) found += kept.count(t);
    CHECK(expected > 1000);
    CHECK(found == expected);
}

TEST_CASE("a region makes a volume too large for the memory limit fit", "[region]") {
    const auto g = sphere(0.25);
    pqdc::ExtractOptions o;
    o.memory_limit_bytes = std::size_t(2) << 20;
    try {
        pqdc::extract(*g, o);
        FAIL("the whole sphere fit in 2 MiB");
    } catch (const pqdc::resource_error& e) {
        CHECK(std::string(e.what()).find("smaller region") != std::string::npos);
    }
    o.region.bbox = openvdb::BBoxd(Vec3d(7.0, -3.0, -3.0), Vec3d(11.0, 3.0, 3.0));
    const pqdc::Mesh m = pqdc::extract(*g, o);
    CHECK(m.triangles.size() > 1000);
}

// A procedural field is sampled before anything else: only its nodes near the
// region, and refused while its lattice is classified when even that is too
// large (it used to sample the whole field first: 6 s and 860 MB for a 2048^3
// sphere refused at 100 MiB, and a small box cost as much as the whole).
TEST_CASE("a procedural field is sampled only around the region, and refused before sampling when too large",
          "[region][procedural]") {
    const auto field = pqdc::make_procedural("sphere");
    pqdc::ProceduralSampling sampling;
    sampling.resolution = 512;  // about 10 k leaves of 2 KiB on the surface: 20 MiB
    pqdc::ExtractOptions o;
    o.memory_limit_bytes = std::size_t(4) << 20;
    pqdc::AdaptiveOptions a;
    a.base = o;
    for (bool adaptive : {false, true}) {
        INFO("adaptive " << adaptive);
        try {
            adaptive ? pqdc::extract_adaptive(*field, sampling, a) : pqdc::extract(*field, sampling, o);
            FAIL("the whole field fit in 4 MiB");
        } catch (const pqdc::resource_error& e) {
            CHECK_THAT(e.what(), Catch::Contains("sampled at resolution 512") &&
                                     Catch::Contains("counted before sampling") && Catch::Contains("smaller region"));
        }
    }
    // A box around one 128^3 node of the surface: its leaves fit, and it is
    // the same piece as with the whole field sampled.
    const openvdb::BBoxd box(Vec3d(-0.1, -0.1, 0.9), Vec3d(0.1, 0.1, 1.05));
    pqdc::ExtractOptions roomy = o, boxed = o;
    roomy.memory_limit_bytes = std::size_t(1) << 30;
    roomy.region.bbox = boxed.region.bbox = box;
    const pqdc::Mesh piece = pqdc::extract(*field, sampling, boxed);
    CHECK(piece.triangles.size() > 1000);
    CHECK(piece.points == pqdc::extract(*field, sampling, roomy).points);
    pqdc::AdaptiveOptions boxed_adaptive, roomy_adaptive;
    boxed_adaptive.base = boxed;
    roomy_adaptive.base = roomy;
    const pqdc::Mesh adaptive_piece = pqdc::extract_adaptive(*field, sampling, boxed_adaptive);
    CHECK(adaptive_piece.triangles.size() > 20);
    CHECK(adaptive_piece.points == pqdc::extract_adaptive(*field, sampling, roomy_adaptive).points);
}

TEST_CASE("region options are validated", "[region]") {
    const auto g = sphere();
    pqdc::ExtractOptions o;
    o.region.bbox = openvdb::BBoxd(Vec3d(1.0), Vec3d(0.0, 2.0, 2.0));
    CHECK_THROWS_AS(pqdc::extract(*g, o), pqdc::option_error);
    o.region.bbox.reset();
    o.region.invert_mask = true;
    CHECK_THROWS_AS(pqdc::extract(*g, o), pqdc::option_error);
    o.region.mask = openvdb::Vec3SGrid::create();
    CHECK_THROWS_AS(pqdc::extract(*g, o), pqdc::input_error);
    // A box that misses the surface gives an empty mesh, not an error.
    o.region = pqdc::MeshRegion{};
    o.region.bbox = openvdb::BBoxd(Vec3d(50.0), Vec3d(60.0));
    CHECK(pqdc::extract(*g, o).empty());
}

TEST_CASE("an adaptive mesh of a region equals the whole grid's away from the cut", "[region][adaptive]") {
    const auto g = sphere();
    const pqdc::Mesh full = pqdc::extract_adaptive(*g, pqdc::AdaptiveOptions{});
    pqdc::AdaptiveOptions ao;
    ao.base.region.bbox = openvdb::BBoxd(Vec3d(-100.0), Vec3d(3.1, 100.0, 100.0));
    const pqdc::Mesh piece = pqdc::extract_adaptive(*g, ao);
    const auto tris = triangle_set(full);
    std::size_t same = 0, far_same = 0, far = 0;
    for (const auto& t : triangle_set(piece)) {
        same += tris.count(t);
        const bool away = t[0][0] < 3.1 - 8 && t[1][0] < 3.1 - 8 && t[2][0] < 3.1 - 8;
        far += away;
        far_same += away && tris.count(t);
    }
    INFO("adaptive piece " << piece.triangles.size() << " triangles, " << same << " identical to the full mesh; "
                           << far << " more than 8 units (16 voxels) from the cut, " << far_same << " identical");
    // Merges beside the cut see missing siblings; beyond a root or so nothing changes.
    CHECK(far > 500);
    CHECK(far_same == far);
    // Closer in, the region's border vertices stay put where the whole
    // grid's relax (adaptive/relax.hpp, two sweeps): beyond 3 units (6
    // voxels) every triangle is the whole grid's.
    std::size_t beyond = 0, beyond_same = 0;
    for (const auto& t : triangle_set(piece)) {
        const bool away = t[0][0] < 3.1 - 3 && t[1][0] < 3.1 - 3 && t[2][0] < 3.1 - 3;
        beyond += away;
        beyond_same += away && tris.count(t);
    }
    // (The cells at the cut keep their finest size, as in uniform mode.)
    CHECK(double(beyond) > 0.6 * double(piece.triangles.size()));
    CHECK(beyond_same == beyond);
}

TEST_CASE("an adaptive mesh of a region counts its open crossings as the uniform one does", "[region][adaptive]") {
    // Adaptive mode reported 0 boundary crossings for a cut mesh (and the
    // CLI summary did not say it was open).
    const auto g = sphere();
    pqdc::AdaptiveOptions ao;
    ao.base.region.bbox = openvdb::BBoxd(Vec3d(-100.0), Vec3d(3.1, 100.0, 100.0));
    pqdc::ExtractStats uniform;
    pqdc::extract(*g, ao.base, &uniform);
    pqdc::AdaptiveStats adaptive;
    const pqdc::Mesh piece = pqdc::extract_adaptive(*g, ao, &adaptive);
    CHECK(uniform.boundary_crossings > 0);
    CHECK(adaptive.boundary_crossings == uniform.boundary_crossings);
    CHECK(adaptive.crossing_edges == uniform.crossing_edges);
    CHECK(pqdc::measure_topology(piece).boundary_edge_count > 0);
    pqdc::AdaptiveStats whole;
    pqdc::extract_adaptive(*g, pqdc::AdaptiveOptions{}, &whole);
    CHECK(whole.boundary_crossings == 0);
    // Brick by brick, the same count.
    pqdc::BrickOptions bricks;
    bricks.brick_size = 128;  // the sphere spans about 2 of them
    pqdc::AdaptiveStats by_bricks;
    pqdc::extract_adaptive_bricks(*g, ao, bricks, &by_bricks);
    CHECK(by_bricks.boundary_crossings == adaptive.boundary_crossings);
}

TEST_CASE("a region too small for a face says so, not that it holds no surface", "[region]") {
    // One cell's centre in the box: its crossings lack the other cells
    // around them, so no face; the warning said "no surface inside the region".
    const auto g = sphere();
    pqdc::ExtractOptions o;
    const Vec3d at(10.2, -0.1, 0.3);  // on the sphere
    o.region.bbox = openvdb::BBoxd(at - Vec3d(0.2), at + Vec3d(0.2));
    pqdc::ExtractStats s;
    const pqdc::Mesh m = pqdc::extract(*g, o, &s);
    CHECK(m.empty());
    CHECK(s.crossing_edges > 0);
    CHECK(s.boundary_crossings == s.crossing_edges);
    REQUIRE(!s.warnings.empty());
    CHECK(s.warnings.back().find("none has all four cells around it") != std::string::npos);
}

TEST_CASE("an adaptive mesh of a region stays open where the region cuts, also on samples at the isovalue",
          "[region][adaptive]") {
    // A box whose faces lie on lattice points (values exactly 0), as in
    // integer CT data, cut by a box region: adaptive mode merged the cells
    // at the cut, and gave a closed box with a wall 3 voxels inside the
    // region (8 vertices); a mask gave nothing at all. Off the lattice the
    // mesh ended up to 3 voxels short of the uniform one's edge.
    const double h = 0.05;
    for (const double half_x : {1.0, 1.01}) {
        openvdb::FloatGrid::Ptr g = openvdb::FloatGrid::create(float(3 * h));
        g->setTransform(openvdb::math::Transform::createLinearTransform(h));
        g->setGridClass(openvdb::GRID_LEVEL_SET);
        auto acc = g->getAccessor();
        const Vec3d half(half_x, 0.7 + (half_x - 1.0), 0.5 + (half_x - 1.0));
        for (int i = -32; i <= 32; ++i)
            for (int j = -32; j <= 32; ++j)
                for (int k = -32; k <= 32; ++k) {
                    const Vec3d p(i * h, j * h, k * h);
                    const Vec3d q(std::abs(p.x()) - half.x(), std::abs(p.y()) - half.y(), std::abs(p.z()) - half.z());
                    const Vec3d outside(std::max(q.x(), 0.0), std::max(q.y(), 0.0), std::max(q.z(), 0.0));
                    const double d = outside.length() + std::min(std::max({q.x(), q.y(), q.z()}), 0.0);
                    if (std::abs(d) < 3 * h) acc.setValue(openvdb::Coord(i, j, k), float(d));
                }
        pqdc::AdaptiveOptions ao;
        ao.base.region.bbox = openvdb::BBoxd(Vec3d(-2.0), Vec3d(0.3, 2.0, 2.0));
        const pqdc::Mesh uniform = pqdc::extract(*g, ao.base);
        const pqdc::Mesh piece = pqdc::extract_adaptive(*g, ao);
        INFO("half x " << half_x << ": uniform " << uniform.points.size() << " vertices, adaptive "
                       << piece.points.size());
        const pqdc::TopologyReport t = pqdc::measure_topology(piece), tu = pqdc::measure_topology(uniform);
        CHECK(tu.boundary_edge_count > 0);
        // The same finest cells line the cut (4 fewer edges, where it
        // crosses the box's edges, from how the polygons split there).
        CHECK(double(t.boundary_edge_count) > 0.9 * double(tu.boundary_edge_count));
        CHECK(t.boundary_edge_count <= tu.boundary_edge_count);
        CHECK(piece.points.size() > 100);
        // Every uniform vertex lies on the adaptive piece: no wall, no gap.
        CHECK(pqdc::measure_distance(uniform, piece).max < 0.25 * h);
        CHECK(pqdc::measure_distance(piece, uniform).max < 0.25 * h);
    }
}
