// MeshStreamWriter writes, from pieces, exactly the bytes write_mesh writes
// from the whole mesh, and fails like it: no output, no scratch left behind;
// so does finish(group) from the parts several ranks (threads here) hold.
#include "test_files.hpp"
#include "random.hpp"
#include "thread_ranks.hpp"
#include "pqdc/mesh_stream.hpp"

#include "io/temporary_files.hpp"
#include "pqdc/exceptions.hpp"
#include "pqdc/file_io.hpp"

#include <catch2/catch.hpp>

#include <algorithm>
#include <atomic>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <string>
#include <vector>

namespace fs = std::filesystem;

namespace {

std::string fresh_dir(const std::string& name) {
    const fs::path dir = fs::path(PQDC_BINARY_DIR) / "test_output" / ("mesh_stream_" + name);
    fs::remove_all(dir);
    fs::create_directories(dir);
    return dir.string();
}

std::vector<std::string> entries(const std::string& dir) {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(dir)) names.push_back(e.path().filename().string());
    std::sort(names.begin(), names.end());
    return names;
}

pqdc::Mesh random_mesh(std::uint32_t seed, std::size_t points, std::size_t tris, std::size_t quads, bool normals) {
    pqdc_test::Random rng(seed);
    pqdc_test::UniformReal mantissa{-1.0, 1.0};
    pqdc_test::UniformInt exponent{-20, 20};
    pqdc::Mesh m;
    for (std::size_t i = 0; i < points; ++i) {
        openvdb::Vec3d p, n;
        for (int k = 0; k < 3; ++k) p[k] = std::ldexp(mantissa(rng), exponent(rng));
        for (int k = 0; k < 3; ++k) n[k] = mantissa(rng);
        m.points.push_back(p);
        if (normals) m.normals.push_back(n);
    }
    pqdc_test::UniformInt idx{0, int(points) - 1};
    for (std::size_t i = 0; i < tris; ++i) m.triangles.emplace_back(idx(rng), idx(rng), idx(rng));
    for (std::size_t i = 0; i < quads; ++i) m.quads.emplace_back(idx(rng), idx(rng), idx(rng), idx(rng));
    return m;
}

/// `m` cut into `parts` pieces: points, triangles and quads each split at
/// their own random places, so a piece's faces refer to earlier, own and
/// later pieces' vertices alike.
std::vector<pqdc::Mesh> pieces_of(const pqdc::Mesh& m, int parts, std::uint32_t seed) {
    pqdc_test::Random rng(seed);
    auto cuts = [&](std::size_t n) {
        std::vector<std::size_t> c{0, n};
        pqdc_test::UniformInt at{0, int(n)};
        for (int i = 1; i < parts; ++i) c.push_back(std::size_t(at(rng)));
        std::sort(c.begin(), c.end());
        return c;
    };
    const auto pc = cuts(m.points.size()), tc = cuts(m.triangles.size()), qc = cuts(m.quads.size());
    std::vector<pqdc::Mesh> out(static_cast<std::size_t>(parts));
    for (int i = 0; i < parts; ++i) {
        pqdc::Mesh& p = out[std::size_t(i)];
        p.points.assign(m.points.begin() + long(pc[i]), m.points.begin() + long(pc[i + 1]));
        if (!m.normals.empty())
            p.normals.assign(m.normals.begin() + long(pc[i]), m.normals.begin() + long(pc[i + 1]));
        p.triangles.assign(m.triangles.begin() + long(tc[i]), m.triangles.begin() + long(tc[i + 1]));
        p.quads.assign(m.quads.begin() + long(qc[i]), m.quads.begin() + long(qc[i + 1]));
    }
    return out;
}

}  // namespace

