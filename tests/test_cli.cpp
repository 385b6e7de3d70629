// The pqdc command line under bad input, faults and hostile volumes (issue 6).
// Every case runs the real binary and checks the exit code, that stderr names
// the problem and what to do, and that no output (or a pre-existing one,
// intact) and no temporary file is left behind.
#include "random.hpp"
#include "cli_runner.hpp"
#include "mesh_checks.hpp"

#include "pqdc/brick_store.hpp"
#include "pqdc/exceptions.hpp"
#include "pqdc/measure.hpp"
#include "pqdc/mesh.hpp"
#include "pqdc/mesh_io.hpp"

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>

#include <sys/mount.h>
#include <sys/stat.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <map>
#include <random>
#include <set>
#include <string>
#include <vector>

// tests/CMakeLists.txt passes the binary's path when the apps are built.
#ifdef PQDC_CLI_PATH

using openvdb::Vec3d;
using pqdc_test::RunResult;
using pqdc_test::RunSpec;
using pqdc_test::ScratchDir;
using pqdc_test::check_closed_manifold;

namespace {

struct Init {
    Init() { openvdb::initialize(); }
} init_openvdb;

const std::string kSentinel = "previous output, must survive\n";

RunResult pqdc_in(const ScratchDir& dir, std::vector<std::string> args, RunSpec spec = {}) {
    spec.args = std::move(args);
    spec.cwd = dir.dir();
    return pqdc_test::run_program(PQDC_CLI_PATH, spec);
}

std::string describe(const std::vector<std::string>& args, const RunResult& r) {
    std::string s = "pqdc";
    for (const auto& a : args) s += " " + a;
    return s + "\n  exit " + std::to_string(r.exit_code) + " signal " + std::to_string(r.term_signal) +
           "\n  stderr: " + r.err;
}

bool contains(const std::string& haystack, const std::string& needle) {
    return haystack.find(needle) != std::string::npos;
}

/// With PQDC_CLI_TRANSCRIPT=FILE set, every catalogue run appends a
/// markdown table row (test, command, exit code, stderr) to FILE:
/// scripts/bad-input-messages.sh builds docs/bad-inputs.md from it.
void record_transcript(const std::vector<std::string>& args, const RunResult& r) {
    const char* path = std::getenv("PQDC_CLI_TRANSCRIPT");
    if (!path) return;
    std::string command = "pqdc", err;
    for (const auto& a : args) command += " " + a;
    for (char c : r.err) {
        if (c == '\n') err += ' ';
        else if (c == '|') err += "\\|";
        else err += c;
    }
    while (!err.empty() && err.back() == ' ') err.pop_back();
    std::ofstream(path, std::ios::app) << "| " << Catch::getResultCapture().getCurrentTestName() << " | `" << command
                                       << "` | " << r.exit_code << " | " << err << " |\n";
}

/// Runs pqdc with out.obj (or `output`) holding a previous result and checks
/// a clean failure: the exit code, every needle in stderr, the previous
/// output byte for byte, and no new file in the directory.
RunResult expect_failure(const ScratchDir& dir, const std::vector<std::string>& args, int exit_code,
                         const std::vector<std::string>& needles, RunSpec spec = {},
                         const std::string& output = "out.obj") {
    pqdc_test::write_file(dir.path(output), kSentinel);
    const auto before = dir.entries();
    const RunResult r = pqdc_in(dir, args, spec);
    record_transcript(args, r);
    INFO(describe(args, r));
    CHECK_FALSE(r.timed_out);
    CHECK(r.term_signal == 0);
    CHECK(r.exit_code == exit_code);
    for (const auto& n : needles) {
        INFO("stderr should contain: " << n);
        CHECK(contains(r.err, n));
    }
    CHECK(pqdc_test::read_file(dir.path(output)) == kSentinel);
    CHECK(dir.entries() == before);
    return r;
}

/// Runs pqdc expecting success and returns the mesh it wrote.
pqdc::Mesh expect_mesh(const ScratchDir& dir, const std::vector<std::string>& args, const std::string& output,
                       RunResult* result = nullptr) {
    std::remove(dir.path(output).c_str());
    const RunResult r = pqdc_in(dir, args);
    record_transcript(args, r);
    if (result) *result = r;
    INFO(describe(args, r));
    REQUIRE(r.exit_code == 0);
    for (const auto& e : dir.entries()) CHECK_FALSE(contains(e, ".tmp-"));
    return pqdc::read_mesh(dir.path(output));
}

void write_vdb(const std::string& path, const openvdb::GridPtrVec& grids) { openvdb::io::File(path).write(grids); }

openvdb::FloatGrid::Ptr sphere(double radius_voxels, double voxel = 1.0, const Vec3d& center = Vec3d(0.3, -0.2, 0.1),
                               float half_width = 3.0f, const std::string& name = "sdf") {
    auto g = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(float(radius_voxels * voxel), center,
                                                                        float(voxel), half_width);
    g->setName(name);
    return g;
}

void check_finite(const pqdc::Mesh& m) {
    const pqdc::TopologyReport t = pqdc::measure_topology(m);  // also throws on out-of-range indices
    CHECK(t.non_finite_point_count == 0);
}

/// The three-grid file several cases share: a level set, a fog volume, a vector grid.
std::string write_multigrid(const ScratchDir& dir) {
    auto fog = sphere(5.0, 1.0, Vec3d(0.0), 3.0f, "density");
    fog->setGridClass(openvdb::GRID_UNKNOWN);
    auto vel = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
    vel->setName("vel");
    vel->tree().setValue(openvdb::Coord(1, 2, 3), openvdb::Vec3s(1.0f, 0.0f, 0.0f));
    write_vdb(dir.path("multi.vdb"), {vel, sphere(6.0), fog});
    return "multi.vdb";
}

}  // namespace

// ------------------------------------------------------------------ files

