// The command-line conventions and files of issue 12: --opt=value, repeated
// options, stdout/stdin, vdb_print grid order, several grids, float PLY,
// vertex normals, STL for pqdc's own tools, --max-error inf, adaptive quad
// counts, JSON's rule for non-finite numbers, progress only when asked.
#include "cli_runner.hpp"
#include "mesh_checks.hpp"

#include "pqdc/measure.hpp"
#include "pqdc/mesh_io.hpp"

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>

#include <pty.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <regex>
#include <string>
#include <vector>

#ifdef PQDC_CLI_PATH

using openvdb::Vec3d;
using pqdc_test::RunResult;
using pqdc_test::RunSpec;
using pqdc_test::ScratchDir;

namespace {

struct Init {
    Init() { openvdb::initialize(); }
} init_openvdb;

RunResult run_in(const ScratchDir& dir, std::vector<std::string> args, const std::string& program = PQDC_CLI_PATH) {
    RunSpec spec;
    spec.args = std::move(args);
    spec.cwd = dir.dir();
    return pqdc_test::run_program(program, spec);
}

/// Runs a shell command line in dir (for pipes and redirections).
RunResult shell_in(const ScratchDir& dir, const std::string& command) {
    return run_in(dir, {"-c", command}, "/bin/sh");
}

openvdb::FloatGrid::Ptr sphere(const std::string& name, double radius, const Vec3d& center = Vec3d(0.3, -0.2, 0.1)) {
    auto g = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(float(radius), center, 1.0f, 3.0f);
    g->setName(name);
    return g;
}

bool contains(const std::string& s, const std::string& needle) { return s.find(needle) != std::string::npos; }

}  // namespace

TEST_CASE("each app's --help shows its own usage lines, not CLI11's generic one", "[cli][conventions]") {
    ScratchDir dir("help");
    std::vector<std::pair<std::string, std::string>> apps = {{PQDC_CLI_PATH, "usage: pqdc INPUT.vdb"}};
#ifdef PQDC_DECIMATE_PATH
    apps.emplace_back(PQDC_DECIMATE_PATH, "usage: pqdc-decimate INPUT.");
#endif
#ifdef PQDC_MEASURE_PATH
    apps.emplace_back(PQDC_MEASURE_PATH, "usage: pqdc-measure MESH.");
#endif
#ifdef PQDC_BRICKS_PATH
    apps.emplace_back(PQDC_BRICKS_PATH, "usage: pqdc-bricks split");
#endif
#ifdef PQDC_MESH_TO_VOLUME_PATH
    apps.emplace_back(PQDC_MESH_TO_VOLUME_PATH, "usage: pqdc-mesh-to-volume INPUT.");
#endif
    for (const auto& [program, usage] : apps) {
        CAPTURE(program);
        const RunResult r = run_in(dir, {"--help"}, program);
        CHECK(r.exit_code == 0);
        CHECK(contains(r.out, usage));
        // "Usage: NAME [OPTIONS] [inputs...]" suggested several inputs.
        CHECK_FALSE(contains(r.out, "[OPTIONS]"));
    }
}

