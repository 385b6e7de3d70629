// Uniform dual contouring: geometry, topology, determinism, sources.
#include "pqdc/adaptive.hpp"
#include "pqdc/exceptions.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/measure.hpp"
#include "pqdc/mesh_io.hpp"
#include "pqdc/procedural.hpp"
#include "pqdc/volume_io.hpp"

#include "mesh_checks.hpp"

#include <catch2/catch.hpp>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <openvdb/tools/LevelSetUtil.h>
#include <tbb/global_control.h>

#include <array>
#include <cmath>
#include <fstream>
#include <functional>
#include <iterator>
#include <map>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

using openvdb::Vec3d;
using pqdc_test::box_corners;
using pqdc_test::require_watertight;

namespace {

struct Init {
    Init() { openvdb::initialize(); }
} init_openvdb;

openvdb::FloatGrid::Ptr vdb_sphere(float radius_voxels, float voxel = 1.0f, Vec3d center = Vec3d(0.3, -0.2, 0.1)) {
    return openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(radius_voxels * voxel, center, voxel, 3.0f);
}

double nearest_vertex_distance(const pqdc::Mesh& m, const Vec3d& p) {
    double best = std::numeric_limits<double>::max();
    for (const auto& v : m.points) best = std::min(best, (v - p).length());
    return best;
}

}  // namespace

TEST_CASE("options are validated", "[extract]") {
    pqdc::ExtractOptions o;
    o.sigma_n = -0.1;
    CHECK_THROWS_AS(pqdc::validate(o), pqdc::option_error);
    o.sigma_n = std::nan("");
    CHECK_THROWS_AS(pqdc::validate(o), pqdc::option_error);
    o.sigma_n = std::numeric_limits<double>::infinity();
    CHECK_NOTHROW(pqdc::validate(o));
    o.isovalue = std::nan("");
    CHECK_THROWS_AS(pqdc::validate(o), pqdc::option_error);
    o.isovalue = 0;
    o.pseudo_inverse_cutoff = 1.0;
    CHECK_THROWS_AS(pqdc::validate(o), pqdc::option_error);
    // Enum fields hold named values: (FaceType)9 gave quads, (Interior)7 a guess.
    pqdc::ExtractOptions e;
    e.faces = static_cast<pqdc::FaceType>(9);
    CHECK_THROWS_WITH(pqdc::validate(e), Catch::Contains("faces holds 9"));
    e = {};
    e.interior = static_cast<pqdc::Interior>(-1);
    CHECK_THROWS_WITH(pqdc::validate(e), Catch::Contains("interior holds -1"));
    pqdc::AdaptiveOptions a;
    a.base.denoise = static_cast<pqdc::Denoise>(3);
    CHECK_THROWS_WITH(pqdc::validate(a), Catch::Contains("AdaptiveOptions::base.denoise holds 3"));
}

TEST_CASE("sphere vertices lie within 0.05 voxel of the true surface", "[extract]") {
    SECTION("procedural sphere, exact Hermite data") {
        const auto field = pqdc::make_sphere({Vec3d(0.1, -0.05, 0.02), 1.0});
        pqdc::ProceduralSampling s;
        s.resolution = 48;
        const double h = pqdc::procedural_transform(*field, s)->voxelSize()[0];
        for (double sigma : {0.0, 0.1, 0.25}) {
            pqdc::ExtractOptions o;
            o.sigma_n = sigma;
            const pqdc::Mesh m = pqdc::extract(*field, s, o);
            INFO("sigma_n " << sigma);
            require_watertight(m, "procedural sphere");
            CHECK(pqdc::measure_distance(m, *field).max < 0.05 * h);
        }
    }
    SECTION("VDB level set sphere, linear crossings and finite-difference normals") {
        const float r = 20.0f, voxel = 0.25f;
        const Vec3d c(0.3, -0.2, 0.1);
        const auto grid = vdb_sphere(r, voxel, c);
        const pqdc::Mesh m = pqdc::extract(*grid, pqdc::ExtractOptions{});
        require_watertight(m, "vdb sphere");
        double worst = 0;
        for (const auto& p : m.points) worst = std::max(worst, std::abs((p - c).length() - r * voxel));
        CHECK(worst < 0.05 * voxel);
    }
}