TEST_CASE("missing, unreadable, empty, non-VDB and non-regular inputs", "[cli][robust]") {
    ScratchDir dir("bad_files", pqdc_test::ScratchLocation::world_reachable);  // a section runs as nobody
    write_vdb(dir.path("good.vdb"), {sphere(6.0)});

    expect_failure(dir, {"missing.vdb", "-o", "out.obj"}, 1, {"'missing.vdb'", "No such file", "check the path"});
    expect_failure(dir, {"nodir/missing.vdb", "-o", "out.obj"}, 1, {"'nodir/missing.vdb'", "No such file"});

    pqdc_test::write_file(dir.path("empty.vdb"), "");
    expect_failure(dir, {"empty.vdb", "-o", "out.obj"}, 1, {"'empty.vdb'", "empty", "written completely"});

    pqdc_test::write_file(dir.path("notes.vdb"), "these are not voxels\n");
    expect_failure(dir, {"notes.vdb", "-o", "out.obj"}, 1,
                   {"'notes.vdb'", "not a readable OpenVDB file", "re-export"});
    // A mesh given where a volume is expected.
    pqdc_test::write_file(dir.path("mesh.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    expect_failure(dir, {"mesh.obj", "-o", "out.obj"}, 1, {"'mesh.obj'", "not a readable OpenVDB file"});

    std::filesystem::create_directory(dir.path("adir.vdb"));
    expect_failure(dir, {"adir.vdb", "-o", "out.obj"}, 1, {"'adir.vdb'", "is a directory", ".vdb file"});
    expect_failure(dir, {"/dev/null", "-o", "out.obj"}, 1, {"'/dev/null'", "not a regular file"});

    SECTION("unreadable: no read permission") {
        // As root permissions do not apply, so the run drops to nobody; the
        // directory must then be writable for the output check to pass.
        std::filesystem::permissions(dir.dir(), std::filesystem::perms::all);
        std::filesystem::copy_file(dir.path("good.vdb"), dir.path("secret.vdb"));
        std::filesystem::permissions(dir.path("secret.vdb"), std::filesystem::perms::none);
        RunSpec spec;
        spec.as_nobody = true;
        expect_failure(dir, {"secret.vdb", "-o", "out.obj"}, 1,
                       {"'secret.vdb'", "Permission denied", "permissions"}, spec);
        std::filesystem::permissions(dir.path("secret.vdb"), std::filesystem::perms::owner_all);

        // A brick store's unreadable index or brick is a permission problem,
        // not a missing index ("make one") or a damaged store ("split it again").
        const openvdb::FloatGrid::Ptr big = sphere(150.0);
        pqdc::write_brick_store(*big, dir.path("store"));
        const auto readable = std::filesystem::perms::owner_all | std::filesystem::perms::others_read |
                              std::filesystem::perms::others_exec;
        for (const auto& entry : std::filesystem::directory_iterator(dir.path("store")))
            std::filesystem::permissions(entry.path(), readable);
        std::filesystem::permissions(dir.path("store"), readable);
        for (const std::string file : {"index.txt", "brick-000001.vdb"}) {
            INFO(file);
            std::filesystem::permissions(dir.path("store/" + file), std::filesystem::perms::none);
            const RunResult r = expect_failure(dir, {"store", "-o", "out.obj"}, 1,
                                               {"store/" + file + "': Permission denied (check its permissions)"}, spec);
            CHECK_FALSE(contains(r.err, "split"));
            CHECK_FALSE(contains(r.err, "make one"));
            std::filesystem::permissions(dir.path("store/" + file), readable);
        }
    }
}

TEST_CASE("truncated files fail cleanly at every length", "[cli][robust]") {
    ScratchDir dir("truncated");
    write_vdb(dir.path("good.vdb"), {sphere(6.0)});
    const std::string bytes = pqdc_test::read_file(dir.path("good.vdb"));
    REQUIRE(bytes.size() > 1000);
    // The header region byte by byte, then points spread over the rest.
    std::set<std::size_t> lengths;
    for (std::size_t n = 1; n <= 72; n += 3) lengths.insert(n);
    for (int i = 1; i < 16; ++i) lengths.insert(bytes.size() * i / 16);
    lengths.insert(bytes.size() - 1);
    for (const std::size_t n : lengths) {
        INFO("truncated to " << n << " of " << bytes.size() << " bytes");
        pqdc_test::write_file(dir.path("cut.vdb"), bytes.substr(0, n));
        const RunResult r = expect_failure(dir, {"cut.vdb", "-o", "out.obj"}, 1, {"'cut.vdb'"});
        CHECK((contains(r.err, "truncated") || contains(r.err, "corrupt")));
    }
}

TEST_CASE("pqdc without its worker program says where the worker belongs and writes nothing", "[cli][robust]") {
    // pqdc runs pqdc-job from a path relative to its own (libexec/pqdc/); a
    // copy of pqdc alone is an incomplete installation.
    ScratchDir dir("no_worker");
    write_vdb(dir.path("in.vdb"), {sphere(6.0)});
    std::filesystem::create_directories(dir.path("bin"));
    std::filesystem::copy_file(PQDC_CLI_PATH, dir.path("bin/pqdc"));
    RunSpec spec;
    spec.args = {"in.vdb", "-o", "out.obj"};
    spec.cwd = dir.dir();
    const RunResult r = pqdc_test::run_program(dir.path("bin/pqdc"), spec);
    INFO(r.err);
    CHECK(r.exit_code == 1);
    CHECK(contains(r.err, "cannot start pqdc's worker program"));
    CHECK(contains(r.err, "pqdc-job"));
    CHECK(contains(r.err, "installation"));
    CHECK_FALSE(std::filesystem::exists(dir.path("out.obj")));
}

TEST_CASE("bit-flipped files never crash pqdc", "[cli][robust]") {
    // OpenVDB's reader overflows heap buffers on some of these; pqdc reads in a
    // child process and must turn that into an error naming the file.
    ScratchDir dir("bitflip");
    write_vdb(dir.path("good.vdb"), {sphere(6.0)});
    const std::string bytes = pqdc_test::read_file(dir.path("good.vdb"));
    pqdc_test::Random rng(6);
    int failed = 0, meshed = 0;
    for (int trial = 0; trial < 40; ++trial) {
        std::string flipped = bytes;
        const int flips = 1 + trial % 3;
        for (int f = 0; f < flips; ++f) {
            // Half the flips in the first 2 KiB (header, metadata, topology), where they do the most harm.
            const std::size_t span = (rng.bits() & 1) ? std::min<std::size_t>(2048, bytes.size()) : bytes.size();
            flipped[rng.bits() % span] ^= char(1u << (rng.bits() % 8));
        }
        pqdc_test::write_file(dir.path("flipped.vdb"), flipped);
        std::remove(dir.path("out.obj").c_str());
        const RunResult r = pqdc_in(dir, {"flipped.vdb", "-o", "out.obj", "--quiet"});
        if (r.exit_code != 0) record_transcript({"flipped.vdb", "-o", "out.obj", "--quiet"}, r);
        INFO("trial " << trial << ": " << describe({"flipped.vdb"}, r));
        REQUIRE(r.term_signal == 0);
        REQUIRE((r.exit_code == 0 || r.exit_code == 1));
        for (const auto& e : dir.entries()) CHECK_FALSE(contains(e, ".tmp-"));
        if (r.exit_code == 1) {
            ++failed;
            CHECK(contains(r.err, "'flipped.vdb'"));
            CHECK_FALSE(std::filesystem::exists(dir.path("out.obj")));
        } else {
            ++meshed;  // the flip hit voxel values: any mesh is fine as long as it is sane
            check_finite(pqdc::read_mesh(dir.path("out.obj")));
        }
    }
    CHECK(failed > 0);
    INFO(failed << " rejected, " << meshed << " meshed");
}

// ------------------------------------------------------------------ grids

TEST_CASE("grid selection: none, several, unknown names and non-scalar types", "[cli][robust]") {
    ScratchDir dir("grids");
    const std::string multi = write_multigrid(dir);

    SECTION("several scalar grids and no --grid: says which one and lists them") {
        RunResult r;
        const pqdc::Mesh m = expect_mesh(dir, {multi, "-o", "m.obj"}, "m.obj", &r);
        // File order is vel, sdf, density; vdb_print (io::File) lists by name.
        CHECK(contains(r.err, "several scalar grids ('density', 'sdf')"));
        CHECK(contains(r.err, "using 'density'"));
        CHECK(contains(r.err, "--grid"));
        check_closed_manifold(m);
    }
    SECTION("--grid picks another one") {
        RunResult r;
        expect_mesh(dir, {multi, "--grid", "density", "-o", "m.obj"}, "m.obj", &r);
        CHECK(contains(r.err, "using grid 'density'"));
    }
    SECTION("a --grid name that does not exist lists the names there are") {
        expect_failure(dir, {multi, "--grid", "sdff", "-o", "out.obj"}, 1,
                       {"'multi.vdb' has no grid named 'sdff'", "'density', 'sdf', 'vel'", "--grid"});
    }
    SECTION("a non-scalar grid by name lists the scalar ones") {
        expect_failure(dir, {multi, "--grid", "vel", "-o", "out.obj"}, 1,
                       {"grid 'vel'", "'multi.vdb'", "vec3s", "choose one of 'density', 'sdf'"});
    }
    SECTION("no grids at all") {
        write_vdb(dir.path("nogrids.vdb"), {});
        expect_failure(dir, {"nogrids.vdb", "-o", "out.obj"}, 1, {"'nogrids.vdb'", "contains no grids"});
    }
    SECTION("only vector, bool, mask and int grids") {
        auto vel = openvdb::Vec3SGrid::create();
        vel->setName("vel");
        auto flags = openvdb::BoolGrid::create();
        flags->setName("flags");
        auto mask = openvdb::MaskGrid::create();
        mask->setName("mask");
        auto ids = openvdb::Int32Grid::create();
        ids->setName("ids");
        ids->tree().setValue(openvdb::Coord(0), 7);
        write_vdb(dir.path("nonscalar.vdb"), {vel, flags, mask, ids});
        expect_failure(dir, {"nonscalar.vdb", "-o", "out.obj"}, 1,
                       {"'nonscalar.vdb' has no float or double grid", "'vel' (vec3s)", "'flags' (bool)",
                        "'mask' (mask)", "'ids' (int32)", "convert"});
        expect_failure(dir, {"nonscalar.vdb", "--grid", "ids", "-o", "out.obj"}, 1,
                       {"grid 'ids'", "int32", "this file has none"});
    }
    SECTION("double grids are meshed like float grids") {
        auto d = openvdb::tools::createLevelSetSphere<openvdb::DoubleGrid>(6.0, openvdb::Vec3f(0.3f), 1.0, 3.0);
        d->setName("dsdf");
        write_vdb(dir.path("double.vdb"), {d});
        check_closed_manifold(expect_mesh(dir, {"double.vdb", "-o", "m.obj"}, "m.obj"));
    }
}

TEST_CASE("grids without a surface: empty, no sign change, isovalue outside the range", "[cli][robust]") {
    ScratchDir dir("no_surface");
    RunResult r;
    SECTION("an empty grid") {
        auto g = openvdb::FloatGrid::create(3.0f);
        g->setName("nothing");
        write_vdb(dir.path("empty_grid.vdb"), {g});
        const pqdc::Mesh m = expect_mesh(dir, {"empty_grid.vdb", "-o", "m.obj"}, "m.obj", &r);
        CHECK(m.face_count() == 0);
        CHECK(contains(r.err, "warning: no surface in grid 'nothing'"));
        CHECK(contains(r.err, "no active voxels or tiles"));
    }
    SECTION("active values that never change sign") {
        auto g = openvdb::FloatGrid::create(3.0f);
        g->setName("positive");
        g->tree().fill(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(9)), 1.5f, true);
        g->tree().setValue(openvdb::Coord(4), 2.0f);
        write_vdb(dir.path("positive.vdb"), {g});
        const pqdc::Mesh m = expect_mesh(dir, {"positive.vdb", "-o", "m.ply"}, "m.ply", &r);
        CHECK(m.face_count() == 0);
        CHECK(contains(r.err, "active values lie in [1.5, 2]"));
        CHECK(contains(r.err, "isovalue 0 is outside"));
        CHECK(contains(r.err, "--isovalue"));
    }
    SECTION("a mask of one active value at that value: the level suggested lies towards the background") {
        auto g = openvdb::FloatGrid::create(0.0f);
        g->setName("mask");
        g->tree().fill(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(9)), 1.0f, true);
        write_vdb(dir.path("mask.vdb"), {g});
        const pqdc::Mesh m = expect_mesh(dir, {"mask.vdb", "--isovalue", "1", "-o", "m.ply"}, "m.ply", &r);
        CHECK(m.face_count() == 0);
        CHECK(contains(r.err, "the isovalue is the smallest value"));
        // It suggested "e.g. --isovalue 1", the isovalue given.
        CHECK(contains(r.err, "between two of its values or the background, e.g. --isovalue 0.5"));
    }
    SECTION("an isovalue outside the value range") {
        write_vdb(dir.path("sphere.vdb"), {sphere(6.0)});
        const pqdc::Mesh m = expect_mesh(dir, {"sphere.vdb", "--isovalue", "100", "-o", "m.obj"}, "m.obj", &r);
        CHECK(m.face_count() == 0);
        CHECK(contains(r.err, "the isovalue 100 is outside that range"));
        CHECK(contains(r.err, "choose --isovalue inside it"));
    }
}

