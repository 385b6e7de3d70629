// The pqdc CLI on the inputs of issue 12 items 1-4: what it says about the
// interior side, the warnings it prints, anisotropic voxels, and regions
// (--bbox, --mask, --invert-mask) with their usage errors.
#include "cli_runner.hpp"
#include "mesh_checks.hpp"

#include "pqdc/measure.hpp"
#include "pqdc/mesh_io.hpp"

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <openvdb/tools/Composite.h>
#include <openvdb/tools/LevelSetUtil.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

using openvdb::Vec3d;
using pqdc_test::RunResult;
using pqdc_test::RunSpec;
using pqdc_test::ScratchDir;

namespace {

struct Init {
    Init() { openvdb::initialize(); }
} init_openvdb;

/// Runs pqdc; with PQDC_CLI_TRANSCRIPT=FILE set, appends the run to the
/// bad-input catalogue as test_cli.cpp does (scripts/bad-input-messages.sh).
RunResult pqdc_run(const ScratchDir& dir, std::vector<std::string> args) {
    RunSpec spec;
    spec.args = args;
    spec.cwd = dir.dir();
    const RunResult r = pqdc_test::run_program(PQDC_CLI_PATH, spec);
    if (const char* path = std::getenv("PQDC_CLI_TRANSCRIPT")) {
        std::string command = "pqdc", err;
        for (const auto& a : args) command += " " + a;
        for (char c : r.err) err += c == '\n' ? std::string(" ") : c == '|' ? std::string("\\|") : std::string(1, c);
        while (!err.empty() && err.back() == ' ') err.pop_back();
        std::ofstream(path, std::ios::app) << "| " << Catch::getResultCapture().getCurrentTestName() << " | `"
                                           << command << "` | " << r.exit_code << " | " << err << " |\n";
    }
    return r;
}

bool has(const std::string& s, const std::string& needle) { return s.find(needle) != std::string::npos; }

nlohmann::json read_json(const std::string& path) { return nlohmann::json::parse(pqdc_test::read_file(path)); }

openvdb::FloatGrid::Ptr level_set(const std::string& name, double voxel = 0.5) {
    auto g = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(8.f, openvdb::Vec3f(0.2f), float(voxel), 3.f);
    g->setName(name);
    return g;
}

/// CT-like: 1000 inside a ball of radius 8 voxels, -1000 air, unknown class.
openvdb::FloatGrid::Ptr ct(const std::string& name) {
    auto g = openvdb::FloatGrid::create(-1000.f);
    g->setName(name);
    auto acc = g->getAccessor();
    for (int i = -13; i <= 13; ++i)
        for (int j = -13; j <= 13; ++j)
            for (int k = -13; k <= 13; ++k)
                acc.setValue(openvdb::Coord(i, j, k),
                             float(1000.0 * std::tanh((8.0 - std::sqrt(double(i * i + j * j + k * k))) / 1.5)));
    return g;
}

}  // namespace

TEST_CASE("pqdc says which side is inside and why, and a CT grid comes out outward", "[cli][interior]") {
    ScratchDir dir("cli_interior");
    openvdb::io::File(dir.path("ct.vdb")).write({ct("density")});
    const RunResult r = pqdc_run(dir, {"ct.vdb", "--isovalue", "300", "-o", "m.ply", "--stats", "s.json"});
    INFO(r.err);
    REQUIRE(r.exit_code == 0);
    CHECK(has(r.err, "inside above the isovalue"));
    CHECK(has(r.err, "background -1000 is below the isovalue 300"));
    CHECK(pqdc_test::signed_volume(pqdc::read_mesh(dir.path("m.ply"))) > 0);
    const nlohmann::json j = read_json(dir.path("s.json"));
    CHECK(j["interior"] == "above");
    CHECK(has(j["interior_reason"].get<std::string>(), "background"));
    CHECK(j["warnings"].empty());
    CHECK(j["region"].is_null());
}

TEST_CASE("pqdc warns when a fog volume is meshed at its background value", "[cli][interior]") {
    ScratchDir dir("cli_fog");
    auto fog = level_set("fog", 1.0);
    openvdb::tools::sdfToFogVolume(*fog);
    openvdb::io::File(dir.path("fog.vdb")).write({fog});
    const RunResult r = pqdc_run(dir, {"fog.vdb", "-o", "m.obj", "--stats", "s.json"});
    INFO(r.err);
    REQUIRE(r.exit_code == 0);
    CHECK(has(r.err, "warning: the isovalue 0 equals the background"));
    CHECK(has(r.err, "isovalue 0.5"));
    CHECK(read_json(dir.path("s.json"))["warnings"].size() == 1);
    const RunResult quiet = pqdc_run(dir, {"fog.vdb", "--isovalue", "0.5", "-o", "m.obj"});
    CHECK(quiet.exit_code == 0);
    CHECK_FALSE(has(quiet.err, "warning"));
}