/// Whether the lattice can see a box corner at all: the cell containing it
/// must have a corner inside the box. A tip poking into a cell between
/// lattice points is invisible to every sign-based extractor.
bool corner_is_sampled(const pqdc::ScalarField& f, const openvdb::math::Transform& xf, const Vec3d& corner) {
    // A corner on a lattice plane belongs to the cells on both sides.
    const Vec3d i = xf.worldToIndex(corner);
    for (int side = 0; side < 8; ++side) {
        openvdb::Coord cell;
        for (int a = 0; a < 3; ++a) cell[a] = int(std::floor(i[a] + ((side >> a) & 1 ? 1e-9 : -1e-9)));
        for (int c = 0; c < 8; ++c)
            if (f.value(xf.indexToWorld(cell + openvdb::Coord(c & 1, (c >> 1) & 1, (c >> 2) & 1))) < 0) return true;
    }
    return false;
}

TEST_CASE("classical quadrics reproduce the rotated box's corners and edges", "[extract]") {
    pqdc::BoxParams p;
    const auto field = pqdc::make_rotated_box(p);
    const auto corners = box_corners(p);
    for (const auto& c : corners) REQUIRE(std::abs(field->value(c)) < 1e-12);  // test's rotation matches the field's

    pqdc::ProceduralSampling s;
    s.resolution = 40;
    const auto xf = pqdc::procedural_transform(*field, s);
    const double h = xf->voxelSize()[0];
    int sampled = 0;
    for (const auto& c : corners) sampled += corner_is_sampled(*field, *xf, c);
    REQUIRE(sampled >= 6);  // at this resolution and pose, two tips fall between lattice points

    SECTION("procedural box, sigma_n = 0: within 1e-3 voxel") {
        pqdc::ExtractOptions o;
        o.sigma_n = 0.0;
        const pqdc::Mesh m = pqdc::extract(*field, s, o);
        require_watertight(m, "procedural box");
        for (const auto& c : corners)
            if (corner_is_sampled(*field, *xf, c)) CHECK(nearest_vertex_distance(m, c) < 1e-3 * h);
        // Every box edge is traced by vertices on it, one per voxel of its
        // length, except where the wedge between the two faces is thinner than
        // the lattice (no crossing of one face in that cell): allow 3%.
        int samples = 0, traced = 0;
        for (int a = 0; a < 8; ++a)
            for (int b = a + 1; b < 8; ++b) {
                const int diff = a ^ b;
                if (diff != 1 && diff != 2 && diff != 4) continue;
                const Vec3d A = corners[a], B = corners[b], d = (B - A).unitSafe();
                const double len = (B - A).length();
                for (double t = 1.5 * h; t < len - 1.5 * h; t += h) {
                    const Vec3d q = A + d * t;
                    double best = std::numeric_limits<double>::max();
                    for (const auto& v : m.points) {
                        if ((v - q).length() > h) continue;
                        const Vec3d off = (v - A) - d * (v - A).dot(d);
                        best = std::min(best, off.length());
                    }
                    ++samples;
                    traced += best < 1e-3 * h;
                }
            }
        INFO(traced << " of " << samples << " edge samples traced");
        CHECK(samples > 200);
        CHECK(traced >= 0.97 * samples);
    }
    SECTION("box sampled into a VDB, sigma_n = 0: corners within half a voxel") {
        // A sampled SDF is rounded outside convex corners (distance to the
        // corner point, not to the face planes), which biases both the
        // linear crossings and the finite-difference normals near a corner.
        // Measured worst case here: 0.43 voxel with central normals; the
        // next section shows GridNormals::sharp reaching 0.1 on 5 of 6.
        const openvdb::FloatGrid::Ptr grid = pqdc::sample_field(*field, s);
        pqdc::ExtractOptions o;
        o.sigma_n = 0.0;
        const pqdc::Mesh m = pqdc::extract(*grid, o);
        require_watertight(m, "vdb box");
        for (const auto& c : corners)
            if (corner_is_sampled(*field, *xf, c)) CHECK(nearest_vertex_distance(m, c) < 0.5 * h);
    }
    SECTION("box sampled into a VDB, sigma_n = 0, sharp normals") {
        const openvdb::FloatGrid::Ptr grid = pqdc::sample_field(*field, s);
        pqdc::ExtractOptions o;
        o.sigma_n = 0.0;
        o.normals = pqdc::GridNormals::sharp;
        const pqdc::Mesh m = pqdc::extract(*grid, o);
        require_watertight(m, "vdb box, sharp normals");
        // Measured: five corners within 0.06 voxel, the sixth (its tip 0.06
        // voxel from a lattice plane, barely sampled) at 0.14; central
        // normals give 0.25-0.43 for all six.
        int sampled_corners = 0, within_tenth = 0;
        for (const auto& c : corners)
            if (corner_is_sampled(*field, *xf, c)) {
                const double d = nearest_vertex_distance(m, c);
                ++sampled_corners;
                within_tenth += d < 0.1 * h;
                CHECK(d < 0.15 * h);
            }
        CHECK(within_tenth >= sampled_corners - 1);
    }
}