TEST_CASE("a grid made only of active tiles meshes closed", "[cli][robust]") {
    ScratchDir dir("tiles");
    auto g = openvdb::FloatGrid::create(1.0f);
    g->setName("block");
    // 16^3 voxels at tile granularity: stored as active tiles, no leaf at all.
    g->tree().fill(openvdb::CoordBBox(openvdb::Coord(-8), openvdb::Coord(7)), -1.0f, true);
    REQUIRE(g->tree().leafCount() == 0);
    REQUIRE(g->tree().activeTileCount() > 0);
    write_vdb(dir.path("tiles.vdb"), {g});
    const pqdc::Mesh m = expect_mesh(dir, {"tiles.vdb", "-o", "m.ply"}, "m.ply");
    check_closed_manifold(m);
    // The surface lies half way between the last inside and the first outside
    // voxel (a cube of half-size 8 around -0.5); each vertex stays in its cell.
    for (const auto& p : m.points) {
        const double d = std::max({std::abs(p.x() + 0.5), std::abs(p.y() + 0.5), std::abs(p.z() + 0.5)});
        CHECK(std::abs(d - 8.0) < 0.5);
    }
}

TEST_CASE("NaN, Inf, denormal and huge voxel values", "[cli][robust]") {
    ScratchDir dir("values");
    const auto base = sphere(6.0, 1.0, Vec3d(0.0));
    write_vdb(dir.path("base.vdb"), {base});
    const pqdc::Mesh ref = expect_mesh(dir, {"base.vdb", "--quads", "-o", "ref.ply"}, "ref.ply");
    check_closed_manifold(ref);

    SECTION("NaN voxels make holes, reported, never NaN vertices") {
        auto g = base->deepCopy();
        int candidates = 0, n = 0;
        for (auto it = g->tree().beginValueOn(); it; ++it)
            if (std::abs(*it) < 0.5f && (++candidates % 7) == 0) {
                it.setValue(std::numeric_limits<float>::quiet_NaN());
                ++n;
            }
        write_vdb(dir.path("nan.vdb"), {g});
        RunResult r;
        const pqdc::Mesh m = expect_mesh(dir, {"nan.vdb", "-o", "m.ply"}, "m.ply", &r);
        CHECK(contains(r.err, std::to_string(n) + " NaN/Inf voxels skipped"));
        const pqdc::TopologyReport t = pqdc::measure_topology(m);
        CHECK(t.non_finite_point_count == 0);
        CHECK(t.edge_manifold());
        CHECK(t.consistently_oriented());
        CHECK(t.boundary_edge_count > 0);
    }
    SECTION("infinite voxels keep their sign") {
        auto g = base->deepCopy();
        for (auto it = g->tree().beginValueOn(); it; ++it)
            if (std::abs(*it) > 1.5f) it.setValue(*it > 0 ? std::numeric_limits<float>::infinity()
                                                          : -std::numeric_limits<float>::infinity());
        write_vdb(dir.path("inf.vdb"), {g});
        const pqdc::Mesh m = expect_mesh(dir, {"inf.vdb", "-o", "m.ply"}, "m.ply");
        check_closed_manifold(m);
        for (const auto& p : m.points) CHECK(std::abs(p.length() - 6.0) < 0.5);
    }
    SECTION("huge values scale away: same mesh in cell units") {
        for (const float scale : {1e-30f, 1e30f, 1e37f}) {
            INFO("values scaled by " << scale);
            auto g = base->deepCopy();
            for (auto it = g->tree().beginValueAll(); it; ++it) it.setValue(*it * scale);
            g->tree().root().setBackground(base->background() * scale, false);
            write_vdb(dir.path("scaled.vdb"), {g});
            const pqdc::Mesh m = expect_mesh(dir, {"scaled.vdb", "--quads", "-o", "m.ply"}, "m.ply");
            check_closed_manifold(m);
            REQUIRE(m.points.size() == ref.points.size());
            CHECK(m.quads == ref.quads);
            double worst = 0;
            for (std::size_t i = 0; i < m.points.size(); ++i)
                worst = std::max(worst, (m.points[i] - ref.points[i]).length());
            CHECK(worst < 1e-4);
        }
    }
    SECTION("denormal values: few mantissa bits, values near zero flush to 0, still a sane surface") {
        auto g = base->deepCopy();
        for (auto it = g->tree().beginValueAll(); it; ++it) it.setValue(*it * 1e-41f);
        g->tree().root().setBackground(base->background() * 1e-41f, false);
        REQUIRE(std::fpclassify(g->background()) == FP_SUBNORMAL);
        write_vdb(dir.path("denormal.vdb"), {g});
        const pqdc::Mesh m = expect_mesh(dir, {"denormal.vdb", "-o", "m.ply"}, "m.ply");
        check_closed_manifold(m);
        for (const auto& p : m.points) CHECK(std::abs(p.length() - 6.0) < 0.5);
    }
    SECTION("huge double values near the overflow limit") {
        auto d = openvdb::tools::createLevelSetSphere<openvdb::DoubleGrid>(6.0, openvdb::Vec3f(0.0f), 1.0, 3.0);
        for (auto it = d->tree().beginValueAll(); it; ++it) it.setValue(*it * 1e307);
        d->tree().root().setBackground(3e307, false);
        write_vdb(dir.path("huge.vdb"), {d});
        RunResult r;
        const pqdc::Mesh m = expect_mesh(dir, {"huge.vdb", "-o", "m.ply"}, "m.ply", &r);
        check_closed_manifold(m);
        for (const auto& p : m.points) CHECK(std::abs(p.length() - 6.0) < 0.1);
        // The gradients' squared lengths overflow: their directions were
        // dropped as zero ("654 zero-gradient crossings", mass points).
        CHECK_FALSE(contains(r.err, "zero-gradient"));
        // Adaptive mode took the overflowing gradient lengths for infinite,
        // every distance for 0, and collapsed the octree to a cube (34 vertices).
        const pqdc::Mesh a = expect_mesh(dir, {"huge.vdb", "--adaptive", "-o", "a.ply"}, "a.ply");
        check_closed_manifold(a);
        CHECK(a.points.size() > 100);
        for (const auto& p : a.points) CHECK(std::abs(p.length() - 6.0) < 0.3);
    }
}

