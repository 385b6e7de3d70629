#include "test_files.hpp"
#include "random.hpp"
#include "pqdc/mesh_io.hpp"
#include "pqdc/file_io.hpp"

#include "pqdc/exceptions.hpp"

#include <catch2/catch.hpp>

#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <thread>

#include <dirent.h>
#include <fcntl.h>
#include <sys/wait.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

namespace {

// A fresh, empty directory per test under the build tree (not /tmp, so tests
// of one build never see another build's files).
std::string make_test_dir(const std::string& name) {
    const std::filesystem::path dir = std::filesystem::path(PQDC_BINARY_DIR) / "test_output" / ("mesh_io_" + name);
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
    return dir.string();
}

std::size_t count_entries(const std::string& dir) {
    std::size_t n = 0;
    if (DIR* d = ::opendir(dir.c_str())) {
        while (dirent* e = ::readdir(d)) {
            if (std::strcmp(e->d_name, ".") != 0 && std::strcmp(e->d_name, "..") != 0) ++n;
        }
        ::closedir(d);
    }
    return n;
}

// Coordinates chosen to stress shortest round-trip printing: random bit
// patterns across many magnitudes, plus awkward exact values.
pqdc::Mesh random_mesh(std::uint32_t seed, std::size_t points, std::size_t tris, std::size_t quads) {
    pqdc_test::Random rng(seed);
    pqdc_test::UniformReal mantissa{-1.0, 1.0};
    pqdc_test::UniformInt exponent{-30, 30};
    pqdc::Mesh m;
    for (std::size_t i = 0; i < points; ++i) {
        openvdb::Vec3d p;
        for (int k = 0; k < 3; ++k) p[k] = std::ldexp(mantissa(rng), exponent(rng));
        m.points.push_back(p);
    }
    m.points[0] = openvdb::Vec3d(0.1, -0.0, 1e30);
    m.points[1] = openvdb::Vec3d(5e-324, 123456789.125, -2.5);
    pqdc_test::UniformInt idx{0, int(points) - 1};
    for (std::size_t i = 0; i < tris; ++i) m.triangles.emplace_back(idx(rng), idx(rng), idx(rng));
    for (std::size_t i = 0; i < quads; ++i) m.quads.emplace_back(idx(rng), idx(rng), idx(rng), idx(rng));
    return m;
}

bool bitwise_equal(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

void require_same_mesh(const pqdc::Mesh& a, const pqdc::Mesh& b) {
    REQUIRE(a.points.size() == b.points.size());
    REQUIRE(a.triangles.size() == b.triangles.size());
    REQUIRE(a.quads.size() == b.quads.size());
    std::size_t mismatched = 0;
    for (std::size_t i = 0; i < a.points.size(); ++i)
        for (int k = 0; k < 3; ++k)
            if (!bitwise_equal(a.points[i][k], b.points[i][k])) ++mismatched;
    CHECK(mismatched == 0);
    CHECK(a.triangles == b.triangles);
    CHECK(a.quads == b.quads);
}

}  // namespace

TEST_CASE("mesh_format_from_path maps extensions case-insensitively", "[mesh_io]") {
    CHECK(pqdc::mesh_format_from_path("a/b.obj") == pqdc::MeshFormat::obj);
    CHECK(pqdc::mesh_format_from_path("B.PLY") == pqdc::MeshFormat::ply);
    CHECK(pqdc::mesh_format_from_path("x.y/c.Stl") == pqdc::MeshFormat::stl);
    CHECK(pqdc::mesh_format_from_path("d/e.OfF") == pqdc::MeshFormat::off);
    CHECK_THROWS_AS(pqdc::mesh_format_from_path("mesh.xyz"), pqdc::option_error);
    CHECK_THROWS_AS(pqdc::mesh_format_from_path("dir.obj/mesh"), pqdc::option_error);
    CHECK_THROWS_WITH(pqdc::mesh_format_from_path("mesh.xyz"),
                      Catch::Contains("mesh.xyz") && Catch::Contains(".obj, .ply, .off or .stl"));
}

pqdc::MeshWriteOptions double_precision() {
    pqdc::MeshWriteOptions o;
    o.precision = pqdc::VertexPrecision::float64;
    return o;
}

TEST_CASE("OBJ, PLY and OFF round trips are bit-exact in double precision", "[mesh_io]") {
    pqdc::Mesh mesh = random_mesh(12345, 2000, 1500, 700);
    mesh.points[0][2] = 1e300;
    for (const char* ext : {".obj", ".ply", ".off"}) {
        SECTION(ext) {
            const std::string dir = make_test_dir(std::string("roundtrip") + (ext + 1));
            const std::string path = dir + "/mesh" + ext;
            pqdc::write_mesh(mesh, path, double_precision());
            require_same_mesh(mesh, pqdc::read_mesh(path));
            // Writing the same mesh again gives the same bytes.
            const std::string first = pqdc_test::read_file(path);
            pqdc::write_mesh(mesh, path, double_precision());
            CHECK(pqdc_test::read_file(path) == first);
            CHECK(count_entries(dir) == 1);  // no temporary files left behind
        }
    }
}

TEST_CASE("float precision (the default) stores the nearest float, shortest digits in text", "[mesh_io]") {
    pqdc::Mesh mesh = random_mesh(99, 500, 300, 100);
    mesh.points[0] = openvdb::Vec3d(0.1, -0.0, 1e30);
    mesh.points[2] = openvdb::Vec3d(0.1, 1.0 / 3.0, -12345.678);  // known shortest floats
    for (const char* ext : {".obj", ".ply", ".off"}) {
        const std::string dir = make_test_dir(std::string("float") + (ext + 1));
        const std::string path = dir + "/mesh" + ext;
        pqdc::write_mesh(mesh, path);
        const pqdc::Mesh back = pqdc::read_mesh(path);
        REQUIRE(back.points.size() == mesh.points.size());
        std::size_t mismatched = 0;  // read back as float, every coordinate is the float nearest the original
        for (std::size_t i = 0; i < mesh.points.size(); ++i)
            for (int k = 0; k < 3; ++k)
                if (static_cast<float>(back.points[i][k]) != static_cast<float>(mesh.points[i][k])) ++mismatched;
        CHECK(mismatched == 0);
        CHECK(back.triangles == mesh.triangles);
        if (std::string(ext) == ".obj") CHECK(pqdc_test::read_file(path).find("\nv 0.1 0.33333334 -12345.678\n") != std::string::npos);
        // Float text is much smaller than double text for random coordinates.
        if (std::string(ext) != ".ply") {
            pqdc::write_mesh(mesh, dir + "/double" + ext, double_precision());
            CHECK(pqdc_test::read_file(path).size() < 0.75 * pqdc_test::read_file(dir + "/double" + ext).size());
        }
    }
    // A coordinate beyond float's range is refused, not written as inf.
    mesh.points[1][2] = 1e300;
    const std::string dir = make_test_dir("float_range");
    CHECK_THROWS_WITH(pqdc::write_mesh(mesh, dir + "/m.ply"), Catch::Contains("write it with double precision (PLY, OBJ or OFF)"));
    CHECK_THROWS_AS(pqdc::write_mesh(mesh, dir + "/m.stl"), pqdc::input_error);
    CHECK(count_entries(dir) == 0);
    pqdc::write_mesh(mesh, dir + "/m.ply", double_precision());
}

TEST_CASE("vertex normals: OBJ vn with f a//a, PLY nx ny nz, read back", "[mesh_io]") {
    pqdc::Mesh mesh = random_mesh(5, 50, 20, 10);
    for (std::size_t i = 0; i < mesh.points.size(); ++i)
        mesh.normals.push_back(openvdb::Vec3d(0.6, 0.0, -0.8) * (i % 2 ? 1.0 : -1.0));
    const std::string dir = make_test_dir("normals");
    for (const char* ext : {".obj", ".ply"}) {
        const std::string path = dir + "/n" + ext;
        pqdc::write_mesh(mesh, path, double_precision());
        const pqdc::Mesh back = pqdc::read_mesh(path);
        require_same_mesh(mesh, back);
        REQUIRE(back.normals.size() == mesh.normals.size());
        for (std::size_t i = 0; i < mesh.normals.size(); ++i) CHECK(back.normals[i] == mesh.normals[i]);
    }
    const std::string obj = pqdc_test::read_file(dir + "/n.obj");
    CHECK(obj.find("\nvn ") != std::string::npos);
    CHECK(obj.find("//") != std::string::npos);
    pqdc::write_mesh(mesh, dir + "/f.ply");
    CHECK(pqdc_test::read_file(dir + "/f.ply").find("property float x\nproperty float y\nproperty float z\nproperty float nx\n"
                                    "property float ny\nproperty float nz\n") != std::string::npos);
    mesh.normals.pop_back();
    CHECK_THROWS_AS(pqdc::write_mesh(mesh, dir + "/bad.obj"), pqdc::input_error);
}

TEST_CASE("OBJ normals follow the faces' a//c references, or are dropped when per corner", "[mesh_io]") {
    const std::string dir = make_test_dir("obj_vn");
    const std::string head = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
                             "vn 0 0 1\nvn 0 1 0\nvn 1 0 0\nvn 0 0 -1\n";
    // The vn lines in another order than the v lines: taken by position,
    // vertex 0 got vn 1 instead of vn 4.
    pqdc_test::write_file(dir + "/mapped.obj", head + "f 1//4 2//3 3//2\nf 1//4 3//2 4//1\n");
    const pqdc::Mesh m = pqdc::read_mesh(dir + "/mapped.obj");
    REQUIRE(m.normals.size() == 4);
    CHECK(m.normals[0] == openvdb::Vec3d(0, 0, -1));
    CHECK(m.normals[1] == openvdb::Vec3d(1, 0, 0));
    CHECK(m.normals[2] == openvdb::Vec3d(0, 1, 0));
    CHECK(m.normals[3] == openvdb::Vec3d(0, 0, 1));
    // Vertex 0 with two normals (a crease), a reference to no vn line, and
    // corners with and without normals: no per-vertex normals, same faces.
    for (const char* faces : {"f 1//4 2//3 3//2\nf 1//1 3//2 4//1\n", "f 1//9 2//3 3//2\n", "f 1//4 2 3//2\n"}) {
        pqdc_test::write_file(dir + "/corner.obj", head + faces);
        const pqdc::Mesh c = pqdc::read_mesh(dir + "/corner.obj");
        CHECK(c.normals.empty());
        CHECK(c.face_count() > 0);
    }
}

TEST_CASE("writing to standard output needs a format", "[mesh_io]") {
    CHECK_THROWS_WITH(pqdc::write_mesh(random_mesh(1, 5, 1, 0), "-"), Catch::Contains("needs a format"));
    CHECK(pqdc::mesh_format_from_name("PLY") == pqdc::MeshFormat::ply);
    CHECK_THROWS_AS(pqdc::mesh_format_from_name("vdb"), pqdc::option_error);
}

TEST_CASE("empty mesh round trips", "[mesh_io]") {
    const std::string dir = make_test_dir("empty");
    for (const char* ext : {".obj", ".ply", ".off"}) {
        const std::string path = dir + "/empty" + ext;
        pqdc::write_mesh(pqdc::Mesh{}, path);
        const pqdc::Mesh back = pqdc::read_mesh(path);
        CHECK(back.points.empty());
        CHECK(back.face_count() == 0);
    }
}

TEST_CASE("binary STL has the right size and triangle count", "[mesh_io]") {
    const std::string dir = make_test_dir("stl");
    const pqdc::Mesh mesh = random_mesh(7, 100, 37, 11);
    const std::string path = dir + "/mesh.stl";
    pqdc::write_mesh(mesh, path);
    const std::string bytes = pqdc_test::read_file(path);
    const std::size_t expected_tris = 37 + 2 * 11;
    REQUIRE(bytes.size() == 84 + 50 * expected_tris);
    std::uint32_t count = 0;
    std::memcpy(&count, bytes.data() + 80, 4);
    CHECK(count == expected_tris);
    // First triangle's first vertex is stored as float.
    float v[3];
    std::memcpy(v, bytes.data() + 84 + 12, 12);
    const auto& p = mesh.points[mesh.triangles[0][0]];
    for (int k = 0; k < 3; ++k) CHECK(v[k] == static_cast<float>(p[k]));
}

TEST_CASE("STL reader: binary and ASCII, corners welded into shared vertices", "[mesh_io]") {
    const std::string dir = make_test_dir("stlread");
    // A closed tetrahedron as quads+triangles: the STL holds 4 triangles with 12 corners.
    pqdc::Mesh tet;
    tet.points = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    tet.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
    pqdc::write_mesh(tet, dir + "/t.stl");
    const pqdc::Mesh back = pqdc::read_mesh(dir + "/t.stl");
    CHECK(back.points.size() == 4);
    REQUIRE(back.triangles.size() == 4);
    for (std::size_t f = 0; f < 4; ++f)
        for (int k = 0; k < 3; ++k) CHECK(back.points[back.triangles[f][k]] == tet.points[tet.triangles[f][k]]);
    pqdc_test::write_file(dir + "/a.stl", "solid t\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 0\n"
                         "   vertex 0 1 0\n  endloop\n endfacet\n facet normal 0 0 1\n  outer loop\n"
                         "   vertex 1 0 0\n   vertex 1 1 0\n   vertex 0 1 0\n  endloop\n endfacet\nendsolid t\n");
    const pqdc::Mesh ascii = pqdc::read_mesh(dir + "/a.stl");
    CHECK(ascii.points.size() == 4);
    CHECK(ascii.triangles.size() == 2);
    // Some exporters write upper case, or indent the first line: still ASCII
    // (was read as a binary header declaring ~7e8 triangles).
    std::string upper = "  \tSOLID T\n";
    for (const char* v : {"VERTEX 0 0 0\n", "VERTEX 1 0 0\n", "VERTEX 0 1 0\n"}) upper += v;
    pqdc_test::write_file(dir + "/upper.stl", upper + "ENDSOLID T\n");
    const pqdc::Mesh up = pqdc::read_mesh(dir + "/upper.stl");
    CHECK(up.points.size() == 3);
    CHECK(up.triangles.size() == 1);
    std::string cut = pqdc_test::read_file(dir + "/t.stl");
    cut.resize(cut.size() - 7);
    pqdc_test::write_file(dir + "/cut.stl", cut);
    CHECK_THROWS_WITH(pqdc::read_mesh(dir + "/cut.stl"), Catch::Contains("cut.stl") && Catch::Contains("truncated"));
    // Cut after a whole facet (no endsolid): every tool read the part silently.
    const std::string a = pqdc_test::read_file(dir + "/a.stl");
    pqdc_test::write_file(dir + "/cut_ascii.stl", a.substr(0, a.find("endsolid")));
    CHECK_THROWS_WITH(pqdc::read_mesh(dir + "/cut_ascii.stl"), Catch::Contains("ends before 'endsolid'"));
    pqdc_test::write_file(dir + "/two.stl", a + a);  // several solids in one file
    CHECK(pqdc::read_mesh(dir + "/two.stl").triangles.size() == 4);
    pqdc_test::write_file(dir + "/bad.stl", "solid x\n vertex 0 0 zero\n");
    CHECK_THROWS_WITH(pqdc::read_mesh(dir + "/bad.stl"), Catch::Contains("line 2") && Catch::Contains("'zero'"));
}

TEST_CASE("PLY header written as documented", "[mesh_io]") {
    const std::string dir = make_test_dir("plyheader");
    const std::string path = dir + "/m.ply";
    pqdc::write_mesh(random_mesh(3, 10, 2, 1), path);
    const std::string bytes = pqdc_test::read_file(path);
    CHECK(bytes.rfind("ply\nformat binary_little_endian 1.0\n", 0) == 0);
    CHECK(bytes.find("element vertex 10\nproperty float x\nproperty float y\nproperty float z\n") !=
          std::string::npos);
    CHECK(bytes.find("element face 3\nproperty list uchar int vertex_indices\nend_header\n") != std::string::npos);
    const std::size_t data = bytes.find("end_header\n") + 11;
    CHECK(bytes.size() - data == 10 * 12 + 2 * 13 + 17);
    pqdc::write_mesh(random_mesh(3, 10, 2, 1), path, double_precision());
    const std::string wide = pqdc_test::read_file(path);
    CHECK(wide.find("property double x\nproperty double y\nproperty double z\n") != std::string::npos);
    CHECK(wide.size() - (wide.find("end_header\n") + 11) == 10 * 24 + 2 * 13 + 17);
}

TEST_CASE("OFF written as documented", "[mesh_io]") {
    const std::string dir = make_test_dir("offwrite");
    const std::string path = dir + "/m.OFF";
    pqdc::Mesh m;
    m.points = {{0, 0, 0}, {1.5, 0, 0}, {0, 0.1, -2}, {1e-300, 1, 1}};
    m.triangles.emplace_back(0, 1, 2);
    m.quads.emplace_back(0, 1, 3, 2);
    pqdc::write_mesh(m, path, double_precision());
    CHECK(pqdc_test::read_file(path) == "OFF\n4 2 0\n0 0 0\n1.5 0 0\n0 0.1 -2\n1e-300 1 1\n3 0 1 2\n4 0 1 3 2\n");
}

TEST_CASE("writing with an unknown extension throws before touching disk", "[mesh_io]") {
    const std::string dir = make_test_dir("ext");
    CHECK_THROWS_AS(pqdc::write_mesh(random_mesh(1, 5, 1, 0), dir + "/m.xyz"), pqdc::option_error);
    CHECK(count_entries(dir) == 0);
}

TEST_CASE("writing a mesh with out-of-range indices throws", "[mesh_io]") {
    const std::string dir = make_test_dir("badidx");
    pqdc::Mesh m = random_mesh(1, 5, 1, 0);
    m.triangles.emplace_back(0, 1, 5);
    CHECK_THROWS_AS(pqdc::write_mesh(m, dir + "/m.obj"), pqdc::input_error);
    CHECK(count_entries(dir) == 0);
}

TEST_CASE("failed writes leave the existing file intact and no temporary", "[mesh_io]") {
    const pqdc::Mesh mesh = random_mesh(99, 50, 40, 0);

    SECTION("missing directory") {
        const std::string dir = make_test_dir("atomic_missing");
        const std::string path = dir + "/no/such/dir/m.obj";
        CHECK_THROWS_AS(pqdc::write_mesh(mesh, path), pqdc::io_error);
        CHECK_THROWS_WITH(pqdc::write_mesh(mesh, path),
                          Catch::Contains(path) && Catch::Contains("No such file or directory"));
    }
    SECTION("target is a directory") {
        const std::string dir = make_test_dir("atomic_isdir");
        const std::string path = dir + "/sub.obj";
        REQUIRE(::mkdir(path.c_str(), 0777) == 0);
        CHECK_THROWS_AS(pqdc::write_mesh(mesh, path), pqdc::io_error);
        CHECK_THROWS_WITH(pqdc::write_mesh(mesh, path), Catch::Contains(path));
        struct stat st {};
        REQUIRE(::stat(path.c_str(), &st) == 0);
        CHECK(S_ISDIR(st.st_mode));
        CHECK(count_entries(dir) == 1);
    }
    SECTION("file size limit hit mid-write (stands in for a full disk)") {
        const std::string dir = make_test_dir("atomic_fsize");
        // RLIMIT_FSIZE makes write(2) fail with EFBIG part way through, the
        // same code path as ENOSPC, and it applies to root as well.
        const std::string path = dir + "/m.ply";
        const std::string original = "previous contents\n";
        pqdc_test::write_file(path, original);
        const pqdc::Mesh big = random_mesh(5, 200000, 200000, 0);  // ~7.4 MB, beyond one buffer
        rlimit old {};
        REQUIRE(::getrlimit(RLIMIT_FSIZE, &old) == 0);
        const auto old_handler = std::signal(SIGXFSZ, SIG_IGN);
        rlimit small = old;
        small.rlim_cur = 64 * 1024;
        REQUIRE(::setrlimit(RLIMIT_FSIZE, &small) == 0);
        bool threw_io_error = false;
        std::string message;
        try {
            pqdc::write_mesh(big, path);
        } catch (const pqdc::io_error& e) {
            threw_io_error = true;
            message = e.what();
        }
        ::setrlimit(RLIMIT_FSIZE, &old);
        std::signal(SIGXFSZ, old_handler);
        CHECK(threw_io_error);
        CHECK_THAT(message, Catch::Contains(path) && Catch::Contains(std::strerror(EFBIG)));
        CHECK(pqdc_test::read_file(path) == original);
        CHECK(count_entries(dir) == 1);
    }
}

/// A directory whose file system makes files without a name (O_TMPFILE),
/// which the kill test below needs: the build tree's, else tmpfs's.
std::string directory_with_unnamed_files(const std::string& name) {
    for (const std::string& dir : {make_test_dir(name), std::string("/dev/shm")}) {
        const int fd = ::open(dir.c_str(), O_TMPFILE | O_WRONLY | O_CLOEXEC, 0600);
        if (fd < 0) continue;
        ::close(fd);
        if (dir == "/dev/shm") {
            const std::string sub = dir + "/pqdc_test_" + std::to_string(::getpid()) + "_" + name;
            std::filesystem::remove_all(sub);
            std::filesystem::create_directories(sub);
            return sub;
        }
        return dir;
    }
    return {};
}

TEST_CASE("a writer killed mid-file (SIGKILL) leaves no partial file and no temporary", "[mesh_io]") {
    // The OOM killer or a batch system's limit ends a process without a
    // chance to clean up: the unfinished file must go with the process.
    const std::string dir = directory_with_unnamed_files("killed");
    REQUIRE_FALSE(dir.empty());
    const pqdc::Mesh big = random_mesh(7, 200000, 200000, 0);  // ~7.4 MB, beyond one 4 MiB buffer
    const std::string path = dir + "/m.ply", original = "previous contents\n";
    for (const bool replacing : {false, true}) {
        INFO((replacing ? "replacing a file" : "a new file"));
        if (replacing) pqdc_test::write_file(path, original);
        const pid_t pid = ::fork();
        REQUIRE(pid >= 0);
        if (pid == 0) {
            pqdc::MeshWriteOptions options;
            options.progress = [](double) { ::raise(SIGKILL); };  // once the first 4 MiB are in the file
            try {
                pqdc::write_mesh(big, path, options);
            } catch (...) {
            }
            ::_exit(0);
        }
        int status = 0;
        REQUIRE(::waitpid(pid, &status, 0) == pid);
        CHECK(WIFSIGNALED(status));
        CHECK(WTERMSIG(status) == SIGKILL);
        if (replacing) CHECK(pqdc_test::read_file(path) == original);
        CHECK(count_entries(dir) == (replacing ? 1u : 0u));
    }
    // The same writer, not killed, still puts the file in place (new and replaced).
    std::remove(path.c_str());
    pqdc::write_mesh(big, path);
    const std::string first = pqdc_test::read_file(path);
    CHECK(first.size() > (std::size_t(4) << 20));
    pqdc::write_mesh(big, path);
    CHECK(pqdc_test::read_file(path) == first);
    CHECK(count_entries(dir) == 1);
    if (dir.rfind("/dev/shm/", 0) == 0) std::filesystem::remove_all(dir);
}

TEST_CASE("write_file writes, replaces and fails like the mesh writers", "[mesh_io]") {
    const std::string dir = make_test_dir("write_file");
    const std::string path = dir + "/run.json";
    pqdc::write_file(path, "{\"a\": 1}\n");
    CHECK(pqdc_test::read_file(path) == "{\"a\": 1}\n");
    pqdc::write_file(path, "");
    CHECK(pqdc_test::read_file(path).empty());
    CHECK(count_entries(dir) == 1);
    const std::string missing = dir + "/no/such/run.json";
    CHECK_THROWS_AS(pqdc::write_file(missing, "x"), pqdc::io_error);
    CHECK_THROWS_WITH(pqdc::write_file(missing, "x"), Catch::Contains(missing));
    CHECK(count_entries(dir) == 1);
}

TEST_CASE("replacing a file keeps its permission bits", "[mesh_io]") {
    const std::string dir = make_test_dir("mode");
    const std::string path = dir + "/m.obj";
    pqdc_test::write_file(path, "old\n");
    REQUIRE(::chmod(path.c_str(), 0600) == 0);
    pqdc::write_mesh(random_mesh(1, 5, 1, 0), path);
    struct stat st {};
    REQUIRE(::stat(path.c_str(), &st) == 0);
    CHECK((st.st_mode & 0777) == 0600);
}

TEST_CASE("a target that is a pipe or device is written in place, not replaced", "[mesh_io]") {
    // A rename onto /dev/null as root replaces the device node with a plain
    // file; a FIFO shows the same without risking the machine's /dev/null.
    const std::string dir = make_test_dir("fifo");
    const std::string fifo = dir + "/out.ply", plain = dir + "/plain.ply";
    REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
    const pqdc::Mesh mesh = random_mesh(3, 200, 150, 20);
    pqdc::write_mesh(mesh, plain);
    std::string received;
    std::thread reader([&] { received = pqdc_test::read_file(fifo); });
    pqdc::write_mesh(mesh, fifo);
    reader.join();
    struct stat st {};
    REQUIRE(::stat(fifo.c_str(), &st) == 0);
    CHECK(S_ISFIFO(st.st_mode));
    CHECK(received == pqdc_test::read_file(plain));
    CHECK(count_entries(dir) == 2);  // no temporary or scratch file left
}

TEST_CASE("OBJ reader accepts common variants", "[mesh_io]") {
    const std::string dir = make_test_dir("objvariants");
    const std::string path = dir + "/v.obj";
    pqdc_test::write_file(path,
         "# comment\r\n"
         "mtllib x.mtl\n"
         "o thing\n"
         "v 0 0 0\n"
         "v +1.5 0 0 1.0\n"   // optional w
         "v 1 1e0 0 0.5 0.5 0.5\n"  // colors
         "v 0 1 0\n"
         "vt 0 0\n"
         "vn 0 0 1\n"
         "s off\n"
         "f 1/1/1 2/1/1 3/1/1\r\n"
         "f 1//1 3//1 4//1\n"
         "f -4 -3 -2 -1\n"
         "\tf 1 2 3 4 1\n");  // pentagon -> fan of 3 triangles
    const pqdc::Mesh m = pqdc::read_mesh(path);
    REQUIRE(m.points.size() == 4);
    CHECK(m.points[1] == openvdb::Vec3d(1.5, 0, 0));
    CHECK(m.triangles.size() == 2 + 3);
    REQUIRE(m.quads.size() == 1);
    CHECK(m.quads[0] == openvdb::Vec4I(0, 1, 2, 3));
    CHECK(m.triangles[1] == openvdb::Vec3I(0, 2, 3));
}

TEST_CASE("a concave polygon becomes a fan that does not fold over itself", "[mesh_io]") {
    // A square with a notch: the fan from its first corner would put a
    // triangle across the notch, facing the other way; the notch's corner
    // sees the whole polygon.
    const std::string dir = make_test_dir("concave");
    pqdc_test::write_file(dir + "/notch.obj", "v 0 0 0\nv 4 0 0\nv 4 4 0\nv 2 1 0\nv 0 4 0\nf 1 2 3 4 5\n");
    pqdc_test::write_file(dir + "/notch.off", "OFF\n5 1 0\n0 0 0\n4 0 0\n4 4 0\n2 1 0\n0 4 0\n5 0 1 2 3 4\n");
    for (const char* name : {"/notch.obj", "/notch.off"}) {
        const pqdc::Mesh m = pqdc::read_mesh(dir + name);
        REQUIRE(m.triangles.size() == 3);
        double area = 0;
        for (const auto& t : m.triangles) {
            const openvdb::Vec3d n = (m.points[t[1]] - m.points[t[0]]).cross(m.points[t[2]] - m.points[t[0]]);
            CHECK(n.z() > 0);  // every triangle faces the polygon's side
            area += n.z() / 2;
        }
        CHECK(area == 10.0);  // 16 minus the notch's 6: the polygon, covered once
        CHECK(m.triangles[0][0] == 3);
    }
}

TEST_CASE("malformed OBJ files throw input_error naming path and line", "[mesh_io]") {
    const std::string dir = make_test_dir("badobj");
    const std::string path = dir + "/bad.obj";
    struct Case {
        const char* text;
        const char* line;
    };
    const Case cases[] = {
        {"v 0 0 0\nv 1 0 0\nv 0 x 0\n", "line 3"},
        {"v 0 0 0\nv 1 0 0\n", nullptr},  // valid, no faces
        {"v 0 0\n", "line 1"},
        {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "line 4"},
        {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "line 4"},
        {"v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2\n", "line 5"},
        {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -4\n", "line 4"},
        {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 a\n", "line 4"},
        {"v 1e999 0 0\n", "line 1"},
    };
    for (const Case& c : cases) {
        pqdc_test::write_file(path, c.text);
        INFO(c.text);
        if (!c.line) {
            CHECK_NOTHROW(pqdc::read_mesh(path));
            continue;
        }
        CHECK_THROWS_AS(pqdc::read_mesh(path), pqdc::input_error);
        CHECK_THROWS_WITH(pqdc::read_mesh(path), Catch::Contains(path) && Catch::Contains(c.line));
    }
    CHECK_THROWS_AS(pqdc::read_mesh(dir + "/missing.obj"), pqdc::input_error);
    CHECK_THROWS_WITH(pqdc::read_mesh(dir + "/missing.obj"), Catch::Contains("missing.obj"));
}

namespace {
template <typename T>
void put(std::string& s, T v) {
    s.append(reinterpret_cast<const char*>(&v), sizeof v);
}
}  // namespace

TEST_CASE("PLY reader: ascii and binary, float vertices, extra properties", "[mesh_io]") {
    const std::string dir = make_test_dir("plyvariants");
    SECTION("ascii with extra element and properties") {
        const std::string path = dir + "/a.ply";
        pqdc_test::write_file(path,
             "ply\r\nformat ascii 1.0\r\ncomment hi\r\n"
             "element vertex 4\r\nproperty float x\r\nproperty float y\r\nproperty float z\r\n"
             "property uchar red\r\n"
             "element face 2\r\nproperty list uchar int vertex_indices\r\nproperty int flags\r\n"
             "element edge 1\r\nproperty int vertex1\r\nproperty int vertex2\r\n"
             "end_header\r\n"
             "0 0 0 255\r\n1 0 0 0\r\n1.25 1 0 0\r\n0 1 -0.5 0\r\n"
             "3 0 1 2 7\r\n4 0 1 2 3 7\r\n"
             "0 1\r\n");
        const pqdc::Mesh m = pqdc::read_mesh(path);
        REQUIRE(m.points.size() == 4);
        CHECK(m.points[2] == openvdb::Vec3d(1.25, 1, 0));
        CHECK(m.points[3] == openvdb::Vec3d(0, 1, -0.5));
        REQUIRE(m.triangles.size() == 1);
        REQUIRE(m.quads.size() == 1);
        CHECK(m.quads[0] == openvdb::Vec4I(0, 1, 2, 3));
    }
    SECTION("binary little endian, float vertices, int vertex_index with uint count") {
        const std::string path = dir + "/b.ply";
        std::string s =
            "ply\nformat binary_little_endian 1.0\n"
            "element vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty float confidence\n"
            "element face 1\nproperty uchar flags\nproperty list uint uint vertex_index\n"
            "end_header\n";
        const float verts[3][4] = {{0.f, 0.f, 0.f, 1.f}, {0.1f, 0.f, 0.f, 1.f}, {0.f, 1.f, 2.f, 1.f}};
        for (const auto& v : verts)
            for (float x : v) put(s, x);
        put(s, std::uint8_t(9));
        put(s, std::uint32_t(3));
        for (std::uint32_t i : {2u, 1u, 0u}) put(s, i);
        pqdc_test::write_file(path, s);
        const pqdc::Mesh m = pqdc::read_mesh(path);
        REQUIRE(m.points.size() == 3);
        CHECK(m.points[1][0] == static_cast<double>(0.1f));
        REQUIRE(m.triangles.size() == 1);
        CHECK(m.triangles[0] == openvdb::Vec3I(2, 1, 0));
    }
}

TEST_CASE("malformed PLY files throw input_error naming the path", "[mesh_io]") {
    const std::string dir = make_test_dir("badply");
    const std::string path = dir + "/bad.ply";
    const std::string head =
        "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty double x\nproperty double y\n"
        "property double z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
    std::string good = head;
    for (int i = 0; i < 9; ++i) put(good, double(i));
    put(good, std::uint8_t(3));
    for (std::int32_t i : {0, 1, 2}) put(good, i);
    pqdc_test::write_file(path, good);
    REQUIRE(pqdc::read_mesh(path).triangles.size() == 1);

    std::string out_of_range = good;
    out_of_range[out_of_range.size() - 4] = 3;  // last index 2 -> 3
    const std::string cases[] = {
        good.substr(0, good.size() - 3),                                       // truncated data
        good.substr(0, 20),                                                    // truncated header
        out_of_range,                                                          // index >= vertex count
        "plx\n" + good.substr(4),                                              // bad magic
        "ply\nformat binary_big_endian 1.0\n" + good.substr(good.find("element")),  // unsupported
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n0 0\n",  // no z
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
        "end_header\n0 0 q\n",                                                 // not a number
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
        "end_header\n0 0 0 0\n",                                               // too many values
        "ply\nformat ascii 1.0\nelement vertex 99999999999\nproperty float x\nproperty float y\n"
        "property float z\nend_header\n0 0 0\n",                               // absurd count
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n",
        // Faces as triangle strips: skipped, they left an empty mesh read without a word.
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
        "element tristrips 1\nproperty list int int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
    };
    for (const std::string& c : cases) {
        pqdc_test::write_file(path, c);
        INFO(c.substr(0, 80));
        CHECK_THROWS_AS(pqdc::read_mesh(path), pqdc::input_error);
        CHECK_THROWS_WITH(pqdc::read_mesh(path), Catch::Contains(path));
    }
}

TEST_CASE("OFF reader: known small files and Geomview/CGAL variants", "[mesh_io]") {
    const std::string dir = make_test_dir("offvariants");
    const std::string path = dir + "/v.off";
    const openvdb::Vec3d square[4] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};

    SECTION("triangles, a quad and a pentagon; comments and blank lines") {
        pqdc_test::write_file(path,
             "# made by hand\n"
             "OFF\n"
             "\n"
             "5 3 0   # vertices faces edges\n"
             "0 0 0\n1 0 0\n1 1 0\n0 1 0\n"
             "\n"
             "-0.5 +0.5 2.5e-1  # a comment right after the numbers\n"
             "3 0 1 2\n"
             "4 0 1 2 3\n"
             "5 4 0 1 2 3\n");  // pentagon: fan around its first vertex
        const pqdc::Mesh m = pqdc::read_mesh(path);
        REQUIRE(m.points.size() == 5);
        for (int i = 0; i < 4; ++i) CHECK(m.points[static_cast<std::size_t>(i)] == square[i]);
        CHECK(m.points[4] == openvdb::Vec3d(-0.5, 0.5, 0.25));
        REQUIRE(m.triangles.size() == 1 + 3);
        CHECK(m.triangles[0] == openvdb::Vec3I(0, 1, 2));
        CHECK(m.triangles[1] == openvdb::Vec3I(4, 0, 1));
        CHECK(m.triangles[2] == openvdb::Vec3I(4, 1, 2));
        CHECK(m.triangles[3] == openvdb::Vec3I(4, 2, 3));
        REQUIRE(m.quads.size() == 1);
        CHECK(m.quads[0] == openvdb::Vec4I(0, 1, 2, 3));
    }
    SECTION("an n-gon gives the same faces from OFF and OBJ") {
        pqdc_test::write_file(path, "OFF\n6 1 0\n0 0 0\n1 0 0\n2 1 0\n1 2 0\n0 2 0\n-1 1 0\n6 0 1 2 3 4 5\n");
        const std::string obj = dir + "/v.obj";
        pqdc_test::write_file(obj, "v 0 0 0\nv 1 0 0\nv 2 1 0\nv 1 2 0\nv 0 2 0\nv -1 1 0\nf 1 2 3 4 5 6\n");
        const pqdc::Mesh from_off = pqdc::read_mesh(path);
        CHECK(from_off.triangles.size() == 4);
        require_same_mesh(from_off, pqdc::read_mesh(obj));
    }
    SECTION("COFF: vertex and face colors are skipped") {
        pqdc_test::write_file(path,
             "COFF\n4 2 0\n"
             "0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n1 1 0 0 0 255 255\n0 1 0 0.5 0.5 0.5 1\n"
             "3 0 1 2 255 255 0\n3 0 2 3 0.1 0.2 0.3 0.4\n");
        const pqdc::Mesh m = pqdc::read_mesh(path);
        REQUIRE(m.points.size() == 4);
        for (int i = 0; i < 4; ++i) CHECK(m.points[static_cast<std::size_t>(i)] == square[i]);
        REQUIRE(m.triangles.size() == 2);
        CHECK(m.triangles[1] == openvdb::Vec3I(0, 2, 3));
    }
    SECTION("NOFF and STCNOFF: normals and texture coordinates are skipped; CRLF") {
        pqdc_test::write_file(path, "NOFF\r\n3 1 0\r\n0 0 0 0 0 1\r\n1 0 0 0 0 1\r\n1 1 0 0 0 1\r\n3 0 1 2\r\n");
        const pqdc::Mesh n = pqdc::read_mesh(path);
        REQUIRE(n.points.size() == 3);
        CHECK(n.points[2] == square[2]);
        CHECK(n.triangles.size() == 1);
        pqdc_test::write_file(path, "STCNOFF\n3 1 0\n0 0 0 0 0 1 1 0 0 1 0 0\n1 0 0 0 0 1 1 0 0 1 1 0\n1 1 0 0 0 1 1 0 0 1 1 1\n"
                   "3 2 1 0\n");
        const pqdc::Mesh st = pqdc::read_mesh(path);
        REQUIRE(st.points.size() == 3);
        CHECK(st.points[1] == square[1]);
        REQUIRE(st.triangles.size() == 1);
        CHECK(st.triangles[0] == openvdb::Vec3I(2, 1, 0));
    }
    SECTION("plain OFF is a stream of numbers: counts on the header line, lines broken anywhere") {
        pqdc_test::write_file(path, "OFF 3 1 0\n0 0 0 1 0\n0 1 1\n0\n3 0\n1 2\n");
        const pqdc::Mesh m = pqdc::read_mesh(path);
        REQUIRE(m.points.size() == 3);
        CHECK(m.points[1] == square[1]);
        CHECK(m.points[2] == square[2]);
        REQUIRE(m.triangles.size() == 1);
        CHECK(m.triangles[0] == openvdb::Vec3I(0, 1, 2));
    }
    SECTION("non-finite coordinates are read, as write_mesh writes them and OBJ and PLY read them") {
        pqdc::Mesh odd;
        odd.points = {{std::nan(""), 0, 0}, {1, 0, 0}, {0, 1, 0}};
        odd.triangles = {{0, 1, 2}};
        pqdc::write_mesh(odd, path);
        CHECK(std::isnan(pqdc::read_mesh(path).points.at(0)[0]));
        pqdc_test::write_file(path, "OFF\n3 1 0\n0 0 0\n1 inf 0\n0 1 -INF\n3 0 1 2\n");
        const pqdc::Mesh m = pqdc::read_mesh(path);
        REQUIRE(m.points.size() == 3);
        CHECK(m.points[1][1] == HUGE_VAL);
        CHECK(m.points[2][2] == -HUGE_VAL);
    }
    SECTION("whole-number counts written as decimals, no faces, trailing data ignored") {
        pqdc_test::write_file(path, "OFF\n3.0 0 0e0\n0 0 0\n1 0 0\n0 1 0\nanything after the last face\n");
        const pqdc::Mesh m = pqdc::read_mesh(path);
        CHECK(m.points.size() == 3);
        CHECK(m.face_count() == 0);
    }
}

TEST_CASE("malformed OFF files throw input_error naming path, line and problem", "[mesh_io]") {
    const std::string dir = make_test_dir("badoff");
    const std::string path = dir + "/bad.off";
    const std::string tri = "3 1 0\n0 0 0\n1 0 0\n0 1 0\n";
    struct Case {
        std::string text;
        std::string where;  // "line N", or "" for errors about the whole file
        std::string what;
    };
    const Case cases[] = {
        {"", "", "the file has no data (empty or only comments)"},
        {"# only a comment\n\n", "", "the file has no data"},
        {"OFX\n" + tri + "3 0 1 2\n", "line 1", "not an OFF file (first word 'OFX', expected OFF, COFF, NOFF...)"},
        {"ply\n", "line 1", "not an OFF file (first word 'ply'"},
        {"# comment\nCXOFF\n" + tri + "3 0 1 2\n", "line 2", "not an OFF file (first word 'CXOFF')"},
        {"4OFF\n3 1 0\n0 0 0 0\n1 0 0 0\n0 1 0 0\n3 0 1 2\n", "line 1",
         "'4OFF': only 3D OFF files are supported (no 4OFF/nOFF)"},
        {"nOFF\n4\n3 1 0\n", "line 1", "'nOFF': only 3D OFF files are supported"},
        {"OFF BINARY\n", "line 1", "binary OFF is not supported"},
        {"OFF\n3.5 1 0\n", "line 2", "expected the vertex count (a whole number >= 0), found '3.5'"},
        {"OFF\n3 -1 0\n", "line 2", "expected the face count (a whole number >= 0), found '-1'"},
        {"OFF\n99999999999 1 0\n", "line 2", "the vertex count 99999999999 is more than the 1e9 this reader takes"},
        {"OFF\n3 1 x\n", "line 2", "expected the edge count, found 'x'"},
        {"OFF\n3 1\n", "line 2", "file ends before the edge count"},
        {"OFF\n" + tri + "2 0 1\n", "line 6", "face 0 has 2 vertices (need >= 3)"},
        {"OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 3\n", "line 7", "face 1 uses vertex 3 but there are only 3"},
        {"OFF\n" + tri + "3 0 1 1.5\n", "line 6", "expected a vertex index (a whole number >= 0), found '1.5'"},
        {"OFF\n3 1 0\n0 0 0\n1 0 0\n", "line 4", "file ends before a vertex coordinate"},
        {"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1", "line 5", "file ends before a vertex coordinate"},
        {"OFF\n" + tri + "3 0 1\n\n", "line 7", "file ends before a vertex index"},  // the last line
        {"OFF\n" + tri, "line 5", "file ends before a face's vertex count"},
        {"OFF\n3 1 0\n0 0 0\n1 0 -1e999\n0 1 0\n3 0 1 2\n", "line 4", "expected a vertex coordinate, found '-1e999'"},
        {"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 z\n3 0 1 2\n", "line 5", "expected a vertex coordinate, found 'z'"},
    };
    for (const Case& c : cases) {
        pqdc_test::write_file(path, c.text);
        INFO(c.text);
        CHECK_THROWS_AS(pqdc::read_mesh(path), pqdc::input_error);
        const std::string prefix = "cannot read OFF '" + path + "'" + (c.where.empty() ? "" : " " + c.where) + ": ";
        CHECK_THROWS_WITH(pqdc::read_mesh(path), Catch::StartsWith(prefix + c.what));
    }
    CHECK_THROWS_AS(pqdc::read_mesh(dir + "/missing.off"), pqdc::input_error);
    CHECK_THROWS_WITH(pqdc::read_mesh(dir + "/missing.off"),
                      Catch::Contains("missing.off") && Catch::Contains("No such file or directory"));
}

TEST_CASE("mesh_file_face_count: the header's face count, or nothing when it cannot be trusted", "[mesh_io]") {
    const std::string dir = make_test_dir("facecount");
    const pqdc::Mesh m = random_mesh(11, 40, 30, 7);
    SECTION("what pqdc writes: PLY (float and double), OFF, binary STL; OBJ has no count") {
        pqdc::MeshWriteOptions doubles;
        doubles.precision = pqdc::VertexPrecision::float64;
        pqdc::write_mesh(m, dir + "/m.ply");
        pqdc::write_mesh(m, dir + "/d.ply", doubles);
        pqdc::write_mesh(m, dir + "/m.off");
        pqdc::write_mesh(m, dir + "/m.stl");
        pqdc::write_mesh(m, dir + "/m.obj");
        for (const char* name : {"/m.ply", "/d.ply", "/m.off"}) {
            CAPTURE(name);
            CHECK(pqdc::mesh_file_face_count(dir + name) == std::optional<std::uint64_t>(37));
        }
        CHECK(pqdc::mesh_file_face_count(dir + "/m.stl") == std::optional<std::uint64_t>(30 + 2 * 7));
        CHECK_FALSE(pqdc::mesh_file_face_count(dir + "/m.obj").has_value());
        // A lower bound on what read_mesh gives (quads as two triangles, as decimate counts them).
        for (const char* name : {"/m.ply", "/m.off", "/m.stl"}) {
            const pqdc::Mesh r = pqdc::read_mesh(dir + name);
            CHECK(*pqdc::mesh_file_face_count(dir + name) <= r.triangles.size() + 2 * r.quads.size());
        }
    }
    SECTION("other writers' headers: ascii PLY with comments and extra elements, OFF after comments") {
        pqdc_test::write_file(dir + "/a.ply",
                              "ply\r\nformat ascii 1.0\r\ncomment hi\r\n"
                              "element vertex 4\r\nproperty float x\r\nproperty float y\r\nproperty float z\r\n"
                              "element face 2\r\nproperty list uchar int vertex_indices\r\n"
                              "element edge 1\r\nproperty int vertex1\r\nproperty int vertex2\r\n"
                              "end_header\r\n0 0 0\r\n1 0 0\r\n1 1 0\r\n0 1 0\r\n3 0 1 2\r\n4 0 1 2 3\r\n0 1");
        CHECK(pqdc::mesh_file_face_count(dir + "/a.ply") == std::optional<std::uint64_t>(2));
        pqdc_test::write_file(dir + "/c.off", "# made by hand\nCOFF 3 1 0\n0 0 0 1 1 1 1\n1 0 0 1 1 1 1\n0 1 0 1 1 1 1\n3 0 1 2\n");
        CHECK(pqdc::mesh_file_face_count(dir + "/c.off") == std::optional<std::uint64_t>(1));
    }
    SECTION("counts the file cannot hold, broken headers and ASCII STL give nothing") {
        // Trusted, the first two would be refused for their memory; read_mesh
        // says what is wrong with each instead.
        pqdc_test::write_file(dir + "/big.ply",
                              "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
                              "property float y\nproperty float z\nelement face 4000000000\n"
                              "property list uchar int vertex_indices\nend_header\n0123456789");
        pqdc_test::write_file(dir + "/big.off", "OFF\n3 900000000 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
        pqdc_test::write_file(dir + "/open.ply", "ply\nformat ascii 1.0\nelement face 5\n");
        pqdc_test::write_file(dir + "/be.ply", "ply\nformat binary_big_endian 1.0\nelement face 1\nend_header\n");
        pqdc_test::write_file(dir + "/a.stl", "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n"
                                             "vertex 0 1 0\nendloop\nendfacet\nendsolid t\n");
        pqdc_test::write_file(dir + "/short.stl", std::string(84, '\0') + "x");
        for (const char* name : {"/big.ply", "/big.off", "/open.ply", "/be.ply", "/short.stl"}) {
            CAPTURE(name);
            CHECK_FALSE(pqdc::mesh_file_face_count(dir + name).has_value());
            CHECK_THROWS_AS(pqdc::read_mesh(dir + name), pqdc::input_error);
        }
        CHECK_FALSE(pqdc::mesh_file_face_count(dir + "/a.stl").has_value());  // ASCII STL: no count
        CHECK(pqdc::read_mesh(dir + "/a.stl").triangles.size() == 1);
    }
    SECTION("a file that cannot be opened is an input_error naming it") {
        CHECK_THROWS_WITH(pqdc::mesh_file_face_count(dir + "/missing.ply"), Catch::Contains("missing.ply"));
        CHECK_THROWS_AS(pqdc::mesh_file_face_count(dir + "/missing.ply"), pqdc::input_error);
    }
}

TEST_CASE("mesh_file_face_count on every truncation and byte flip of a file: never more than read_mesh gives",
          "[mesh_io]") {
    // Hostile headers must neither crash the early count nor make it claim
    // more faces than a successful read holds (it is a lower bound).
    const std::string dir = make_test_dir("facecount_sweep");
    const pqdc::Mesh m = random_mesh(5, 12, 9, 3);
    for (const char* name : {"/s.ply", "/s.off", "/s.stl"}) {
        CAPTURE(name);
        pqdc::write_mesh(m, dir + name);
        const std::string good = pqdc_test::read_file(dir + name);
        std::vector<std::string> variants;
        for (std::size_t n = 0; n < good.size(); n += 3) variants.push_back(good.substr(0, n));
        pqdc_test::Random rng(17);
        pqdc_test::UniformInt at{0, int(std::min<std::size_t>(good.size(), 200)) - 1}, bit{0, 7};
        for (int k = 0; k < 300; ++k) {
            std::string flipped = good;
            flipped[std::size_t(at(rng))] ^= char(1 << bit(rng));
            variants.push_back(flipped);
        }
        std::size_t counted = 0;
        for (const std::string& v : variants) {
            const std::string path = dir + "/v" + (name + 2);  // v.ply, v.off, v.stl
            pqdc_test::write_file(path, v);
            const auto faces = pqdc::mesh_file_face_count(path);
            if (!faces) continue;
            ++counted;
            try {
                const pqdc::Mesh r = pqdc::read_mesh(path);
                CHECK(*faces <= r.triangles.size() + 2 * r.quads.size());
            } catch (const pqdc::input_error&) {
                // a count from a header whose file then fails to read: the reader's message stands
            }
        }
        CHECK(counted > 0);
    }
}