TEST_CASE("options take --opt=value, the last value wins, --triangles and --quads by order", "[cli][conventions]") {
    ScratchDir dir("conventions_opts");
    openvdb::io::File(dir.path("in.vdb")).write({sphere("sdf", 6.0)});
    RunResult r = run_in(dir, {"in.vdb", "--sigma-n=0.2", "--output=a.obj", "-o", "b.obj", "--stats=s.json"});
    INFO(r.err);
    REQUIRE(r.exit_code == 0);
    CHECK(dir.entries() == std::vector<std::string>{"b.obj", "in.vdb", "s.json"});
    CHECK(nlohmann::json::parse(pqdc_test::read_file(dir.path("s.json")))["sigma_n"] == 0.2);
    r = run_in(dir, {"in.vdb", "--quads", "--triangles", "-o", "t.ply", "-q"});
    REQUIRE(r.exit_code == 0);
    const pqdc::Mesh t = pqdc::read_mesh(dir.path("t.ply"));
    CHECK(t.quads.empty());
    CHECK(!t.triangles.empty());
    // A flag's =false switches it off, --quads and --triangles too: they
    // wrote quads for --quads=false (and --quads=maybe).
    r = run_in(dir, {"in.vdb", "--quads=false", "-o", "f.ply", "-q"});
    REQUIRE(r.exit_code == 0);
    CHECK(pqdc::read_mesh(dir.path("f.ply")).quads.empty());
    r = run_in(dir, {"in.vdb", "--quads", "--triangles=0", "-o", "q.ply", "-q"});
    REQUIRE(r.exit_code == 0);
    CHECK(pqdc::read_mesh(dir.path("q.ply")).triangles.empty());
    r = run_in(dir, {"in.vdb", "--quads=maybe", "-o", "m.ply", "-q"});
    CHECK(r.exit_code == 2);
    CHECK(contains(r.err, "--quads"));
    CHECK(!std::filesystem::exists(dir.path("m.ply")));
    // An empty "=" value is refused (it took the next argument, "-o", as the
    // number); "--" ends the options, so a file may start with "-".
    r = run_in(dir, {"in.vdb", "--sigma-n=", "-o", "e.ply", "-q"});
    CHECK(r.exit_code == 2);
    CHECK(contains(r.err, "--sigma-n needs a value after '='"));
    std::filesystem::copy_file(dir.path("in.vdb"), dir.path("-dash.vdb"));
    r = run_in(dir, {"-o", "dash.ply", "-q", "--", "-dash.vdb"});
    CHECK(r.exit_code == 0);
    CHECK(std::filesystem::exists(dir.path("dash.ply")));
    std::filesystem::remove(dir.path("-dash.vdb"));
    std::filesystem::remove(dir.path("dash.ply"));
#ifdef PQDC_DECIMATE_PATH
    // The small apps' flags too: --quiet=false prints the summary.
    pqdc::write_mesh(t, dir.path("t.obj"));
    r = run_in(dir, {"t.obj", "-o", "d.obj", "--target-ratio", "0.5", "--quiet=false"}, PQDC_DECIMATE_PATH);
    REQUIRE(r.exit_code == 0);
    CHECK(!r.err.empty());
    r = run_in(dir, {"t.obj", "-o", "d.obj", "--target-ratio", "0.5", "--quiet"}, PQDC_DECIMATE_PATH);
    REQUIRE(r.exit_code == 0);
    CHECK(r.err.empty());
#endif
    r = run_in(dir, {"in.vdb", "--isovalue", "-0.5", "-o", "n.obj", "-q"});  // a negative number is a value
    CHECK(r.exit_code == 0);
    // Below the double range is a number (a denormal): it was "expects a number".
    r = run_in(dir, {"in.vdb", "--sigma-n", "1e-320", "-o", "d.obj", "-q"});
    INFO(r.err);
    CHECK(r.exit_code == 0);
    r = run_in(dir, {"in.vdb", "--isovalue", "1e999", "-o", "h.obj", "-q"});  // beyond it is not
    CHECK(r.exit_code == 2);
}

TEST_CASE("pipes: -o - writes to stdout and - reads the .vdb from stdin", "[cli][conventions]") {
    ScratchDir dir("conventions_pipes");
    openvdb::io::File(dir.path("in.vdb")).write({sphere("sdf", 6.0)});
    REQUIRE(run_in(dir, {"in.vdb", "-o", "ref.ply", "-q"}).exit_code == 0);
    const std::string ref = pqdc_test::read_file(dir.path("ref.ply"));
    RunResult r = run_in(dir, {"in.vdb", "--format", "ply", "-o", "-"});
    INFO(r.err);
    REQUIRE(r.exit_code == 0);
    CHECK(r.out == ref);
    CHECK(contains(r.err, "wrote the mesh to standard output"));
    r = shell_in(dir, std::string("exec '") + PQDC_CLI_PATH + "' - --format ply -o - < in.vdb");
    INFO(r.err);
    REQUIRE(r.exit_code == 0);
    CHECK(r.out == ref);
    CHECK(contains(r.err, "from standard input"));
    // A corrupt stream on stdin is named as standard input.
    pqdc_test::write_file(dir.path("junk.vdb"), "not a vdb file at all, just text");
    r = shell_in(dir, std::string("exec '") + PQDC_CLI_PATH + "' - -o j.obj < junk.vdb");
    CHECK(r.exit_code == 1);
    CHECK(contains(r.err, "standard input"));
    CHECK_FALSE(contains(r.err, "/proc/self/fd"));
}