// ------------------------------------------------------------- transforms

TEST_CASE("non-affine transforms are refused naming file and grid, affine ones are meshed", "[cli][robust]") {
    ScratchDir dir("transforms");
    auto with = [](openvdb::math::Transform::Ptr xf, const std::string& name) {
        auto g = sphere(6.0);
        g->setTransform(xf);
        g->setName(name);
        return g;
    };
    auto stretched = openvdb::math::Transform::createLinearTransform(1.0);
    stretched->preScale(Vec3d(1.0, 2.0, 1.0));
    openvdb::Mat4d shear = openvdb::Mat4d::identity();
    shear(1, 0) = 0.4;
    const auto frustum = openvdb::math::Transform::createFrustumTransform(
        openvdb::BBoxd(Vec3d(-10.0), Vec3d(10.0)), 0.5, 2.0, 1.0);
    write_vdb(dir.path("stretched.vdb"), {with(stretched, "squashed")});
    write_vdb(dir.path("sheared.vdb"), {with(openvdb::math::Transform::createLinearTransform(shear), "leaning")});
    write_vdb(dir.path("frustum.vdb"), {with(frustum, "camera")});
    expect_failure(dir, {"frustum.vdb", "-o", "out.obj"}, 1,
                   {"'frustum.vdb'", "grid 'camera'", "not affine", "resample"});

    SECTION("non-uniform scale and shear are meshed; the log gives every voxel edge") {
        RunResult r;
        const pqdc::Mesh m = expect_mesh(dir, {"stretched.vdb", "-o", "m.ply"}, "m.ply", &r);
        check_closed_manifold(m);
        CHECK(contains(r.err, "voxel size 1 x 2 x 1"));
        check_closed_manifold(expect_mesh(dir, {"sheared.vdb", "-o", "s.ply"}, "s.ply"));
    }

    SECTION("rotation, mirror and uniform scale are fine") {
        openvdb::Mat4d m = openvdb::Mat4d::identity();
        m.setToRotation(Vec3d(1, 2, 3).unit(), 0.7);
        m.preScale(Vec3d(0.5, 0.5, -0.5));  // mirrored
        m.setTranslation(Vec3d(10, -20, 30));
        write_vdb(dir.path("rotated.vdb"), {with(openvdb::math::Transform::createLinearTransform(m), "turned")});
        const pqdc::Mesh mesh = expect_mesh(dir, {"rotated.vdb", "-o", "m.ply"}, "m.ply");
        check_closed_manifold(mesh);
        // Outward winding: positive enclosed volume even through the mirror.
        double volume = 0;
        for (const auto& t : mesh.triangles)
            volume += mesh.points[t[0]].dot(mesh.points[t[1]].cross(mesh.points[t[2]])) / 6.0;
        CHECK(volume > 0);
    }
}