TEST_CASE("the test corpus meshes closed, manifold and outward for every sigma_n and face type", "[extract]") {
    pqdc::ProceduralSampling s;
    s.resolution = 40;
    for (const std::string name : {"sphere", "box", "figure3"}) {
        const auto field = pqdc::make_procedural(name);
        for (double sigma : {0.0, 0.1, std::numeric_limits<double>::infinity()})
            for (pqdc::FaceType faces : {pqdc::FaceType::triangles, pqdc::FaceType::quads}) {
                pqdc::ExtractOptions o;
                o.sigma_n = sigma;
                o.faces = faces;
                pqdc::ExtractStats st;
                const pqdc::Mesh m = pqdc::extract(*field, s, o, &st);
                require_watertight(m, name + " sigma_n " + std::to_string(sigma) +
                                          (faces == pqdc::FaceType::quads ? " quads" : " triangles"));
                CHECK(st.vertices == m.points.size());
                CHECK(st.boundary_crossings == 0);
            }
    }
}

TEST_CASE("two sheets through one cell get separate vertices and stay manifold", "[extract]") {
    // A spherical shell thinner than a voxel: many cells are crossed by both
    // sheets, each needing its own vertex.
    auto grid = openvdb::FloatGrid::create(3.0f);
    grid->setGridClass(openvdb::GRID_LEVEL_SET);
    auto acc = grid->getAccessor();
    const double R = 11.3, half_thickness = 0.3;
    for (int x = -16; x <= 16; ++x)
        for (int y = -16; y <= 16; ++y)
            for (int z = -16; z <= 16; ++z) {
                const double r = std::sqrt(double(x * x + y * y + z * z));
                const double d = std::abs(r - R) - half_thickness;
                if (std::abs(d) < 3.0) acc.setValue(openvdb::Coord(x, y, z), float(d));
            }
    pqdc::ExtractStats st;
    for (pqdc::FaceType faces : {pqdc::FaceType::triangles, pqdc::FaceType::quads}) {
        pqdc::ExtractOptions o;
        o.faces = faces;
        const pqdc::Mesh m = pqdc::extract(*grid, o, &st);
        const pqdc::TopologyReport t = pqdc::measure_topology(m);
        CHECK(st.multi_vertex_cells > 0);
        CHECK(t.closed());
        CHECK(t.edge_manifold());
        CHECK(t.vertex_manifold());
        CHECK(t.consistently_oriented());
        CHECK(t.non_finite_point_count == 0);
    }
}