TEST_CASE("several grids: --grid a,b and *, one mesh per grid through {grid}", "[cli][conventions]") {
    ScratchDir dir("conventions_grids");
    // File order zeta, alpha; vdb_print lists alpha first.
    openvdb::io::File(dir.path("two.vdb")).write({sphere("zeta", 5.0), sphere("alpha", 7.0)});
    RunResult r = run_in(dir, {"two.vdb", "-o", "first.ply"});
    REQUIRE(r.exit_code == 0);
    CHECK(contains(r.err, "using 'alpha'"));
    r = run_in(dir, {"two.vdb", "--grid", "*", "-o", "m_{grid}.ply", "--stats", "m_{grid}.json", "-q"});
    INFO(r.err);
    REQUIRE(r.exit_code == 0);
    const pqdc::Mesh a = pqdc::read_mesh(dir.path("m_alpha.ply")), z = pqdc::read_mesh(dir.path("m_zeta.ply"));
    CHECK(a.points.size() > z.points.size());  // radius 7 against 5
    CHECK(nlohmann::json::parse(pqdc_test::read_file(dir.path("m_zeta.json")))["grid"] == "zeta");
    // A bad name anywhere in the list stops the run before any grid is
    // meshed (zeta's files were written first).
    r = run_in(dir, {"two.vdb", "--grid", "zeta,nope", "-o", "l_{grid}.obj", "--stats", "l_{grid}.json", "-q"});
    CHECK(r.exit_code == 1);
    CHECK(contains(r.err, "no grid named 'nope'"));
    CHECK(contains(r.err, "nothing was meshed"));
    auto velocity = openvdb::Vec3SGrid::create();
    velocity->setName("vel");
    velocity->tree().setValueOn(openvdb::Coord(0, 0, 0), openvdb::Vec3s(1, 0, 0));
    openvdb::io::File(dir.path("three.vdb")).write({sphere("zeta", 5.0), velocity});
    r = run_in(dir, {"three.vdb", "--grid", "zeta,vel", "-o", "v_{grid}.obj", "-q"});
    CHECK(r.exit_code == 1);
    CHECK(contains(r.err, "grid 'vel' in 'three.vdb' is not a float or double grid; pqdc can mesh 'zeta'"));
    // '*' meshes the scalar grids and says which it leaves (it skipped 'vel' silently).
    r = run_in(dir, {"three.vdb", "--grid", "*", "-o", "m_{grid}.ply"});
    CHECK(r.exit_code == 0);
    CHECK(contains(r.err, "--grid '*': skipping 'vel' in 'three.vdb' (not float or double grids"));
    CHECK_FALSE(contains(run_in(dir, {"two.vdb", "--grid", "*", "-o", "m_{grid}.ply"}).err, "skipping"));
    for (const std::string& name : dir.entries())
        CHECK((name.rfind("m_", 0) == 0 || name.find(".vdb") != std::string::npos || name == "first.ply"));
    // A name that holds commas is found whole (it was split: "no grid named 'a'").
    openvdb::io::File(dir.path("comma.vdb")).write({sphere("a,b", 5.0), sphere("c", 6.0)});
    r = run_in(dir, {"comma.vdb", "--grid", "a,b", "-o", "c_{grid}.ply", "-q"});
    CHECK(r.exit_code == 0);
    CHECK(pqdc::read_mesh(dir.path("c_a,b.ply")).points.size() > 100);
    CHECK_FALSE(std::filesystem::exists(dir.path("c_c.ply")));
    // ... also with an -o without {grid}: one grid, one file (a usage error
    // at parse time before, "several grids (--grid a,b)").
    r = run_in(dir, {"comma.vdb", "--grid", "a,b", "-o", "one.ply", "-q"});
    CHECK(r.exit_code == 0);
    CHECK(pqdc::read_mesh(dir.path("one.ply")).points.size() > 100);
    r = run_in(dir, {"comma.vdb", "--grid", "a,c", "-o", "one.ply", "-q"});
    CHECK(r.exit_code == 2);
    CHECK(contains(r.err, "several grids (--grid a,c) give one mesh each; -o 'one.ply' needs {grid}"));
    // A grid that fails after others were written: the error says which
    // files stay (complete) and which grids were not meshed.
    openvdb::io::File(dir.path("sizes.vdb")).write({sphere("small", 3.0), sphere("big", 60.0), sphere("tiny", 2.0)});
    r = run_in(dir, {"sizes.vdb", "--grid", "small,big,tiny", "-o", "s_{grid}.ply", "--memory-limit", "1", "-q"});
    CHECK(r.exit_code == 1);
    CHECK(contains(r.err, "grid 'big' failed (2 of 3); the files of the grids before it are complete and stay: "
                          "'s_small.ply'; not meshed: 'tiny'"));
    CHECK(std::filesystem::exists(dir.path("s_small.ply")));
    CHECK_FALSE(std::filesystem::exists(dir.path("s_big.ply")));
}