TEST_CASE("voxel sizes from OpenVDB's smallest to 1e6 and far origins stay accurate in cell units", "[cli][robust]") {
    ScratchDir dir("voxel_sizes");
    const auto unit = sphere(7.0, 1.0, Vec3d(0.0));
    write_vdb(dir.path("unit.vdb"), {unit});
    // Double-precision PLY: float coordinates could not hold 1e12 origins to 1e-6 voxel.
    const pqdc::Mesh ref = expect_mesh(dir, {"unit.vdb", "--quads", "--precision", "double", "-o", "ref.ply"}, "ref.ply");
    // OpenVDB 10 refuses to build a map whose scale is below ~1.5e-5 ("Non-zero
    // scale values required"); 2e-5 is the smallest round value it accepts.
    CHECK_THROWS(openvdb::math::Transform::createLinearTransform(1e-6));
    for (const auto& [voxel, origin] : std::vector<std::pair<double, Vec3d>>{
             {2e-5, Vec3d(0.0)}, {2e-5, Vec3d(3.0, -4.0, 5.0)}, {1e6, Vec3d(0.0)}, {1e6, Vec3d(1e12, -1e12, 3e11)},
             {1e-3, Vec3d(1e6, 1e6, -1e6)}}) {
        INFO("voxel " << voxel << " origin " << origin);
        auto g = unit->deepCopy();
        auto xf = openvdb::math::Transform::createLinearTransform(voxel);
        xf->postTranslate(origin);
        g->setTransform(xf);
        write_vdb(dir.path("moved.vdb"), {g});
        const pqdc::Mesh m = expect_mesh(dir, {"moved.vdb", "--quads", "--precision", "double", "-o", "m.ply"}, "m.ply");
        REQUIRE(m.points.size() == ref.points.size());
        CHECK(m.quads == ref.quads);
        double worst = 0;
        for (std::size_t i = 0; i < m.points.size(); ++i)
            worst = std::max(worst, (xf->worldToIndex(m.points[i]) - ref.points[i]).length());
        CHECK(worst < 1e-6);
    }

    SECTION("a file carrying a voxel size OpenVDB cannot invert is refused clearly") {
        // Write 1e-4 and patch every copy of that double in the map to 1e-6:
        // files from other writers can carry transforms OpenVDB would not build.
        auto g = unit->deepCopy();
        g->setTransform(openvdb::math::Transform::createLinearTransform(1e-4));
        g->setName("microns");
        write_vdb(dir.path("tiny.vdb"), {g});
        std::string bytes = pqdc_test::read_file(dir.path("tiny.vdb"));
        const double from = 1e-4, to = 1e-6;
        const std::string a(reinterpret_cast<const char*>(&from), 8), b(reinterpret_cast<const char*>(&to), 8);
        int patched = 0;
        for (std::size_t at = bytes.find(a); at != std::string::npos; at = bytes.find(a, at + 8), ++patched)
            bytes.replace(at, 8, b);
        REQUIRE(patched > 0);
        pqdc_test::write_file(dir.path("tiny.vdb"), bytes);
        expect_failure(dir, {"tiny.vdb", "-o", "out.obj"}, 1,
                       {"grid 'microns' in 'tiny.vdb'", "cannot invert", "1e-06", "larger units"});
    }
}

TEST_CASE("far from the origin in float, both modes say to store double precision", "[cli][robust]") {
    // A voxel of 1e-3 at 1e6: float's spacing there is about 60 voxels. The
    // adaptive run used to fall back to the uniform mesh with "please report
    // the input" and without the uniform run's own advice.
    ScratchDir dir("far_float");
    auto g = sphere(7.0, 1.0, Vec3d(0.0));
    auto xf = openvdb::math::Transform::createLinearTransform(1e-3);
    xf->postTranslate(Vec3d(1e6, 1e6, 1e6));
    g->setTransform(xf);
    write_vdb(dir.path("far.vdb"), {g});
    for (const char* mode : {"--threads", "--adaptive"}) {
        INFO(mode);
        std::vector<std::string> args{"far.vdb", "-o", "far.ply", mode};
        if (std::string(mode) == "--threads") args.push_back("2");
        RunResult r;
        expect_mesh(dir, args, "far.ply", &r);
        CHECK(contains(r.err, "store it in double precision (--precision double)"));
        CHECK_FALSE(contains(r.err, "please report"));
    }
}

// --------------------------------------------------- surfaces at the edge

TEST_CASE("surfaces touching the active region or the narrow band: open there, no garbage", "[cli][robust]") {
    ScratchDir dir("boundary");
    const double r = 8.0;
    SECTION("a narrow band one voxel wide still meshes closed and accurate") {
        // Only |d| < 1 stays active; everything else becomes +-background (inactive), as
        // after pruning a band down to its minimum.
        auto g = sphere(r, 1.0, Vec3d(0.0));
        const float bg = g->background();
        for (auto it = g->tree().beginValueOn(); it; ++it)
            if (std::abs(*it) >= 1.0f) {
                it.setValue(*it < 0 ? -bg : bg);
                it.setValueOff();
            }
        write_vdb(dir.path("thin.vdb"), {g});
        const pqdc::Mesh m = expect_mesh(dir, {"thin.vdb", "-o", "m.ply"}, "m.ply");
        check_closed_manifold(m);
        for (const auto& p : m.points) CHECK(std::abs(p.length() - r) < 0.1);
    }
    SECTION("a surface leaving the active region is open at the cut only") {
        auto g = sphere(r, 1.0, Vec3d(0.0));
        for (auto it = g->tree().beginValueOn(); it; ++it)
            if (it.getCoord().z() > 3) it.setValueOff();  // values stay: only the domain shrinks
        write_vdb(dir.path("cut.vdb"), {g});
        RunResult run;
        const pqdc::Mesh m = expect_mesh(dir, {"cut.vdb", "-o", "m.ply"}, "m.ply", &run);
        CHECK(contains(run.err, "open where the surface leaves the active region"));
        const pqdc::TopologyReport t = pqdc::measure_topology(m);
        CHECK(t.boundary_edge_count > 0);
        CHECK(t.edge_manifold());
        CHECK(t.consistently_oriented());
        CHECK(t.non_finite_point_count == 0);
        CHECK(t.degenerate_face_count == 0);
        std::map<std::pair<unsigned, unsigned>, int> edges;
        for (const auto& tr : m.triangles)
            for (int i = 0; i < 3; ++i) {
                const unsigned a = tr[i], b = tr[(i + 1) % 3];
                ++edges[{std::min(a, b), std::max(a, b)}];
            }
        for (const auto& [e, n] : edges)
            if (n == 1) {
                // Cells with an active corner reach z = 4; the rim lies in the last of them.
                CHECK(m.points[e.first].z() > 3.0);
                CHECK(m.points[e.second].z() > 3.0);
            }
        for (const auto& p : m.points) {
            CHECK(p.z() < 4.0 + 1e-9);
            CHECK(std::abs(p.length() - r) < 0.1);  // no garbage: every vertex on the sphere
        }
    }
}

// ----------------------------------------------------------------- output