TEST_CASE("sigma_n = inf places each vertex at the mass point of its cell's crossings", "[extract]") {
    const auto grid = vdb_sphere(9.0f);
    pqdc::ExtractOptions o;
    o.sigma_n = std::numeric_limits<double>::infinity();
    o.containment = pqdc::Containment::unconstrained;
    o.normals = pqdc::GridNormals::central;  // linear crossings, as recomputed below
    const pqdc::Mesh m = pqdc::extract(*grid, o);
    REQUIRE(!m.points.empty());
    const auto acc = grid->getConstAccessor();
    for (const auto& p : m.points) {
        const Vec3d ip = grid->transform().worldToIndex(p);
        const openvdb::Coord cell(int(std::floor(ip.x())), int(std::floor(ip.y())), int(std::floor(ip.z())));
        Vec3d sum(0.0);
        int n = 0;
        for (int axis = 0; axis < 3; ++axis)
            for (int u = 0; u < 2; ++u)
                for (int v = 0; v < 2; ++v) {
                    openvdb::Coord a = cell;
                    a[(axis + 1) % 3] += u;
                    a[(axis + 2) % 3] += v;
                    openvdb::Coord b = a;
                    b[axis] += 1;
                    const double va = acc.getValue(a), vb = acc.getValue(b);
                    if ((va < 0) == (vb < 0)) continue;
                    Vec3d q = a.asVec3d();
                    q[axis] += va / (va - vb);
                    sum += q;
                    ++n;
                }
        REQUIRE(n > 0);
        CHECK((ip - sum / n).length() < 1e-6);
    }
}

TEST_CASE("output is identical for any number of threads", "[extract]") {
    const auto field = pqdc::make_procedural("figure3");
    pqdc::ProceduralSampling s;
    s.resolution = 48;
    pqdc::ExtractOptions o;
    pqdc::Mesh one, many;
    {
        tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
        one = pqdc::extract(*field, s, o);
    }
    {
        tbb::global_control c(tbb::global_control::max_allowed_parallelism, 4);
        many = pqdc::extract(*field, s, o);
    }
    REQUIRE(one.points.size() == many.points.size());
    CHECK(one.points == many.points);
    CHECK(one.triangles == many.triangles);
}

TEST_CASE("active tiles mesh exactly like the same voxels", "[extract]") {
    // A fog volume whose interior is one 128^3 tile plus a few 8^3 tiles.
    auto fog = openvdb::FloatGrid::create(0.0f);
    fog->setGridClass(openvdb::GRID_FOG_VOLUME);
    fog->tree().fill(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(127)), 1.0f, true);
    fog->tree().fill(openvdb::CoordBBox(openvdb::Coord(128, 0, 0), openvdb::Coord(135, 7, 7)), 1.0f, true);
    REQUIRE(fog->tree().activeTileCount() > 0);
    auto dense = fog->deepCopy();
    dense->tree().voxelizeActiveTiles();
    REQUIRE(dense->tree().activeTileCount() == 0);

    pqdc::ExtractOptions o;
    o.isovalue = 0.5;
    pqdc::ExtractStats st;
    const pqdc::Mesh a = pqdc::extract(*fog, o, &st);
    const pqdc::Mesh b = pqdc::extract(*dense, o);
    require_watertight(a, "tiled fog volume");
    CHECK(a.points == b.points);
    CHECK(a.triangles == b.triangles);
    // The surface lies between the last inside (1) and first outside (0) points.
    for (const auto& p : a.points) {
        CHECK(p.x() >= -1.0);
        CHECK(p.y() >= -1.0);
        CHECK(p.z() >= -1.0);
        CHECK(p.x() <= 136.0);
        CHECK(p.y() <= 128.0);
        CHECK(p.z() <= 128.0);
    }
    CHECK(st.multi_vertex_cells == 0);
}