TEST_CASE("pqdc --bbox and --mask mesh a region and their errors are usage errors", "[cli][region]") {
    ScratchDir dir("cli_region");
    auto mask = openvdb::BoolGrid::create(false);
    mask->setName("left");
    mask->setTransform(openvdb::math::Transform::createLinearTransform(0.5));
    mask->fill(openvdb::CoordBBox(openvdb::Coord(-40), openvdb::Coord(2, 40, 40)), true, true);
    auto vel = openvdb::Vec3SGrid::create();
    vel->setName("vel");
    openvdb::io::File(dir.path("in.vdb")).write({level_set("sdf")});
    openvdb::io::File(dir.path("mask.vdb")).write({mask, vel});

    const RunResult full = pqdc_run(dir, {"in.vdb", "-o", "full.ply"});
    REQUIRE(full.exit_code == 0);
    const std::size_t all = pqdc::read_mesh(dir.path("full.ply")).triangles.size();
    for (const std::vector<std::string>& region :
         {std::vector<std::string>{"--bbox", "-10,-10,-10,1.25,10,10"}, {"--mask", "mask.vdb:left"},
          {"--mask", "mask.vdb"}}) {
        std::vector<std::string> args{"in.vdb", "-o", "part.ply", "--stats", "s.json"};
        args.insert(args.end(), region.begin(), region.end());
        const RunResult r = pqdc_run(dir, args);
        INFO(region[0] << " " << region[1] << ": " << r.err);
        REQUIRE(r.exit_code == 0);
        const pqdc::Mesh part = pqdc::read_mesh(dir.path("part.ply"));
        CHECK(part.triangles.size() > all / 4);
        CHECK(part.triangles.size() < all * 3 / 4);
        for (const Vec3d& v : part.points) CHECK(v.x() <= 1.5 + 1e-6);
        CHECK(pqdc::measure_topology(part).boundary_edge_count > 0);
        CHECK_FALSE(read_json(dir.path("s.json"))["region"].is_null());
    }
    const RunResult inv = pqdc_run(dir, {"in.vdb", "-o", "rest.ply", "--mask", "mask.vdb:left", "--invert-mask"});
    REQUIRE(inv.exit_code == 0);
    for (const Vec3d& v : pqdc::read_mesh(dir.path("rest.ply")).points) CHECK(v.x() >= 1.25 - 1e-6);

    auto fails = [&](const std::vector<std::string>& args, int code, const std::string& needle) {
        const RunResult r = pqdc_run(dir, args);
        INFO(r.err);
        CHECK(r.exit_code == code);
        CHECK(has(r.err, needle));
    };
    fails({"in.vdb", "-o", "x.ply", "--bbox", "1,2,3"}, 2, "six numbers");
    fails({"in.vdb", "-o", "x.ply", "--bbox", "0,0,0,-1,1,1"}, 2, "minimum exceeds the maximum along x");
    fails({"in.vdb", "-o", "x.ply", "--invert-mask"}, 2, "--mask");
    fails({"in.vdb", "-o", "x.ply", "--mask", "mask.vdb:nope"}, 1, "no grid named 'nope'");
    fails({"in.vdb", "-o", "x.ply", "--mask", "mask.vdb:vel"}, 1, "use as a mask");
    fails({"in.vdb", "-o", "x.ply", "--mask", "missing.vdb"}, 1, "'missing.vdb'");
}

TEST_CASE("islands: --min-component removes small components and keeps the surface, 0 keeps all",
          "[cli]") {
    ScratchDir dir("cli_islands");
    // A sphere of radius 8 (voxel 0.5: diagonal 55 voxels) and a droplet of
    // radius 1 (diagonal about 7 voxels), both in one level set.
    auto g = level_set("sdf");
    auto drop = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(1.f, openvdb::Vec3f(12.f, 0.f, 0.f), 0.5f, 3.f);
    openvdb::tools::csgUnion(*g, *drop);
    openvdb::io::File(dir.path("in.vdb")).write({g});
    REQUIRE(pqdc_run(dir, {"in.vdb", "-o", "all.ply"}).exit_code == 0);
    const RunResult r = pqdc_run(dir, {"in.vdb", "-o", "big.ply", "--min-component", "10"});
    INFO(r.err);
    REQUIRE(r.exit_code == 0);
    CHECK(has(r.err, "removed 1 of 2 components smaller than 10 voxels"));
    CHECK(pqdc::measure_topology(pqdc::read_mesh(dir.path("all.ply"))).connected_component_count == 2);
    CHECK(pqdc::measure_topology(pqdc::read_mesh(dir.path("big.ply"))).connected_component_count == 1);
    // Removing everything says so, in core and streamed (not "no surface").
    for (const char* extra : {"--threads=2", "--out-of-core"}) {
        const RunResult all_gone = pqdc_run(dir, {"in.vdb", "-o", "none.ply", "--min-component", "1000", extra,
                                                  "--stats", "none.json"});
        INFO(all_gone.err);
        CHECK(all_gone.exit_code == 0);
        // Nothing kept: no smallest kept size (it said 0.0).
        const auto j = nlohmann::json::parse(pqdc_test::read_file(dir.path("none.json")));
        CHECK(j["components"]["smallest_kept_diagonal_voxels"].is_null());
        CHECK(j["components"]["largest_removed_diagonal_voxels"].get<double>() > 50);
        CHECK(has(all_gone.err, "--min-component 1000 removed every component"));
        CHECK(!has(all_gone.err, "no surface"));
        CHECK(pqdc::read_mesh(dir.path("none.ply")).points.empty());
    }
    const RunResult bad = pqdc_run(dir, {"in.vdb", "-o", "x.ply", "--min-component", "-1"});
    CHECK(bad.exit_code == 2);
    CHECK(has(bad.err, "--min-component is a size in voxels"));
}