TEST_CASE("unwritable, missing and odd output paths fail before any work", "[cli][robust]") {
    ScratchDir dir("outputs", pqdc_test::ScratchLocation::world_reachable);  // a section runs as nobody
    write_vdb(dir.path("in.vdb"), {sphere(6.0)});
    expect_failure(dir, {"in.vdb", "-o", "missing/out.obj"}, 1,
                   {"'missing/out.obj'", "-o", "directory 'missing' does not exist", "create it"});
    expect_failure(dir, {"in.vdb", "-o", "in.vdb/out.obj"}, 1, {"'in.vdb/out.obj'", "not a directory"});
    std::filesystem::create_directory(dir.path("taken.obj"));
    expect_failure(dir, {"in.vdb", "-o", "taken.obj"}, 1, {"'taken.obj'", "is a directory"});
    expect_failure(dir, {"in.vdb", "-o", "out.obj", "--stats", "missing/s.json"}, 1,
                   {"'missing/s.json'", "--stats", "does not exist"});
    expect_failure(dir, {"in.vdb", "-o", "out.vdb"}, 2, {"'out.vdb'", ".obj, .ply, .off or .stl"}, {}, "out.vdb");
    expect_failure(dir, {"in.vdb", "-o", "out"}, 2, {"'out'", ".obj, .ply, .off or .stl"}, {}, "out");

    SECTION("a directory without write permission") {
        std::filesystem::create_directory(dir.path("locked"));
        std::filesystem::permissions(dir.path("locked"), std::filesystem::perms::owner_read |
                                                             std::filesystem::perms::owner_exec |
                                                             std::filesystem::perms::others_read |
                                                             std::filesystem::perms::others_exec);
        RunSpec spec;
        spec.as_nobody = true;  // root ignores permissions
        std::filesystem::permissions(dir.path("in.vdb"), std::filesystem::perms::all);
        const RunResult r = pqdc_in(dir, {"in.vdb", "-o", "locked/out.obj"}, spec);
        record_transcript({"in.vdb", "-o", "locked/out.obj"}, r);
        INFO(describe({"locked/out.obj"}, r));
        CHECK(r.exit_code == 1);
        CHECK(contains(r.err, "'locked/out.obj'"));
        CHECK(contains(r.err, "cannot create files in 'locked'"));
        CHECK(std::filesystem::is_empty(dir.path("locked")));
        std::filesystem::permissions(dir.path("locked"), std::filesystem::perms::owner_all);
    }
}

namespace {

/// A mounted 64 KiB tmpfs, or nothing when mounting is not permitted.
struct SmallTmpfs {
    std::string dir;
    bool mounted = false;
    explicit SmallTmpfs(const std::string& d) : dir(d) {
        std::filesystem::create_directories(dir);
        mounted = ::mount("tmpfs", dir.c_str(), "tmpfs", 0, "size=64k") == 0;
    }
    ~SmallTmpfs() {
        if (mounted) ::umount2(dir.c_str(), MNT_DETACH);
    }
};

}  // namespace

TEST_CASE("a write that fails midway (disk full, file size limit) leaves the old output intact", "[cli][robust]") {
    ScratchDir dir("disk_full");
    write_vdb(dir.path("in.vdb"), {sphere(12.0)});  // an OBJ of ~180 KiB

    SECTION("file size limit: write() fails with EFBIG, SIGXFSZ ignored") {
        RunSpec spec;
        spec.file_size_limit_bytes = 32 << 10;
        for (const std::string out : {"out.obj", "out.ply", "out.stl"})
            expect_failure(dir, {"in.vdb", "-o", out}, 1, {"cannot write '" + out + "'", "File too large"}, spec, out);
        // The sampled volume of --write-volume goes through the same kind of writer.
        expect_failure(dir, {"--procedural", "sphere", "--resolution", "64", "--write-volume", "v.vdb"}, 1,
                       {"cannot write 'v.vdb'", "File too large"}, spec, "v.vdb");
        // Out of core the mesh waits in scratch files first: they are named,
        // with their size (the output alone seemed to fit).
        expect_failure(dir, {"in.vdb", "--out-of-core", "-o", "out.ply"}, 1,
                       {"cannot write the scratch files next to 'out.ply'", "File too large", "40 bytes a vertex"},
                       spec, "out.ply");
    }
    SECTION("a full 64 KiB tmpfs") {
        SmallTmpfs fs(dir.path("small"));
        if (!fs.mounted) {
            WARN("cannot mount a tmpfs here (not root?); the file size limit section covers write failures");
        } else {
            pqdc_test::write_file(fs.dir + "/out.obj", kSentinel);
            const RunResult r = pqdc_in(dir, {"in.vdb", "-o", "small/out.obj"});
            record_transcript({"in.vdb", "-o", "small/out.obj"}, r);
            INFO(describe({"small/out.obj"}, r));
            CHECK(r.exit_code == 1);
            CHECK(contains(r.err, "cannot write 'small/out.obj'"));
            CHECK(contains(r.err, "No space left on device"));
            CHECK(pqdc_test::read_file(fs.dir + "/out.obj") == kSentinel);
            std::vector<std::string> left;
            for (const auto& e : std::filesystem::directory_iterator(fs.dir)) left.push_back(e.path().filename());
            CHECK(left == std::vector<std::string>{"out.obj"});
        }
    }
}

TEST_CASE("SIGINT or SIGTERM during a long run leaves no output and no temporary file", "[cli][robust]") {
    // Figure 3 at 512^3 samples and meshes for many seconds; the signal comes
    // while the field is being sampled, which has no cancellation point.
    ScratchDir dir("interrupt");
    for (const auto& [sig, code] : {std::pair<int, int>{SIGINT, 130}, {SIGTERM, 143}}) {
        INFO("signal " << sig);
        RunSpec spec;
        spec.signal_after_seconds = 0.5;
        spec.signal = sig;
        // big.obj holds a previous result; big.json must not appear.
        expect_failure(dir, {"--procedural", "figure3", "--resolution", "512", "-o", "big.obj", "--stats", "big.json"},
                       code, {"interrupted; no output written"}, spec, "big.obj");
    }
}

// ---------------------------------------------------------------- options

TEST_CASE("sharp grid gradients (--gradient sharp) mesh a grid and are recorded in --stats", "[cli]") {
    ScratchDir dir("normals");
    write_vdb(dir.path("in.vdb"), {sphere(6.0)});
    const pqdc::Mesh m = expect_mesh(dir, {"in.vdb", "--gradient", "sharp", "-o", "m.ply", "--stats", "s.json"}, "m.ply");
    check_closed_manifold(m);
    CHECK(contains(pqdc_test::read_file(dir.path("s.json")), "\"gradient\": \"sharp\""));
}