TEST_CASE("fog volume meshed at an isovalue, inside denser", "[extract]") {
    const float r = 12.0f;
    auto grid = vdb_sphere(r, 1.0f, Vec3d(0.0));
    openvdb::tools::sdfToFogVolume(*grid);  // 1 deep inside, ramps to 0 over the inner band (3 voxels)
    REQUIRE(grid->getGridClass() == openvdb::GRID_FOG_VOLUME);
    pqdc::ExtractOptions o;
    o.isovalue = 0.5;  // half way down the ramp: radius r - 1.5
    pqdc::ExtractStats st;
    const pqdc::Mesh m = pqdc::extract(*grid, o, &st);
    INFO("noise " << st.noise_voxels << ", gradient " << st.gradient << ", denoise " << st.denoise_radius);
    require_watertight(m, "fog sphere");
    double worst = 0;
    for (const auto& p : m.points) worst = std::max(worst, std::abs(p.length() - (r - 1.5)));
    CHECK(worst < 0.05);
}

TEST_CASE("voxel size and origin change nothing in cell units, even far from zero", "[extract]") {
    const auto unit = vdb_sphere(10.0f, 1.0f, Vec3d(0.0));
    pqdc::ExtractOptions o;
    o.faces = pqdc::FaceType::quads;  // the diagonal choice may flip on exact ties after rounding
    const pqdc::Mesh ref = pqdc::extract(*unit, o);
    for (const auto& [voxel, origin] : {std::pair<double, Vec3d>{1e-4, Vec3d(0.0)}, {1e6, Vec3d(0.0)},
                                        {0.0137, Vec3d(1e5, -3e4, 2.5e3)}, {1e-3, Vec3d(1e6, 1e6, -1e6)}}) {
        auto moved = unit->deepCopy();
        auto xf = openvdb::math::Transform::createLinearTransform(voxel);
        xf->postTranslate(origin);
        moved->setTransform(xf);
        const pqdc::Mesh m = pqdc::extract(*moved, o);
        REQUIRE(m.points.size() == ref.points.size());
        CHECK(m.quads == ref.quads);
        double worst = 0;
        for (std::size_t i = 0; i < m.points.size(); ++i)
            worst = std::max(worst, (xf->worldToIndex(m.points[i]) - ref.points[i]).length());
        INFO("voxel " << voxel << " origin " << origin);
        CHECK(worst < 1e-6);
    }
}

TEST_CASE("voxels next to the 32-bit index limits are refused by name, a little farther in they mesh", "[extract]") {
    // A small sphere at index x = c: near INT_MAX the noise estimate hung,
    // near INT_MIN it crashed (blocks around the voxels wrapped around).
    auto sphere_at = [](std::int64_t c) {
        auto g = openvdb::FloatGrid::create(3.0f);
        g->setName("far");
        g->setGridClass(openvdb::GRID_LEVEL_SET);
        auto acc = g->getAccessor();
        for (int i = -7; i <= 7; ++i)
            for (int j = -7; j <= 7; ++j)
                for (int k = -7; k <= 7; ++k) {
                    const float d = float(std::sqrt(double(i * i + j * j + k * k)) - 4.0);
                    if (std::abs(d) < 3) acc.setValue(openvdb::Coord(int(c + i), j, k), d);
                }
        return g;
    };
    for (std::int64_t c : {std::int64_t(2147483640), std::int64_t(-2147483640)}) {
        const auto g = sphere_at(c);
        INFO("x = " << c);
        try {
            pqdc::extract(*g, pqdc::ExtractOptions{});
            FAIL("accepted");
        } catch (const pqdc::input_error& e) {
            CHECK(std::string(e.what()).find("grid 'far'") != std::string::npos);
            CHECK(std::string(e.what()).find("32-bit index limits") != std::string::npos);
        }
        CHECK_THROWS_AS(pqdc::extract_adaptive(*g, pqdc::AdaptiveOptions{}), pqdc::input_error);
    }
    for (std::int64_t c : {std::int64_t(2147483647 - 5000), std::int64_t(-2147483647 + 5000)}) {
        const pqdc::Mesh m = pqdc::extract(*sphere_at(c), pqdc::ExtractOptions{});
        INFO("x = " << c);
        CHECK(pqdc::measure_topology(m).closed());
        CHECK(m.triangles.size() > 100);
    }
}

