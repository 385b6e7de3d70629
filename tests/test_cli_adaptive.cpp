// The pqdc CLI's adaptive mode: the real binary, its options and --stats.
#include "cli_runner.hpp"

#include "pqdc/measure.hpp"
#include "pqdc/mesh_io.hpp"

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>

using pqdc_test::RunResult;
using pqdc_test::RunSpec;
using pqdc_test::run_program;

TEST_CASE("pqdc --adaptive meshes a shipped volume with far fewer faces, watertight", "[cli][adaptive]") {
    const std::string dir = std::string(PQDC_BINARY_DIR) + "/";
    const std::string uniform = dir + "cli_adaptive_uniform.ply", adaptive = dir + "cli_adaptive.ply";
    const std::string stats = dir + "cli_adaptive.json";
    const std::string volume = std::string(PQDC_SOURCE_DIR) + "/volumes/fandisk.vdb";

    RunSpec u;
    u.args = {volume, "-o", uniform, "-q"};
    REQUIRE(run_program(PQDC_CLI_PATH, u).exit_code == 0);
    RunSpec a;
    a.args = {volume, "--adaptive", "--max-error", "0.1", "--max-cell-size", "32", "-o", adaptive, "--stats", stats, "-q"};
    const RunResult r = run_program(PQDC_CLI_PATH, a);
    INFO(r.err);
    REQUIRE(r.exit_code == 0);

    const pqdc::Mesh mu = pqdc::read_mesh(uniform), ma = pqdc::read_mesh(adaptive);
    CHECK(ma.face_count() * 3 < mu.face_count());
    const pqdc::TopologyReport t = pqdc::measure_topology(ma);
    CHECK(t.closed());
    CHECK(t.edge_manifold());
    CHECK(t.consistently_oriented());
    const auto json = nlohmann::json::parse(pqdc_test::read_file(stats));
    CHECK(json["mode"] == "adaptive");
    CHECK(json["max_error_voxels"] == 0.1);
    // The octree's figures: merges happened, leaves up to the cell size limit only.
    CHECK(json["adaptive"]["max_cell_size_voxels"] == 32);
    CHECK(json["adaptive"]["merges"] > 0);
    CHECK(json["adaptive"]["surface_leaves_by_size_voxels"].contains("1"));
    CHECK_FALSE(json["adaptive"]["surface_leaves_by_size_voxels"].contains("64"));
    CHECK(json["adaptive"]["refused"].contains("error"));
    for (const auto& p : {uniform, adaptive, stats}) std::remove(p.c_str());
}

TEST_CASE("adaptive options are usage errors when misused", "[cli][adaptive]") {
    const std::string out = std::string(PQDC_BINARY_DIR) + "/cli_adaptive_bad.obj";
    for (const auto& args : std::vector<std::vector<std::string>>{
             {"--procedural", "sphere", "--max-error", "0.2", "-o", out},
             {"--procedural", "sphere", "--adaptive", "--max-error", "-1", "-o", out},
             {"--procedural", "sphere", "--adaptive", "--max-cell-size", "48", "-o", out}}) {
        RunSpec s;
        s.args = args;
        const RunResult r = run_program(PQDC_CLI_PATH, s);
        INFO(r.err);
        CHECK(r.exit_code == 2);
        CHECK((r.err.find("--max-error") != std::string::npos || r.err.find("--max-cell-size") != std::string::npos));
        CHECK(!std::ifstream(out).good());
    }
}