TEST_CASE("bad and conflicting options are usage errors naming the option", "[cli][robust]") {
    ScratchDir dir("options");
    write_vdb(dir.path("in.vdb"), {sphere(6.0)});
    const std::vector<std::pair<std::vector<std::string>, std::vector<std::string>>> cases = {
        {{}, {"no input", "--help"}},
        {{"in.vdb"}, {"no output", "-o"}},
        {{"in.vdb", "-o"}, {"-o needs a value"}},
        {{"in.vdb", "-o", "--quads"}, {"-o needs a value", "'--quads'"}},
        {{"in.vdb", "--frobnicate", "-o", "out.obj"}, {"unknown option '--frobnicate'", "--help"}},
        {{"in.vdb", "other.vdb", "-o", "out.obj"}, {"more than one input", "'other.vdb'"}},
        {{"in.vdb", "--procedural", "sphere", "-o", "out.obj"}, {"either an input file ('in.vdb') or --procedural"}},
        {{"in.vdb", "-o", "out.obj", "--sigma-n", "-0.5"}, {"--sigma-n must be auto or >= 0", "-0.5"}},
        {{"in.vdb", "-o", "out.obj", "--sigma-n", "nan"}, {"--sigma-n expects a number, got 'nan'"}},
        {{"in.vdb", "-o", "out.obj", "--sigma-n", "0.1x"}, {"--sigma-n expects a number"}},
        {{"in.vdb", "-o", "out.obj", "--sigma-n", ""}, {"--sigma-n expects a number"}},
        {{"in.vdb", "-o", "out.obj", "--isovalue", "inf"}, {"--isovalue expects a finite number"}},
        {{"in.vdb", "-o", "out.obj", "--isovalue", "1e999"}, {"--isovalue expects a finite number"}},
        {{"in.vdb", "-o", "out.obj", "--pseudo-inverse-cutoff", "1"}, {"--pseudo-inverse-cutoff must be in [0, 1)"}},
        {{"in.vdb", "-o", "out.obj", "--pseudo-inverse-cutoff", "0.1"}, {"applies with --sigma-n 0"}},
        {{"in.vdb", "-o", "out.obj", "--sigma-n", "0.1", "--pseudo-inverse-cutoff", "0.1"}, {"applies with --sigma-n 0"}},
        {{"in.vdb", "-o", "out.obj", "--interior", "inside"}, {"--interior expects auto, below or above"}},
        {{"in.vdb", "-o", "out.obj", "--containment", "loose"}, {"--containment expects clamp or none"}},
        {{"in.vdb", "-o", "out.obj", "--gradient", "eno"}, {"--gradient expects auto, central, sharp or least-squares"}},
        {{"in.vdb", "-o", "out.obj", "--normals", "sharp"}, {"--normals was renamed", "--gradient", "--vertex-normals"}},
        {{"in.vdb", "-o", "out.obj", "--normals"}, {"--normals was renamed", "--gradient", "--vertex-normals"}},
        {{"--procedural", "box", "-o", "out.obj", "--gradient", "sharp"}, {"--gradient applies to .vdb input"}},
        {{"in.vdb", "-o", "-"}, {"-o -", "--format"}},
        {{"in.vdb", "-o", "out.obj", "--format", "xyz"}, {"--format expects obj, ply, off or stl", "'xyz'"}},
        {{"in.vdb", "-o", "out.obj", "--precision", "half"}, {"--precision expects float or double"}},
        {{"in.vdb", "-o", "out.off", "--vertex-normals"}, {"--vertex-normals: OFF holds no vertex normals", ".ply or .obj"}},
        {{"in.vdb", "-o", "out.mesh", "--format", "stl", "--vertex-normals"}, {"--vertex-normals: STL holds no vertex normals"}},
        {{"in.vdb", "-o", "out.obj", "--format", "stl"}, {"the extension of -o 'out.obj' says OBJ but --format says STL"}},
        {{"in.vdb", "-o", "out.obj", "--grid", "a,,b"}, {"--grid needs grid names separated by commas"}},
        {{"in.vdb", "-o", "out.obj", "--quads", "--decimate", "--target-ratio", "0.5"}, {"--decimate writes triangles", "drop --quads"}},
        {{"in.vdb", "-o", "out.obj", "--grid", "a,b"}, {"-o 'out.obj' needs {grid}"}},
        {{"in.vdb", "-o", "out_{grid}.obj", "--grid", "*", "--stats", "s.json"}, {"--stats 's.json' needs {grid}"}},
        {{"in.vdb", "-o", "d{grid}/out.obj"}, {"{grid} may appear in the file name only"}},
        {{"in.vdb", "-o", "-", "--format", "ply", "--grid", "*"}, {"-o - holds one mesh"}},
        {{"in.vdb", "-o", "out.obj", "--stats", "-"}, {"only -o accepts -"}},
        {{"in.vdb", "-o", "out.obj", "--sigma-n"}, {"--sigma-n needs a value"}},
        {{"in.vdb", "-o", "out.obj", "--adaptive", "--max-error", "-1"}, {"--max-error", ">= 0"}},
        {{"in.vdb", "-o", "out.obj", "--threads", "0"}, {"--threads must be between 1 and 4096"}},
        {{"in.vdb", "-o", "out.obj", "--threads", "two"}, {"--threads expects a whole number"}},
        {{"in.vdb", "-o", "out.obj", "--memory-limit", "0"}, {"--memory-limit must be between 1"}},
        {{"in.vdb", "-o", "out.obj", "--memory-limit", "99999999999999999999"}, {"--memory-limit expects a whole number"}},
        {{"in.vdb", "-o", "out.obj", "--resolution", "64"}, {"--resolution applies to --procedural"}},
        {{"in.vdb", "-o", "out.obj", "--active-band", "4"}, {"--active-band applies to --procedural"}},
        {{"--procedural", "box", "-o", "out.obj", "--active-band", "-1"}, {"--active-band must be >= 0"}},
        {{"--procedural", "box", "-o", "out.obj", "--active-band", "wide"}, {"--active-band expects a number"}},
        {{"in.vdb", "-o", "out.obj", "--write-volume", "v.vdb"}, {"--write-volume", "needs --procedural"}},
        {{"in.vdb", "--stats", "s.json"}, {"--stats", "needs -o"}},
        {{"in.vdb", "-o", "out.obj", "--stats", "out.obj"}, {"--stats 'out.obj' is the same file as -o"}},
        {{"in.vdb", "-o", "out.obj", "--stats", "./in.vdb"}, {"is the same file as the input"}},
        {{"--procedural", "torus", "-o", "out.obj"}, {"unknown procedural field 'torus'", "sphere, box, figure3"}},
        {{"--procedural", "sphere", "--resolution", "3", "-o", "out.obj"}, {"--resolution must be between 4"}},
        {{"--procedural", "sphere", "--grid", "g", "-o", "out.obj"}, {"--grid, --isovalue and --interior"}},
        {{"--procedural", "sphere", "--isovalue", "0", "-o", "out.obj"}, {"apply to .vdb input"}},
        {{"--procedural", "sphere", "--seed", "3", "-o", "out.obj"}, {"figure3 only"}},
        {{"--procedural", "figure3", "--noise-amplitude", "-1", "-o", "out.obj"}, {"--noise-amplitude must be >= 0"}},
        {{"--procedural", "figure3", "--noise-frequency", "0", "-o", "out.obj"}, {"--noise-frequency must be > 0"}},
        {{"--procedural", "figure3", "--octaves", "17", "-o", "out.obj"}, {"--octaves must be between 1 and 16"}},
        {{"--procedural", "sphere", "--write-volume", "v.obj"}, {"--write-volume", "ending in .vdb"}},
        {{"--procedural", "sphere", "--write-volume", "v.vdb", "-o", "v.vdb"}, {".obj, .ply, .off or .stl"}},
    };
    for (const auto& [args, needles] : cases) expect_failure(dir, args, 2, needles);

    SECTION("--help and --version succeed") {
        for (const std::string flag : {"--help", "--version"}) {
            const RunResult r = pqdc_in(dir, {flag});
            CHECK(r.exit_code == 0);
            CHECK(contains(r.out, flag == "--help" ? "usage: pqdc" : "OpenVDB"));
            // Only pqdc's own usage lines: not CLI11's "Usage: pqdc [OPTIONS] [input...]".
            if (flag == "--help") CHECK_FALSE(contains(r.out, "[OPTIONS]"));
        }
    }
}

// ----------------------------------------------------------------- limits