TEST_CASE("streamed meshes are byte-identical to write_mesh in every format and precision", "[mesh_stream]") {
    const std::string dir = fresh_dir("bytes");
    const char* extensions[] = {".obj", ".ply", ".off", ".stl"};
    std::uint32_t seed = 1;
    for (bool normals : {false, true})
        for (auto precision : {pqdc::VertexPrecision::float32, pqdc::VertexPrecision::float64})
            for (int parts : {1, 2, 7})
                for (const char* ext : extensions) {
                    INFO("format " << ext << ", normals " << normals << ", double " << (precision == pqdc::VertexPrecision::float64)
                                   << ", pieces " << parts);
                    const pqdc::Mesh m = random_mesh(seed++, 300, 250, 120, normals);
                    pqdc::MeshWriteOptions options;
                    options.precision = precision;
                    const std::string whole = dir + "/whole" + ext, streamed = dir + "/streamed" + ext;
                    pqdc::write_mesh(m, whole, options);
                    double last = -1;
                    options.progress = [&](double f) {
                        CHECK(f >= last);
                        last = f;
                    };
                    pqdc::MeshStreamWriter writer(streamed, options, normals);
                    for (const pqdc::Mesh& piece : pieces_of(m, parts, seed)) writer.append(piece);
                    CHECK(writer.point_count() == m.points.size());
                    CHECK(writer.triangle_count() == m.triangles.size());
                    CHECK(writer.quad_count() == m.quads.size());
                    writer.finish();
                    CHECK(last == 1.0);
                    const std::string a = pqdc_test::read_file(whole), b = pqdc_test::read_file(streamed);
                    CHECK(a.size() > 100);
                    CHECK(a == b);
                }
    CHECK(entries(dir).size() == 8);  // the two files of each format, no scratch
}

TEST_CASE("a streamed empty mesh and pieces without faces or points match write_mesh", "[mesh_stream]") {
    const std::string dir = fresh_dir("empty");
    for (const char* ext : {".obj", ".ply", ".off", ".stl"}) {
        INFO(ext);
        pqdc::write_mesh(pqdc::Mesh{}, dir + "/a" + ext);
        pqdc::MeshStreamWriter(dir + "/unused" + ext);  // never finished: nothing written
        {
            pqdc::MeshStreamWriter w(dir + "/b" + ext);
            w.append(pqdc::Mesh{});
            w.finish();
        }
        CHECK(pqdc_test::read_file(dir + "/a" + ext) == pqdc_test::read_file(dir + "/b" + ext));
        {
            // Opened with normals, as pqdc --vertex-normals does, and no
            // point came: an empty mesh has no normals to declare (the
            // in-core run writes the same Mesh{}); PLY declared nx/ny/nz.
            pqdc::MeshStreamWriter w(dir + "/e" + ext, {}, true);
            w.append(pqdc::Mesh{});
            w.finish();
        }
        CHECK(pqdc_test::read_file(dir + "/a" + ext) == pqdc_test::read_file(dir + "/e" + ext));
        // Points first, faces in a later piece.
        pqdc::Mesh m = random_mesh(7, 20, 10, 5, false), points_only = m, faces_only = m;
        points_only.triangles.clear();
        points_only.quads.clear();
        faces_only.points.clear();
        pqdc::write_mesh(m, dir + "/c" + ext);
        pqdc::MeshStreamWriter w(dir + "/d" + ext);
        w.append(points_only);
        w.append(faces_only);
        w.finish();
        CHECK(pqdc_test::read_file(dir + "/c" + ext) == pqdc_test::read_file(dir + "/d" + ext));
    }
    CHECK(entries(dir).size() == 20);
}