TEST_CASE("PLY is float by default, double on request, and vdb_tool-style readers take it", "[cli][conventions]") {
    ScratchDir dir("conventions_ply");
    openvdb::io::File(dir.path("in.vdb")).write({sphere("sdf", 6.0)});
    REQUIRE(run_in(dir, {"in.vdb", "-o", "f.ply", "-q"}).exit_code == 0);
    REQUIRE(run_in(dir, {"in.vdb", "-o", "d.ply", "--precision", "double", "-q"}).exit_code == 0);
    const std::string f = pqdc_test::read_file(dir.path("f.ply")), d = pqdc_test::read_file(dir.path("d.ply"));
    CHECK(contains(f, "property float x\nproperty float y\nproperty float z\n"));
    CHECK(contains(d, "property double x\n"));
    const pqdc::Mesh mf = pqdc::read_mesh(dir.path("f.ply")), md = pqdc::read_mesh(dir.path("d.ply"));
    REQUIRE(mf.points.size() == md.points.size());
    for (std::size_t i = 0; i < mf.points.size(); ++i)
        for (int k = 0; k < 3; ++k) CHECK(mf.points[i][k] == double(float(md.points[i][k])));
}

TEST_CASE("vertex normals are unit and outward in OBJ and PLY, and pqdc-measure reads STL", "[cli][conventions]") {
    ScratchDir dir("conventions_normals");
    const Vec3d c(0.3, -0.2, 0.1);
    auto fog = sphere("fog", 6.0, c);
    // A fog-like grid: inside above the isovalue (negated SDF), class fog volume.
    for (auto it = fog->beginValueAll(); it; ++it) it.setValue(-*it);
    fog->tree().root().setBackground(-fog->background(), false);
    fog->setGridClass(openvdb::GRID_FOG_VOLUME);
    openvdb::io::File(dir.path("in.vdb")).write({sphere("sdf", 6.0, c), fog});
    for (const std::string grid : {"sdf", "fog"}) {
        for (const std::string ext : {".obj", ".ply"}) {
            const std::string out = grid + ext;
            const RunResult r = run_in(dir, {"in.vdb", "--grid", grid, "--vertex-normals", "-o", out, "-q"});
            INFO(r.err);
            REQUIRE(r.exit_code == 0);
            const pqdc::Mesh m = pqdc::read_mesh(dir.path(out));
            REQUIRE(m.normals.size() == m.points.size());
            double worst = 1;
            for (std::size_t i = 0; i < m.points.size(); ++i) {
                CHECK(std::abs(m.normals[i].length() - 1) < 1e-6);
                worst = std::min(worst, m.normals[i].dot((m.points[i] - c).unitSafe()));
            }
            INFO(grid << ext);
            CHECK(worst > 0.98);  // outward and close to the sphere's exact normal
        }
    }
    // Procedural fields: the analytic gradient (the unit sphere at the origin).
    {
        const RunResult p = run_in(dir, {"--procedural", "sphere", "--resolution", "32", "--vertex-normals", "-o",
                                         "p.ply", "-q"});
        REQUIRE(p.exit_code == 0);
        const pqdc::Mesh m = pqdc::read_mesh(dir.path("p.ply"));
        REQUIRE(m.normals.size() == m.points.size());
        for (std::size_t i = 0; i < m.points.size(); ++i) CHECK(m.normals[i].dot(m.points[i].unitSafe()) > 0.999);
    }
    RunResult r = run_in(dir, {"in.vdb", "--grid", "sdf", "-o", "s.stl", "-q"});
    REQUIRE(r.exit_code == 0);
#ifdef PQDC_MEASURE_PATH
    r = run_in(dir, {"s.stl"}, PQDC_MEASURE_PATH);
    INFO(r.err);
    REQUIRE(r.exit_code == 0);
    const auto j = nlohmann::json::parse(r.out);
    CHECK(j["topology"]["boundary_edge_count"] == 0);
    CHECK(j["topology"]["non_manifold_edge_count"] == 0);
#endif
}