TEST_CASE("unsupported transforms are refused with the grid's name", "[extract]") {
    auto grid = vdb_sphere(6.0f);
    grid->setName("density");
    grid->setTransform(openvdb::math::Transform::createFrustumTransform(
        openvdb::BBoxd(Vec3d(-10.0), Vec3d(10.0)), 0.5, 2.0, 1.0));
    try {
        pqdc::extract(*grid, pqdc::ExtractOptions{});
        FAIL("frustum accepted");
    } catch (const pqdc::input_error& e) {
        CHECK(std::string(e.what()).find("'density'") != std::string::npos);
    }
}

TEST_CASE("a surface cut by the active region is open exactly at the cut", "[extract]") {
    auto grid = vdb_sphere(10.0f, 1.0f, Vec3d(0.0));
    // Deactivate everything at x > 2 (values stay): cells there have no active corner.
    for (auto it = grid->tree().beginValueOn(); it; ++it)
        if (it.getCoord().x() > 2) it.setValueOff();
    const pqdc::Mesh m = pqdc::extract(*grid, pqdc::ExtractOptions{});
    const pqdc::TopologyReport t = pqdc::measure_topology(m);
    CHECK(t.boundary_edge_count > 0);
    CHECK(t.edge_manifold());
    CHECK(t.consistently_oriented());
    // Boundary vertices sit at the cut (the last cells with an active corner reach x = 3).
    std::vector<int> uses(m.points.size(), 0);
    std::map<std::pair<unsigned, unsigned>, int> edges;
    for (const auto& tr : m.triangles)
        for (int i = 0; i < 3; ++i) {
            unsigned a = tr[i], b = tr[(i + 1) % 3];
            if (a > b) std::swap(a, b);
            ++edges[{a, b}];
        }
    for (const auto& [e, n] : edges)
        if (n == 1) {
            CHECK(m.points[e.first].x() > 1.5);
            CHECK(m.points[e.second].x() > 1.5);
            CHECK(m.points[e.first].x() < 3.0);
        }
    for (const auto& p : m.points) CHECK(p.x() < 3.0);
}

TEST_CASE("procedural fields written as VDB mesh like the field", "[extract]") {
    const auto field = pqdc::make_procedural("sphere");
    pqdc::ProceduralSampling s;
    s.resolution = 32;
    const std::string path = std::string(PQDC_BINARY_DIR) + "/test_extract_sphere.vdb";
    pqdc::write_grid(*pqdc::sample_field(*field, s), path);
    const pqdc::LoadedGrid g = pqdc::read_scalar_grid(path);
    REQUIRE(g.grid);
    const pqdc::Mesh m = pqdc::extract(*g.grid, pqdc::ExtractOptions{});
    require_watertight(m, "sphere via VDB file");
    const double h = g.grid->voxelSize()[0];
    CHECK(pqdc::measure_distance(m, *field).max < 0.05 * h);
    std::remove(path.c_str());
}