TEST_CASE("streamed writes fail like write_mesh: clear errors, old file intact, nothing left", "[mesh_stream]") {
    const std::string dir = fresh_dir("errors");
    const std::string target = dir + "/out.ply";
    {
        std::ofstream(target) << "old";
    }
    pqdc::Mesh m = random_mesh(3, 10, 4, 2, false);
    SECTION("an index beyond the final vertex count names the face") {
        pqdc::MeshStreamWriter w(target);
        w.append(m);
        pqdc::Mesh more;
        more.triangles.emplace_back(0, 1, 10);  // vertex 10 of 10
        w.append(more);
        CHECK_THROWS_WITH(w.finish(), Catch::Contains("out.ply") && Catch::Contains("triangle 4") &&
                                          Catch::Contains("vertex 10") && Catch::Contains("only 10 points"));
        CHECK_THROWS_AS(w.append(m), pqdc::io_error);  // a failed writer only discards
    }
    SECTION("a later piece can supply the vertices a face refers to") {
        pqdc::Mesh faces_first;
        faces_first.quads.emplace_back(0, 1, 2, 3);
        pqdc::Mesh points;
        points.points.assign(4, openvdb::Vec3d(1.0));
        pqdc::MeshStreamWriter w(target);
        w.append(faces_first);
        w.append(points);
        w.finish();
        CHECK(pqdc_test::read_file(target).find("element face 1") != std::string::npos);
    }
    SECTION("normals of the wrong count and float overflow are input errors") {
        pqdc::MeshStreamWriter w(target, {}, /*with_normals=*/true);
        CHECK_THROWS_AS(w.append(m), pqdc::input_error);
        pqdc::MeshStreamWriter f(target);
        pqdc::Mesh big;
        big.points.push_back(openvdb::Vec3d(0.0, 1e300, 0.0));
        CHECK_NOTHROW(f.append(m));
        CHECK_THROWS_WITH(f.append(big), Catch::Contains("vertex 10") && Catch::Contains("beyond float's range"));
    }
    SECTION("standard output needs a format, a format needs a known extension") {
        CHECK_THROWS_AS(pqdc::MeshStreamWriter("-"), pqdc::option_error);
        CHECK_THROWS_AS(pqdc::MeshStreamWriter(dir + "/x.xyz"), pqdc::option_error);
        CHECK_THROWS_AS(pqdc::MeshStreamWriter(dir + "/missing/x.ply"), pqdc::io_error);
    }
    SECTION("a writer dropped before finish leaves the old file") {
        pqdc::MeshStreamWriter w(target);
        w.append(m);
    }
    const std::vector<std::string> left = entries(dir);
    CHECK(left == std::vector<std::string>{"out.ply"});
}

namespace {

const pqdc::PartTransfer kTransfers[] = {pqdc::PartTransfer::shared_file, pqdc::PartTransfer::through_root};

/// finish(group) on thread ranks, rank r appending parts[r] (a piece that
/// fails to append is dropped, the writer then broken); returns each rank's
/// exception message, or "" when it returned with the whole file's point
/// count `points` (checked here, outside the threads: Catch2 v2's
/// assertions are not thread-safe).
std::vector<std::string> finish_on_ranks(const std::vector<std::vector<pqdc::Mesh>>& parts, const std::string& path,
                                         bool normals, pqdc::PartTransfer transfer, std::uint64_t points = 0) {
    std::vector<std::uint64_t> counted(parts.size());
    std::vector<std::string> errors =
        pqdc_test::ThreadRanks(int(parts.size())).run<std::string>([&](pqdc::RankGroup& group) -> std::string {
            pqdc::MeshStreamWriter w(path, {}, normals);
            try {
                for (const pqdc::Mesh& piece : parts[std::size_t(group.rank())]) w.append(piece);
            } catch (const std::exception&) {
            }
            try {
                w.finish(group, transfer);
            } catch (const std::exception& e) {
                return e.what();
            }
            counted[std::size_t(group.rank())] = w.point_count();
            return {};
        });
    for (std::size_t r = 0; r < parts.size(); ++r)
        if (errors[r].empty()) CHECK(counted[r] == points);
    return errors;
}

}  // namespace