TEST_CASE("adaptive: --max-error inf is accepted and the --quads summary counts match the file", "[cli][conventions]") {
    ScratchDir dir("conventions_adaptive");
    openvdb::io::File(dir.path("in.vdb")).write({sphere("sdf", 12.0)});
    RunResult r = run_in(dir, {"in.vdb", "--adaptive", "--max-error", "inf", "--quads", "-o", "q.ply",
                               "--stats", "q.json"});
    INFO(r.err);
    REQUIRE(r.exit_code == 0);
    const pqdc::Mesh m = pqdc::read_mesh(dir.path("q.ply"));
    std::smatch hit;
    const std::regex counts("vertices, (?:(\\d+) triangles)?(?: and )?(?:(\\d+) quads)? in");
    REQUIRE(std::regex_search(r.err, hit, counts));
    const std::size_t tris = hit[1].matched ? std::stoul(hit[1]) : 0, quads = hit[2].matched ? std::stoul(hit[2]) : 0;
    CHECK(tris == m.triangles.size());
    CHECK(quads == m.quads.size());
    const auto j = nlohmann::json::parse(pqdc_test::read_file(dir.path("q.json")));
    CHECK(j["max_error_voxels"].is_null());  // JSON has no infinity: non-finite numbers are null
    CHECK(j["triangles"] == m.triangles.size());
    CHECK(j["quads"] == m.quads.size());
    r = run_in(dir, {"in.vdb", "--sigma-n", "inf", "-o", "mp.obj", "--stats", "mp.json", "-q"});
    REQUIRE(r.exit_code == 0);
    const auto mp = nlohmann::json::parse(pqdc_test::read_file(dir.path("mp.json")));
    CHECK(mp["sigma_n"].is_null());
    CHECK(mp["quadric"] == "mass point");
}

TEST_CASE("progress: silent off a terminal, shown through every stage with --progress", "[cli][conventions]") {
    ScratchDir dir("conventions_progress");
    RunResult r = run_in(dir, {"--procedural", "figure3", "--resolution", "192", "-o", "f.obj"});
    REQUIRE(r.exit_code == 0);
    CHECK_FALSE(contains(r.err, "%"));
    r = run_in(dir, {"--procedural", "figure3", "--resolution", "320", "--progress", "-o", "f.obj"});
    REQUIRE(r.exit_code == 0);
    CHECK(contains(r.err, "meshing procedural figure3"));
    CHECK(std::regex_search(r.err, std::regex("meshing [^\\r]* [1-9][0-9]?%")));
}