TEST_CASE("the shipped real-model level sets mesh closed and manifold", "[extract]") {
    for (const std::string name : {"fandisk", "armadillo"}) {
        const pqdc::LoadedGrid g = pqdc::read_scalar_grid(std::string(PQDC_SOURCE_DIR) + "/volumes/" + name + ".vdb");
        for (double sigma : {0.0, 0.1, std::numeric_limits<double>::infinity()}) {
            pqdc::ExtractOptions o;
            o.sigma_n = sigma;
            pqdc::ExtractStats st;
            const pqdc::Mesh m = pqdc::extract(*g.grid, o, &st);
            require_watertight(m, name + " sigma_n " + std::to_string(sigma));
            CHECK(st.fallback_vertices == 0);
            // Vertices stay near the zero level set (values are world distances).
            const auto* ls = dynamic_cast<const openvdb::FloatGrid*>(g.grid.get());
            REQUIRE(ls);
            CHECK(pqdc::measure_distance(m, *ls).mean < 0.1 * ls->voxelSize()[0]);
        }
    }
}

namespace {

/// An ExtractOptions::values_done that counts its calls and frees `grid`.
std::function<void()> free_when_read(const openvdb::FloatGrid::Ptr& grid, int& calls) {
    return [grid, &calls] {
        ++calls;
        grid->clear();
    };
}

}  // namespace

TEST_CASE("values_done lets the caller free the grid once it has been read, without changing the mesh", "[extract][memory]") {
    pqdc::ExtractOptions o;
    const auto reference_grid = vdb_sphere(20.f);
    pqdc::ExtractStats reference_stats;
    const pqdc::Mesh reference = pqdc::extract(*reference_grid, o, &reference_stats);
    REQUIRE(!reference.empty());

    // Freed in the middle of the run: the same mesh, and the grid is empty.
    auto grid = vdb_sphere(20.f);
    int calls = 0;
    o.values_done = free_when_read(grid, calls);
    pqdc::ExtractStats stats;
    const pqdc::Mesh mesh = pqdc::extract(*grid, o, &stats);
    CHECK(calls == 1);
    CHECK(grid->activeVoxelCount() == 0);
    CHECK(mesh.points == reference.points);
    CHECK(mesh.triangles == reference.triangles);
    CHECK(stats.vertices == reference_stats.vertices);

    // Runs that read the grid again do not call it.
    calls = 0;
    auto kept = vdb_sphere(20.f);
    o.values_done = [&] { ++calls; };
    o.vertex_normals = true;  // normals are read from the grid at the end
    CHECK(!pqdc::extract(*kept, o).normals.empty());
    o.vertex_normals = false;
    o.isovalue = 100.f;  // no surface: the caller may want to read why
    CHECK(pqdc::extract(*kept, o).empty());
    CHECK(calls == 0);
}

TEST_CASE("a freed grid still gets the warning about the active region's edge", "[extract][memory]") {
    // A fog volume just above its background hugs the active region's edge:
    // the warning counts the vertices there from the active voxels, which
    // the run keeps (as a mask) when it may need them.
    auto make_fog = [] {
        auto fog = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(12.f, openvdb::Vec3f(0.3f), 1.f, 3.f);
        openvdb::tools::sdfToFogVolume(*fog);
        return fog;
    };
    pqdc::ExtractOptions o;
    o.isovalue = 0.01;
    pqdc::ExtractStats reference;
    const pqdc::Mesh expected = pqdc::extract(*make_fog(), o, &reference);
    REQUIRE(reference.warnings.size() == 1);
    REQUIRE(reference.warnings[0].find("edge of the active region") != std::string::npos);

    auto fog = make_fog();
    int calls = 0;
    o.values_done = free_when_read(fog, calls);
    pqdc::ExtractStats stats;
    const pqdc::Mesh mesh = pqdc::extract(*fog, o, &stats);
    CHECK(calls == 1);
    CHECK(mesh.points == expected.points);
    CHECK(stats.warnings == reference.warnings);

    // At the background itself the warning names the largest value: the grid is kept.
    o.isovalue = 0;
    calls = 0;
    auto at_background = make_fog();
    pqdc::extract(*at_background, o, &stats);
    CHECK(calls == 0);
    CHECK(at_background->activeVoxelCount() > 0);
    REQUIRE(stats.warnings.size() == 1);
    CHECK(stats.warnings[0].find("isovalue 0.5") != std::string::npos);
}