TEST_CASE("the parts of several ranks joined by finish(group) are write_mesh's bytes, by either transfer",
          "[mesh_stream]") {
    const std::string dir = fresh_dir("ranks");
    std::uint32_t seed = 100;
    for (pqdc::PartTransfer transfer : kTransfers)
        for (int ranks : {2, 3})
            for (const char* ext : {".obj", ".ply", ".off"})
                for (bool normals : {false, true}) {
                    INFO("format " << ext << ", " << ranks << " ranks, normals " << normals << ", through root "
                                   << (transfer == pqdc::PartTransfer::through_root));
                    const pqdc::Mesh m = random_mesh(seed++, 400, 300, 150, normals);
                    pqdc::write_mesh(m, dir + "/whole" + ext);
                    // Two pieces per rank; on three ranks rank 1's part is empty.
                    const std::vector<pqdc::Mesh> cut = pieces_of(m, 2 * ranks, seed);
                    std::vector<std::vector<pqdc::Mesh>> parts(static_cast<std::size_t>(ranks));
                    for (std::size_t i = 0; i < cut.size(); ++i)
                        parts[ranks == 3 && i / 2 == 1 ? 0 : i / 2].push_back(cut[i]);
                    const std::vector<std::string> errors =
                        finish_on_ranks(parts, dir + "/joined" + ext, normals, transfer, m.points.size());
                    CHECK(errors == std::vector<std::string>(std::size_t(ranks)));
                    CHECK(pqdc_test::read_file(dir + "/whole" + ext) == pqdc_test::read_file(dir + "/joined" + ext));
                }
    // Files shorter than the token rank 0 stamps to prove the file is shared.
    for (const char* ext : {".obj", ".ply", ".off"})
        for (pqdc::PartTransfer transfer : kTransfers) {
            INFO("empty " << ext);
            pqdc::write_mesh(pqdc::Mesh{}, dir + "/whole" + ext);
            CHECK(finish_on_ranks({{}, {}}, dir + "/joined" + ext, false, transfer) == std::vector<std::string>(2));
            CHECK(pqdc_test::read_file(dir + "/whole" + ext) == pqdc_test::read_file(dir + "/joined" + ext));
        }
    CHECK(entries(dir) ==
          std::vector<std::string>{"joined.obj", "joined.off", "joined.ply", "whole.obj", "whole.off", "whole.ply"});
}

TEST_CASE("finish(group) fails on every rank together and leaves the old file", "[mesh_stream]") {
    const std::string dir = fresh_dir("ranks_errors");
    const std::string target = dir + "/out.ply";
    {
        std::ofstream(target) << "old";
    }
    const pqdc::Mesh m = random_mesh(5, 10, 4, 2, false);
    for (pqdc::PartTransfer transfer : kTransfers) {
        INFO("through root " << (transfer == pqdc::PartTransfer::through_root));
        // An index beyond every part's vertices names the face's number in the whole file.
        pqdc::Mesh bad;
        bad.triangles.emplace_back(0, 1, 20);  // vertex 20 of 20
        for (const std::string& e : finish_on_ranks({{m}, {m, bad}}, target, false, transfer))
            CHECK_THAT(e, Catch::Contains("out.ply") && Catch::Contains("triangle 8") && Catch::Contains("vertex 20") &&
                              Catch::Contains("only 20 points"));
        // A rank whose part failed earlier (a coordinate beyond float's range) fails every rank.
        pqdc::Mesh big;
        big.points.push_back(openvdb::Vec3d(0.0, 1e300, 0.0));
        for (const std::string& e : finish_on_ranks({{m}, {m}, {big}}, target, false, transfer))
            CHECK_THAT(e, Catch::Contains("rank 2") && Catch::Contains("out.ply"));
        // STL pieces must all be on rank 0.
        for (const std::string& e : finish_on_ranks({{m}, {m}}, dir + "/out.stl", false, transfer))
            CHECK_THAT(e, Catch::Contains("STL pieces must all be on rank 0"));
        CHECK(finish_on_ranks({{m}, {}}, dir + "/out.stl", false, transfer, m.points.size()) ==
              std::vector<std::string>(2));
        pqdc::write_mesh(m, dir + "/whole.stl");
        CHECK(pqdc_test::read_file(dir + "/whole.stl") == pqdc_test::read_file(dir + "/out.stl"));
        fs::remove(dir + "/whole.stl");
        fs::remove(dir + "/out.stl");
    }
    CHECK(pqdc_test::read_file(target) == "old");
    CHECK(entries(dir) == std::vector<std::string>{"out.ply"});
}