TEST_CASE("progress on a terminal: reading, meshing and writing all advance", "[cli][conventions]") {
    ScratchDir dir("conventions_tty");
    // A volume big enough to take a few tenths of a second per stage (the line starts after 0.2 s).
    openvdb::io::File(dir.path("f.vdb")).write({sphere("big", 350.0)});
    int master = -1;
    const std::string vdb = dir.path("f.vdb"), out = dir.path("f.obj");
    const pid_t pid = ::forkpty(&master, nullptr, nullptr, nullptr);
    REQUIRE(pid >= 0);
    if (pid == 0) {
        ::execl(PQDC_CLI_PATH, "pqdc", vdb.c_str(), "-o", out.c_str(), static_cast<char*>(nullptr));
        ::_exit(127);
    }
    std::string tty;
    char buf[4096];
    // When the grid was read: the "using grid" line is logged right after.
    const auto start = std::chrono::steady_clock::now();
    double read_seconds = -1;
    for (;;) {
        const ssize_t n = ::read(master, buf, sizeof buf);
        if (n <= 0) break;  // EIO once the child side closes
        tty.append(buf, std::size_t(n));
        if (read_seconds < 0 && contains(tty, "using grid"))
            read_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    }
    ::close(master);
    int status = 0;
    ::waitpid(pid, &status, 0);
    INFO(tty);
    REQUIRE(WIFEXITED(status));
    CHECK(WEXITSTATUS(status) == 0);
    for (const char* stage : {"meshing grid 'big'", "writing '"}) {
        INFO(stage);
        CHECK(std::regex_search(tty, std::regex(std::string(stage) + "[^\r]*%")));
    }
    // The line starts after 0.2 s and redraws every 0.1 s: a read that ends
    // within 0.4 s (this file is delay-loaded, 0.1-0.4 s here) may finish
    // unseen, a longer one must show.
    INFO("read in " << read_seconds << " s");
    if (read_seconds > 0.4) CHECK(std::regex_search(tty, std::regex("reading '[^\r]*%")));
    CHECK(contains(tty, "wrote '"));
}