TEST_CASE("a job over the memory limit fails early with a clear message", "[cli][robust]") {
    ScratchDir dir("memory");
    const RunResult p = expect_failure(dir, {"--procedural", "figure3", "--resolution", "128", "--memory-limit", "1",
                                             "-o", "out.obj"},
                                       1, {"MiB", "more than the 1 MiB allowed", "--memory-limit"});
    // In the command's names, not the library's (it said "options.region: a box or a mask").
    CHECK(contains(p.err, "(--bbox or --mask)"));
    CHECK(contains(p.err, "raise --memory-limit MIB"));
    CHECK_FALSE(contains(p.err, "options."));
    // --write-volume's sampling too, before anything is sampled or written.
    expect_failure(dir, {"--procedural", "figure3", "--resolution", "128", "--memory-limit", "1", "--write-volume",
                         "v.vdb"},
                   1, {"more than the 1 MiB allowed", "--memory-limit"}, {}, "v.vdb");
    write_vdb(dir.path("in.vdb"), {sphere(30.0)});
    // Reading or meshing, whichever hits the limit first, must say so.
    const RunResult r = expect_failure(dir, {"in.vdb", "--memory-limit", "1", "-o", "out.obj"}, 1, {"MiB"});
    CHECK(contains(r.err, "--memory-limit"));
}

TEST_CASE("pqdc --write-volume writes what the mesh is made from: with --bbox only the part around it", "[cli][procedural]") {
    ScratchDir dir("write_volume_region");
    const std::vector<std::string> sphere_run{"--procedural", "sphere", "--resolution", "256", "-q"};
    auto with = [&](std::vector<std::string> extra) {
        extra.insert(extra.begin(), sphere_run.begin(), sphere_run.end());
        return extra;
    };
    REQUIRE(pqdc_in(dir, with({"--write-volume", "whole.vdb"})).exit_code == 0);
    REQUIRE(pqdc_in(dir, with({"--bbox", "0.5,0.5,0.5,2,2,2", "--write-volume", "part.vdb"})).exit_code == 0);
    auto read = [&](const std::string& name) {
        openvdb::io::File file(dir.path(name));
        file.open();
        const auto grid = openvdb::gridPtrCast<openvdb::FloatGrid>(file.readGrid(file.beginName().gridName()));
        file.close();
        REQUIRE(grid);
        return grid;
    };
    const auto whole = read("whole.vdb"), part = read("part.vdb");
    CHECK(part->activeVoxelCount() > 0);
    CHECK(part->activeVoxelCount() < whole->activeVoxelCount() / 4);
    // The same samples where the part has any.
    const auto whole_values = whole->getConstAccessor();
    std::size_t compared = 0;
    for (auto leaf = part->tree().cbeginLeaf(); leaf; ++leaf) {
        const openvdb::FloatTree::LeafNodeType* same = whole->tree().probeConstLeaf(leaf->origin());
        REQUIRE(same != nullptr);
        for (auto v = leaf->cbeginValueAll(); v; ++v) REQUIRE(same->getValue(v.pos()) == *v);
        ++compared;
    }
    CHECK(compared > 10);
}

// ------------------------------------------------------------ pqdc-measure

#ifdef PQDC_MEASURE_PATH
TEST_CASE("pqdc-measure --against-mesh: distances to a reference mesh, bad references", "[cli][measure]") {
    ScratchDir dir("measure_against_mesh");
    pqdc::Mesh cube;
    for (int i = 0; i < 8; ++i) cube.points.emplace_back(i & 1 ? 1 : -1, i & 2 ? 1 : -1, i & 4 ? 1 : -1);
    cube.quads = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
    pqdc::Mesh outer = cube;
    for (Vec3d& p : outer.points) p *= 1.5;
    pqdc::write_mesh(cube, dir.path("cube.obj"));
    pqdc::write_mesh(outer, dir.path("outer.ply"));
    auto measure = [&](std::vector<std::string> args) {
        RunSpec spec;
        spec.args = std::move(args);
        spec.cwd = dir.dir();
        return pqdc_test::run_program(PQDC_MEASURE_PATH, spec);
    };

    const RunResult ok = measure({"outer.ply", "--against-mesh", "cube.obj"});
    INFO("stderr: " << ok.err << "\nstdout: " << ok.out);
    REQUIRE(ok.exit_code == 0);
    CHECK(ok.err.empty());
    const auto json = nlohmann::json::parse(ok.out);
    const auto& ref = json["reference_mesh"];
    CHECK(ref["path"] == "cube.obj");
    // Corners (1.5, 1.5, 1.5) are sqrt(0.75) from the cube's corner (1, 1, 1), outside.
    CHECK(ref["distance"]["sample_count"] == 8);
    CHECK(ref["distance"]["max"].get<double>() == Approx(std::sqrt(0.75)).epsilon(1e-15));
    CHECK(ref["distance"]["mean_signed"].get<double>() == Approx(std::sqrt(0.75)).epsilon(1e-15));
    CHECK(ref["distance"]["unreliable_count"] == 0);
    const auto& si = json["self_intersections"];
    CHECK(si["triangle_count"] == 12);
    CHECK(si["pair_count"] == 0);
    CHECK(si["degenerate_triangle_count"] == 0);
    CHECK(si["first_pairs"].empty());
    pqdc::Mesh crossed = cube;  // the cube and a copy turned 45 degrees about z cross along 16 sides
    for (const Vec3d& p : cube.points) crossed.points.emplace_back((p[0] - p[1]) / std::sqrt(2.0), (p[0] + p[1]) / std::sqrt(2.0), p[2]);
    for (const auto& q : cube.quads) crossed.quads.emplace_back(q[0] + 8, q[1] + 8, q[2] + 8, q[3] + 8);
    pqdc::write_mesh(crossed, dir.path("crossed.obj"));
    const RunResult x = measure({"crossed.obj"});
    REQUIRE(x.exit_code == 0);
    const auto crossed_json = nlohmann::json::parse(x.out);
    CHECK(crossed_json["self_intersections"]["triangle_count"] == 24);
    CHECK(crossed_json["self_intersections"]["pair_count"].get<int>() > 0);

    struct Bad {
        std::string file, content;
        std::vector<std::string> needles;
    };
    for (const Bad& bad : std::vector<Bad>{
             {"points.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n",
              {"--against-mesh 'points.obj'", "no triangles or quads (3 points)", "give it a surface"}},
             {"nan.obj", "v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n",
              {"--against-mesh 'nan.obj'", "point 1", "NaN or infinite", "fix the point"}},
         }) {
        pqdc_test::write_file(dir.path(bad.file), bad.content);
        const RunResult r = measure({"outer.ply", "--against-mesh", bad.file});
        INFO("reference " << bad.file << "; stderr: " << r.err);
        CHECK(r.exit_code == 1);
        CHECK(r.out.empty());  // no partial JSON
        for (const auto& n : bad.needles) {
            INFO("stderr should contain: " << n);
            CHECK(contains(r.err, n));
        }
    }
    const RunResult missing = measure({"outer.ply", "--against-mesh", "nowhere.obj"});
    CHECK(missing.exit_code == 1);
    CHECK(contains(missing.err, "'nowhere.obj'"));
    const RunResult no_value = measure({"outer.ply", "--against-mesh"});
    CHECK(no_value.exit_code == 2);
    CHECK(contains(no_value.err, "--against-mesh needs a value"));
}
#endif  // PQDC_MEASURE_PATH

#endif  // PQDC_CLI_PATH