namespace {

/// A rank group that calls `before_call` (on the calling rank's thread)
/// ahead of every collective call it forwards.
class WatchedGroup final : public pqdc::RankGroup {
public:
    WatchedGroup(pqdc::RankGroup& inner, std::function<void(int rank)> before_call)
        : inner_(inner), before_call_(std::move(before_call)) {}
    int rank() const override { return inner_.rank(); }
    int size() const override { return inner_.size(); }
    std::vector<std::string> gather_at_root(std::string part) override {
        before_call_(rank());
        return inner_.gather_at_root(std::move(part));
    }
    std::string broadcast_from_root(std::string value) override {
        before_call_(rank());
        return inner_.broadcast_from_root(std::move(value));
    }
    void send_to_root(std::string message) override {
        before_call_(rank());
        inner_.send_to_root(std::move(message));
    }
    std::string receive_from(int from) override {
        before_call_(rank());
        return inner_.receive_from(from);
    }

private:
    pqdc::RankGroup& inner_;
    std::function<void(int)> before_call_;
};

bool has_temporary(const std::string& dir) {
    for (const std::string& name : entries(dir))
        if (name.find(".tmp-") != std::string::npos) return true;
    return false;
}

}  // namespace

// pqdc-mpi's ranks call pqdc::remove_temporary_files() from their signal
// handler: when mpirun ends the job because a rank was killed outright, the
// shared temporary file must not stay behind (tests/mpi/run.sh kills a rank).
TEST_CASE("remove_temporary_files removes the shared file of finish(group) while the ranks write it",
          "[mesh_stream]") {
    const std::string dir = fresh_dir("ranks_removed");
    const std::string target = dir + "/out.ply";
    {
        std::ofstream(target) << "old";
    }
    const pqdc::Mesh m = random_mesh(7, 400, 300, 150, false);
    std::atomic<bool> removed{false};
    std::atomic<int> listed_when_removed{0};
    const std::vector<std::string> errors =
        pqdc_test::ThreadRanks(2).run<std::string>([&](pqdc::RankGroup& threads) -> std::string {
            // Rank 1 plays the signal handler of a rank whose peer was killed:
            // the first time it reaches a collective call with the file there.
            WatchedGroup group(threads, [&](int rank) {
                if (rank != 1 || removed || !has_temporary(dir)) return;
                listed_when_removed = pqdc::detail::listed_temporary_files();
                pqdc::remove_temporary_files();
                removed = true;
            });
            pqdc::MeshStreamWriter w(target);
            w.append(m);
            try {
                w.finish(group, pqdc::PartTransfer::shared_file);
            } catch (const std::exception& e) {
                return e.what();
            }
            return {};
        });
    REQUIRE(removed);
    CHECK(listed_when_removed >= 1);
    for (const std::string& e : errors) CHECK_THAT(e, Catch::Contains("out.ply"));
    CHECK(pqdc_test::read_file(target) == "old");
    CHECK(entries(dir) == std::vector<std::string>{"out.ply"});
    CHECK(pqdc::detail::listed_temporary_files() == 0);

    // A finished run leaves nothing listed: a later signal removes no file.
    const std::vector<std::string> ok = pqdc_test::ThreadRanks(2).run<std::string>([&](pqdc::RankGroup& group) {
        pqdc::MeshStreamWriter w(target);
        w.append(m);
        w.finish(group, pqdc::PartTransfer::shared_file);
        return std::string();
    });
    CHECK(ok == std::vector<std::string>(2));
    CHECK(pqdc::detail::listed_temporary_files() == 0);
}

TEST_CASE("the list of temporary files: listed until released, long paths left off", "[mesh_stream]") {
    const std::string dir = fresh_dir("temporary_list");
    const auto make = [&](const std::string& name) {
        std::ofstream(dir + "/" + name) << "x";
        return dir + "/" + name;
    };
    const int before = pqdc::detail::listed_temporary_files();
    {
        pqdc::detail::TemporaryFileListing kept, released, relisted;
        kept.list(make("kept"));
        released.list(make("released"));
        released.release();
        relisted.list(make("first"));
        relisted.list(make("second"));  // the first is released
        pqdc::detail::TemporaryFileListing too_long;
        too_long.list(dir + "/" + std::string(5000, 'a'));
        CHECK(pqdc::detail::listed_temporary_files() == before + 2);
        pqdc::remove_temporary_files();
        CHECK(entries(dir) == std::vector<std::string>{"first", "released"});
    }
    CHECK(pqdc::detail::listed_temporary_files() == before);
}