TEST_CASE("a run never writes one file twice or over its input, and OpenVDB's warnings stay off stdout",
          "[cli][conventions]") {
    ScratchDir dir("conventions_one_file");
    // Grids "a/b" and "a_b" both become m_a_b.ply through {grid}; "x" twice
    // cannot be told apart (grids are read by name, OpenVDB warns).
    openvdb::io::File(dir.path("clash.vdb")).write({sphere("a/b", 5.0), sphere("a_b", 6.0)});
    openvdb::io::File(dir.path("dup.vdb")).write({sphere("x", 5.0), sphere("x", 6.0)});
    RunResult r = run_in(dir, {"clash.vdb", "--grid", "*", "-o", "m_{grid}.ply", "-q"});
    CHECK(r.exit_code == 2);
    CHECK(contains(r.err, "gives grids 'a/b' and 'a_b' the same file 'm_a_b.ply'"));
    r = run_in(dir, {"dup.vdb", "--grid", "*", "-o", "d_{grid}.ply", "-q"});
    CHECK(r.exit_code == 1);  // the file's fault, not the command line's
    CHECK(contains(r.err, "has 2 grids named 'x'"));
    r = run_in(dir, {"dup.vdb", "--grid", "x,x", "-o", "d_{grid}.ply", "-q"});
    CHECK(r.exit_code == 2);
    CHECK(contains(r.err, "--grid lists 'x' twice"));
    CHECK(dir.entries() == std::vector<std::string>{"clash.vdb", "dup.vdb"});
    // Grids named "." and "..": "{grid}" alone is a directory for each, refused
    // before meshing as a directory -o is (it meshed, then failed to rename).
    openvdb::io::File(dir.path("dots.vdb")).write({sphere(".", 5.0), sphere("..", 6.0)});
    r = run_in(dir, {"dots.vdb", "--grid", "*", "-o", "{grid}", "--format", "ply"});
    CHECK(r.exit_code == 1);
    CHECK(contains(r.err, "cannot write '.' (-o): it is a directory; give a file name"));
    CHECK_FALSE(contains(r.err, "active cells"));
    std::filesystem::remove(dir.path("dots.vdb"));
    // One of two x's asked for is refused as well (it meshed the first one
    // silently); OpenVDB's warning about them goes to stderr, never into
    // the mesh on stdout.
    r = run_in(dir, {"dup.vdb", "--grid", "x", "--format", "ply", "-o", "-", "-q"});
    CHECK(r.exit_code == 1);
    CHECK(contains(r.err, "'dup.vdb' has 2 grids named 'x'; pqdc reads grids by name"));
    CHECK(r.out.empty());
    r = run_in(dir, {"dup.vdb", "-o", "d.ply", "-q"});
    CHECK(r.exit_code == 1);
    CHECK(contains(r.err, "has 2 grids named 'x'"));
    r = run_in(dir, {"clash.vdb", "--grid", "a_b", "--format", "ply", "-o", "-", "-q"});
    REQUIRE(r.exit_code == 0);
    CHECK(r.out.rfind("ply\n", 0) == 0);
    // An extension that names another format than --format.
    r = run_in(dir, {"dup.vdb", "--grid", "x", "--format", "obj", "-o", "o.ply", "-q"});
    CHECK(r.exit_code == 2);
    CHECK(contains(r.err, "the extension of -o 'o.ply' says PLY but --format says OBJ"));
#ifdef PQDC_DECIMATE_PATH
    REQUIRE(run_in(dir, {"clash.vdb", "--grid", "a_b", "-o", "in.ply", "-q"}).exit_code == 0);
    const std::string input = pqdc_test::read_file(dir.path("in.ply"));
    for (const std::vector<std::string>& args :
         {std::vector<std::string>{"in.ply", "-o", "o.ply", "--stats", "./o.ply", "--target-ratio", "0.5"},
          std::vector<std::string>{"in.ply", "-o", "o.ply", "--stats", "in.ply", "--target-ratio", "0.5"},
          std::vector<std::string>{"in.ply", "-o",
                                   "../" + std::filesystem::path(dir.path("in.ply")).parent_path().filename().string() +
                                       "/in.ply",
                                   "--target-ratio", "0.5"}}) {
        r = run_in(dir, args, PQDC_DECIMATE_PATH);
        CHECK(r.exit_code == 2);
        CHECK(contains(r.err, "is the same file as"));
    }
    CHECK(pqdc_test::read_file(dir.path("in.ply")) == input);
    r = run_in(dir, {"in.ply", "-o", "o.ply", "--target-ratio", "0.5", "--max-normal-change", "0"}, PQDC_DECIMATE_PATH);
    CHECK(r.exit_code == 2);
    CHECK(contains(r.err, "--max-normal-change must be in (0, 180)"));
    // An option the chosen metric does not use.
    r = run_in(dir, {"in.ply", "-o", "o.ply", "--target-ratio", "0.5", "--sigma-normal", "0.1"}, PQDC_DECIMATE_PATH);
    CHECK(r.exit_code == 2);
    CHECK(contains(r.err, "--sigma-normal is the normal noise of --metric plane"));
    // Two outputs on standard output would mix the mesh and the JSON.
    r = run_in(dir, {"in.ply", "-o", "-", "--format", "off", "--stats", "-", "--target-ratio", "0.5"}, PQDC_DECIMATE_PATH);
    CHECK(r.exit_code == 2);
    CHECK(contains(r.err, "-o and --stats both write to standard output"));
#endif
#ifdef PQDC_BRICKS_PATH
    // Nothing the run writes may land in a brick store it reads: a brick
    // file or the index overwritten destroyed the store.
    REQUIRE(run_in(dir, {"split", "clash.vdb", "--grid", "a_b", "-o", "x.bricks"}, PQDC_BRICKS_PATH).exit_code == 0);
    const std::string index = pqdc_test::read_file(dir.path("x.bricks/index.txt"));
    for (const std::vector<std::string>& args :
         {std::vector<std::string>{"x.bricks", "--format", "ply", "-o", "x.bricks/brick-000000.vdb", "-q"},
          std::vector<std::string>{"x.bricks", "-o", "m.ply", "--stats", "./x.bricks/index.txt", "-q"}}) {
        r = run_in(dir, args);
        CHECK(r.exit_code == 2);
        CHECK(contains(r.err, "lies inside the input 'x.bricks', which the run reads"));
    }
    CHECK(pqdc_test::read_file(dir.path("x.bricks/index.txt")) == index);
    CHECK(!std::filesystem::exists(dir.path("m.ply")));
#endif
#ifdef PQDC_ADD_NOISE_PATH
    r = run_in(dir, {"dup.vdb", "-o", "./dup.vdb", "--sigma-voxels", "0.1"}, PQDC_ADD_NOISE_PATH);
    CHECK(r.exit_code == 2);
    CHECK(contains(r.err, "is the same file as the input"));
#endif
}


