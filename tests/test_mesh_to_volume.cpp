// pqdc::mesh_to_level_set (include/pqdc/mesh_to_volume.hpp) and
// pqdc-mesh-to-volume.
#include "pqdc/exceptions.hpp"
#include "pqdc/measure.hpp"
#include "pqdc/mesh_io.hpp"
#include "pqdc/mesh_to_volume.hpp"
#include "pqdc/volume_io.hpp"

#include "cli_runner.hpp"
#include "l_prism.hpp"

#include <catch2/catch.hpp>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>

namespace {

using openvdb::Vec3d;

// The L-prism shifted off the lattice (tests/l_prism.hpp).
const Vec3d kShift(0.013, 0.007, 0.021);

pqdc::Mesh l_prism() { return pqdc_test::l_prism(openvdb::math::Mat3d::identity(), kShift); }

bool inside_l_prism(const Vec3d& world) {
    const Vec3d p = world - kShift;
    const bool in_a = p[0] > 0 && p[0] < 2 && p[1] > 0 && p[1] < 1;
    const bool in_b = p[0] > 0 && p[0] < 1 && p[1] > 0 && p[1] < 2;
    return (in_a || in_b) && p[2] > 0 && p[2] < 1;
}

pqdc::MeshToLevelSetOptions options(double voxel) {
    pqdc::MeshToLevelSetOptions o;
    o.voxel_size = voxel;
    return o;
}

std::vector<std::pair<openvdb::Coord, float>> active_values(const openvdb::FloatGrid& grid) {
    std::vector<std::pair<openvdb::Coord, float>> v;
    for (auto it = grid.cbeginValueOn(); it; ++it) v.emplace_back(it.getCoord(), *it);
    std::sort(v.begin(), v.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    return v;
}

}  // namespace

TEST_CASE("mesh_to_level_set: every band value is the exact signed distance", "[mesh_to_volume]") {
    const pqdc::Mesh mesh = l_prism();
    const double voxel = 0.05;
    pqdc::MeshToLevelSetStats stats;
    const openvdb::FloatGrid::Ptr grid = pqdc::mesh_to_level_set(mesh, options(voxel), &stats);
    CHECK(grid->getGridClass() == openvdb::GRID_LEVEL_SET);
    CHECK(grid->background() == Approx(3 * voxel));
    CHECK(stats.boundary_edges == 0);
    CHECK(stats.inconsistent_edges == 0);
    CHECK(stats.exact_signs);
    REQUIRE(stats.active_voxels > 10000);
    const pqdc::MeshDistance distance(mesh);
    std::size_t wrong_sign = 0, wrong_distance = 0;
    for (const auto& [ijk, value] : active_values(*grid)) {
        const Vec3d p = grid->indexToWorld(ijk);
        wrong_sign += (value < 0) != inside_l_prism(p);
        wrong_distance += std::abs(std::abs(double(value)) - distance(p)) > 1e-6;
    }
    CHECK(wrong_sign == 0);
    CHECK(wrong_distance == 0);
}

TEST_CASE("mesh_to_level_set: an inside-out mesh gives the same grid", "[mesh_to_volume]") {
    pqdc::Mesh flipped = l_prism();
    for (auto& t : flipped.triangles) std::swap(t[1], t[2]);
    for (auto& q : flipped.quads) std::swap(q[1], q[3]);
    const auto a = pqdc::mesh_to_level_set(l_prism(), options(0.05));
    const auto b = pqdc::mesh_to_level_set(flipped, options(0.05));
    CHECK(active_values(*a) == active_values(*b));
}

TEST_CASE("mesh_to_level_set: the grid does not depend on the thread count", "[mesh_to_volume]") {
    openvdb::FloatGrid::Ptr one;
    {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
        one = pqdc::mesh_to_level_set(l_prism(), options(0.04));
    }
    const auto all = pqdc::mesh_to_level_set(l_prism(), options(0.04));
    CHECK(active_values(*one) == active_values(*all));
}

TEST_CASE("mesh_to_level_set: an open mesh keeps OpenVDB's signs with exact distances", "[mesh_to_volume]") {
    pqdc::Mesh open = l_prism();
    open.triangles.pop_back();  // a hole in the top cap
    pqdc::MeshToLevelSetStats stats;
    const auto grid = pqdc::mesh_to_level_set(open, options(0.05), &stats);
    CHECK(stats.boundary_edges == 3);
    CHECK_FALSE(stats.exact_signs);
    CHECK(stats.signs_changed == 0);
    const pqdc::MeshDistance distance(open);
    std::size_t wrong_distance = 0;
    for (const auto& [ijk, value] : active_values(*grid))
        wrong_distance += std::abs(std::abs(double(value)) - distance(grid->indexToWorld(ijk))) > 1e-6;
    CHECK(wrong_distance == 0);
}

TEST_CASE("mesh_to_level_set: LevelSetDistances::openvdb keeps meshToLevelSet's values", "[mesh_to_volume]") {
    pqdc::MeshToLevelSetOptions o = options(0.05);
    o.distances = pqdc::LevelSetDistances::openvdb;
    pqdc::MeshToLevelSetStats stats;
    const auto vdb = pqdc::mesh_to_level_set(l_prism(), o, &stats);
    CHECK_FALSE(stats.exact_signs);
    const auto exact = pqdc::mesh_to_level_set(l_prism(), options(0.05));
    // Same band, other values.
    const auto a = active_values(*vdb), b = active_values(*exact);
    REQUIRE(a.size() == b.size());
    for (std::size_t i = 0; i < a.size(); ++i) REQUIRE(a[i].first == b[i].first);
}

TEST_CASE("mesh_to_level_set: far from the origin the level set is the one at the origin, moved", "[mesh_to_volume]") {
    // OpenVDB converts the points to float: 1e7 units out (2e8 voxels) the
    // band and signs were voxels off, with no warning (729 active voxels
    // instead of the origin's several thousand).
    const double voxel = 0.05;
    const Vec3d far(1e7, -2e7, 3e6);
    pqdc::Mesh moved = l_prism();
    for (Vec3d& p : moved.points) p += far;
    const openvdb::FloatGrid::Ptr near = pqdc::mesh_to_level_set(l_prism(), options(voxel));
    const openvdb::FloatGrid::Ptr grid = pqdc::mesh_to_level_set(moved, options(voxel));
    CHECK(grid->activeVoxelCount() == near->activeVoxelCount());
    const pqdc::MeshDistance distance(moved);
    std::size_t wrong_sign = 0, wrong_distance = 0;
    for (const auto& [ijk, value] : active_values(*grid)) {
        const Vec3d p = grid->indexToWorld(ijk);
        wrong_sign += (value < 0) != inside_l_prism(p - far);
        wrong_distance += std::abs(std::abs(double(value)) - distance(p)) > 1e-6;
    }
    CHECK(wrong_sign == 0);
    CHECK(wrong_distance == 0);
}

TEST_CASE("mesh_to_level_set: invalid options and meshes are refused", "[mesh_to_volume]") {
    CHECK_THROWS_AS(pqdc::mesh_to_level_set(l_prism(), options(0)), pqdc::option_error);
    // OpenVDB's ArithmeticError ("Non-zero scale values required") came through.
    CHECK_THROWS_WITH(pqdc::mesh_to_level_set(l_prism(), options(1e-12)), Catch::Contains("scale the mesh up"));
    // ... also just below OpenVDB's own limit (a cubic voxel of 1.44e-5), which 1e-8 let through.
    CHECK_THROWS_WITH(pqdc::mesh_to_level_set(l_prism(), options(1.2e-5)), Catch::Contains("scale the mesh up"));
    CHECK_THROWS_AS(pqdc::mesh_to_level_set(l_prism(), options(std::nan(""))), pqdc::option_error);
    pqdc::MeshToLevelSetOptions narrow = options(0.05);
    narrow.half_width_voxels = 0.5;
    CHECK_THROWS_WITH(pqdc::mesh_to_level_set(l_prism(), narrow), Catch::Contains("half_width_voxels"));
    CHECK_THROWS_AS(pqdc::mesh_to_level_set(pqdc::Mesh{}, options(0.05)), pqdc::input_error);
    pqdc::Mesh bad = l_prism();
    bad.triangles.emplace_back(0, 1, 99);
    CHECK_THROWS_WITH(pqdc::mesh_to_level_set(bad, options(0.05)), Catch::Contains("vertex 99"));
    bad = l_prism();
    bad.points[4][1] = std::nan("");
    CHECK_THROWS_WITH(pqdc::mesh_to_level_set(bad, options(0.05)), Catch::Contains("point 4"));
}

#ifdef PQDC_MESH_TO_VOLUME_PATH
TEST_CASE("pqdc-mesh-to-volume writes the library's level set and refuses bad options", "[mesh_to_volume][cli]") {
    pqdc_test::ScratchDir dir("mesh_to_volume_cli");
    pqdc::write_mesh(l_prism(), dir.path("l.off"));
    auto convert = [&dir](std::vector<std::string> args) {
        pqdc_test::RunSpec spec;
        spec.cwd = dir.dir();
        spec.args = std::move(args);
        return pqdc_test::run_program(PQDC_MESH_TO_VOLUME_PATH, spec);
    };
    auto grid_in = [&dir](const std::string& file) {
        return openvdb::gridPtrCast<openvdb::FloatGrid>(pqdc::read_scalar_grid(dir.path(file)).grid);
    };
    const auto ok = convert({"l.off", "-o", "l.vdb", "--voxel-size", "0.05", "--quiet"});
    INFO(ok.err);
    REQUIRE(ok.exit_code == 0);
    CHECK(ok.err.empty());
    const auto written = grid_in("l.vdb");
    REQUIRE(written);
    const auto library = pqdc::mesh_to_level_set(pqdc::read_mesh(dir.path("l.off")), options(0.05));
    CHECK(active_values(*written) == active_values(*library));

    // STL arrives as welded float triangles: the same closed surface, the
    // same band, values within float rounding of the points.
    pqdc::write_mesh(l_prism(), dir.path("l.stl"));
    const auto stl = convert({"l.stl", "-o", "s.vdb", "--voxel-size", "0.05", "--quiet"});
    INFO(stl.err);
    REQUIRE(stl.exit_code == 0);
    CHECK(stl.err.empty());
    const auto a = active_values(*grid_in("s.vdb")), b = active_values(*written);
    REQUIRE(a.size() == b.size());
    std::size_t differ = 0;
    for (std::size_t i = 0; i < a.size(); ++i)
        differ += a[i].first != b[i].first || std::abs(a[i].second - b[i].second) > 1e-6f;
    CHECK(differ == 0);

    // --resolution spans the surface, not a vertex no face uses (a stray
    // point 1000 away made the voxel 62.5 for a unit tetrahedron).
    pqdc::Mesh stray = l_prism();
    stray.points.push_back(openvdb::Vec3d(1000.0));
    pqdc::write_mesh(stray, dir.path("stray.off"));
    pqdc::write_mesh(l_prism(), dir.path("plain.off"));
    REQUIRE(convert({"stray.off", "-o", "stray.vdb", "--resolution", "16", "--quiet"}).exit_code == 0);
    REQUIRE(convert({"plain.off", "-o", "plain.vdb", "--resolution", "16", "--quiet"}).exit_code == 0);
    CHECK(grid_in("stray.vdb")->voxelSize() == grid_in("plain.vdb")->voxelSize());
    CHECK(active_values(*grid_in("stray.vdb")) == active_values(*grid_in("plain.vdb")));

    const auto bad = convert({"l.off", "-o", "m.vdb", "--distances", "fast"});
    CHECK(bad.exit_code == 2);
    CHECK(bad.err.find("--distances") != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(dir.path("m.vdb")));

    pqdc::Mesh open = l_prism();
    open.triangles.pop_back();
    pqdc::write_mesh(open, dir.path("open.off"));
    const auto warned = convert({"open.off", "-o", "open.vdb", "--voxel-size", "0.05", "--quiet"});
    CHECK(warned.exit_code == 0);
    CHECK(warned.err.find("'open.off' is not closed (3 edges") != std::string::npos);
}
#endif