TEST_CASE("an empty mesh is explained by its region, and the warning is in --stats", "[cli][conventions]") {
    ScratchDir dir("conventions_empty_region");
    openvdb::io::File(dir.path("in.vdb")).write({sphere("sdf", 6.0)});
    // A mask whose active voxels lie far from the sphere.
    auto mask = openvdb::BoolGrid::create(false);
    mask->setName("far");
    mask->tree().setValueOn(openvdb::Coord(100, 100, 100), true);
    openvdb::io::File(dir.path("mask.vdb")).write({mask});
    const RunResult r = run_in(dir, {"in.vdb", "--mask", "mask.vdb", "-o", "e.ply", "--stats", "e.json"});
    INFO(r.err);
    REQUIRE(r.exit_code == 0);
    CHECK(contains(r.err, "no surface in grid 'sdf' inside the region (--bbox, --mask)"));
    CHECK_FALSE(contains(r.err, "never change sign"));
    const auto stats = nlohmann::json::parse(pqdc_test::read_file(dir.path("e.json")));
    REQUIRE(stats["warnings"].size() == 1);
    CHECK(contains(stats["warnings"][0].get<std::string>(), "inside the region"));
}


TEST_CASE("an interrupt in pqdc's first milliseconds is an interrupt, not an internal error", "[cli][conventions]") {
    ScratchDir dir("conventions_early_interrupt");
    // Before the worker has its handler the signal ends it: the supervisor
    // says so (it reported "internal error ... Please report this").
    for (double after : {0.001, 0.005, 0.02, 0.05}) {
        RunSpec spec;
        spec.args = {"--procedural", "figure3", "--resolution", "300", "-o", "x.ply"};
        spec.cwd = dir.dir();
        spec.signal_after_seconds = after;
        const RunResult r = pqdc_test::run_program(PQDC_CLI_PATH, spec);
        INFO("SIGINT after " << after << " s: " << r.err);
        CHECK((r.exit_code == 130 || r.term_signal == SIGINT));
        CHECK_FALSE(contains(r.err, "internal error"));
        CHECK(dir.entries().empty());
    }
}

TEST_CASE("a worker stopped from outside is reported as such, not as a corrupt file or pqdc's bug", "[cli][conventions]") {
    ScratchDir dir("conventions_killed_worker");
    // A CPU-time limit (as batch systems set) ends the worker with SIGXCPU
    // while the supervisor, which only waits, stays below it. It was
    // reported as "internal error ... Please report this" (or, while
    // reading, as a corrupt file) with exit code 1.
    RunSpec spec;
    spec.args = {"--cpu=1:1", PQDC_CLI_PATH, "--procedural", "figure3", "--resolution", "500", "--threads", "1",
                 "-o", "x.ply"};
    spec.cwd = dir.dir();
    const RunResult r = pqdc_test::run_program("/usr/bin/prlimit", spec);
    INFO(r.err);
    CHECK((r.exit_code == 128 + SIGXCPU || r.exit_code == 128 + SIGKILL));
    CHECK(contains(r.err, "stopped from outside"));
    CHECK(contains(r.err, "or add --out-of-core"));
    CHECK_FALSE(contains(r.err, "internal error"));
    CHECK_FALSE(contains(r.err, "corrupt"));
    CHECK(dir.entries().empty());
    // Out of core already: the advice is not to add it again.
    spec.args.push_back("--out-of-core");
    const RunResult ooc = pqdc_test::run_program("/usr/bin/prlimit", spec);
    INFO(ooc.err);
    CHECK(contains(ooc.err, "stopped from outside"));
    CHECK_FALSE(contains(ooc.err, "add --out-of-core"));
    CHECK(contains(ooc.err, "--brick-runs"));
    CHECK(dir.entries().empty());
}

#endif
