// Out-of-core and distributed meshing brick by brick (issue 14): the
// decomposition is a set of contiguous runs of the candidate list, brick
// trees hold the source's values, and extract_bricks and
// extract_distributed (ranks as threads here; MPI in tests/mpi) give the
// same bytes as extract for every brick size, thread count and rank count,
// from memory and from a delay-loaded file; extract_adaptive_bricks the
// same bytes as extract_adaptive.
#include "pqdc/adaptive.hpp"
#include "pqdc/brick_store.hpp"
#include "pqdc/bricks.hpp"
#include "pqdc/distributed.hpp"
#include "pqdc/exceptions.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/mesh_io.hpp"
#include "pqdc/mesh_stream.hpp"
#include "pqdc/noise.hpp"
#include "pqdc/procedural.hpp"
#include "pqdc/vertex_normals.hpp"
#include "pqdc/volume_io.hpp"

#include "lattice/candidates.hpp"
#include "bricks/brick_source.hpp"
#include "bricks/bricks.hpp"
#include "bricks/mapped_pages.hpp"
#include "scale/stream_scratch.hpp"
#include "ranks/rank_exchange.hpp"
#include "bricks/store_source.hpp"
#include "scale/stream_untangle.hpp"

#include "cli_runner.hpp"
#include "thread_ranks.hpp"

#include <catch2/catch.hpp>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Composite.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <tbb/global_control.h>

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

namespace {

struct Init {
    Init() { openvdb::initialize(); }
} init_openvdb;

using openvdb::Coord;
using openvdb::CoordBBox;

/// A directory of the test's own under the system temporary directory,
/// removed with everything in it when the test case ends, also when it fails.
class TempDir {
public:
    explicit TempDir(const std::string& name)
        : path_(std::filesystem::temp_directory_path() / ("pqdc-" + name + "-" + std::to_string(::getpid()))) {
        std::filesystem::remove_all(path_);
        std::filesystem::create_directories(path_);
    }
    ~TempDir() {
        std::error_code ignored;
        std::filesystem::remove_all(path_, ignored);
    }
    TempDir(const TempDir&) = delete;
    TempDir& operator=(const TempDir&) = delete;
    std::string path(const std::string& entry) const { return (path_ / entry).string(); }

private:
    std::filesystem::path path_;
};

/// True when the two vectors hold the same bytes. (memcmp on an empty
/// vector's data(), which may be null, is undefined even for 0 bytes.)
template <class T>
bool same_bytes(const std::vector<T>& a, const std::vector<T>& b) {
    return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

/// Byte equality of the whole mesh (points, triangles, quads), with a count
/// to tell an empty comparison from a real one.
void require_same_bytes(const pqdc::Mesh& a, const pqdc::Mesh& b) {
    REQUIRE(a.points.size() == b.points.size());
    REQUIRE(a.triangles.size() == b.triangles.size());
    REQUIRE(a.quads.size() == b.quads.size());
    REQUIRE(same_bytes(a.points, b.points));
    REQUIRE(same_bytes(a.triangles, b.triangles));
    REQUIRE(same_bytes(a.quads, b.quads));
    REQUIRE(same_bytes(a.normals, b.normals));
}

/// `mesh(b)` against `in_core` for brick sizes 128 and 4096.
template <class MeshWith>
void require_sizes_match(const pqdc::Mesh& in_core, const MeshWith& mesh) {
    for (int size : {128, 4096}) {
        INFO("brick size " << size);
        pqdc::BrickOptions b;
        b.brick_size = size;
        require_same_bytes(in_core, mesh(b));
    }
}

/// Rank 0's mesh of extract_distributed over `ranks` thread ranks, bricks of
/// 128; requires every other rank's mesh to be empty. `stats`: rank 0's.
template <class Input>
pqdc::Mesh distributed(const Input& input, const pqdc::ExtractOptions& options, int ranks,
                       pqdc::ExtractStats* stats = nullptr) {
    pqdc::BrickOptions b;
    b.brick_size = 128;
    const std::vector<pqdc::Mesh> meshes =
        pqdc_test::ThreadRanks(ranks).run<pqdc::Mesh>([&](pqdc::RankGroup& group) {
            return pqdc::extract_distributed(input, options, b, group, group.rank() == 0 ? stats : nullptr);
        });
    for (std::size_t r = 1; r < meshes.size(); ++r) REQUIRE(meshes[r].empty());
    return meshes[0];
}

/// The file's bytes ("" when it cannot be read).
std::string file_bytes(const std::string& path) {
    std::ifstream f(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
}

/// The counters a streamed run must report as the in-core run does.
void require_same_counts(const pqdc::ExtractStats& a, const pqdc::ExtractStats& b) {
    using S = pqdc::ExtractStats;
    for (std::uint64_t S::*count :
         {&S::vertices, &S::triangles, &S::quads, &S::active_cells, &S::crossing_edges, &S::boundary_crossings,
          &S::clamped_vertices, &S::multi_vertex_cells, &S::untangle_found, &S::untangle_moved,
          &S::untangle_snapped, &S::untangle_rounds})
        CHECK(a.*count == b.*count);
    CHECK(a.warnings == b.warnings);
    using C = pqdc::ComponentFilterStats;
    for (std::size_t C::*count : {&C::components, &C::removed_components, &C::removed_faces, &C::removed_points})
        CHECK(a.components.*count == b.components.*count);
    CHECK(a.components.largest_removed_diagonal_voxels == b.components.largest_removed_diagonal_voxels);
    CHECK(a.components.smallest_kept_diagonal_voxels == b.components.smallest_kept_diagonal_voxels);
}

/// The grid written as a brick store (bricks of 128) and meshed by the
/// streamed runs on a pqdc::BrickStore, which never assemble its topology:
/// `expected` (the in-core mesh's double-precision PLY) for brick sizes 128
/// and 256, 1 to 3 runs at once and 2 thread ranks, with the same counts.
void require_store_streamed_match(const openvdb::GridBase& grid, const pqdc::ExtractOptions& options,
                                  const std::string& expected, const pqdc::ExtractStats& in_core_stats,
                                  const TempDir& dir) {
    pqdc::BrickOptions split;
    split.brick_size = 128;
    std::filesystem::remove_all(dir.path("store"));
    pqdc::write_brick_store(grid, dir.path("store"), split);
    const pqdc::BrickStore store(dir.path("store"));
    pqdc::MeshWriteOptions wo;
    wo.precision = pqdc::VertexPrecision::float64;
    for (const auto& [size, runs] : {std::pair{128, 1}, std::pair{256, 0}, std::pair{128, 3}}) {
        INFO("store read file by file, brick size " << size << ", " << runs << " concurrent runs, assembled: "
                                                    << store.assembles_for(options));
        pqdc::BrickOptions b;
        b.brick_size = size;
        b.concurrent_runs = runs;
        pqdc::MeshStreamWriter out(dir.path("store.ply"), wo, options.vertex_normals);
        pqdc::ExtractStats s;
        pqdc::extract_bricks(store, options, b, out, {}, &s);
        out.finish();
        REQUIRE(file_bytes(dir.path("store.ply")) == expected);
        require_same_counts(in_core_stats, s);
    }
    INFO("store read file by file on 2 ranks");
    pqdc::BrickOptions b;
    b.brick_size = 128;
    std::vector<pqdc::ExtractStats> s(2);
    pqdc_test::ThreadRanks(2).run<int>([&](pqdc::RankGroup& group) {
        pqdc::MeshStreamWriter out(dir.path("store-ranks.ply"), wo, options.vertex_normals);
        pqdc::extract_distributed(store, options, b, group, out, {}, &s[std::size_t(group.rank())]);
        out.finish(group);
        return 0;
    });
    REQUIRE(file_bytes(dir.path("store-ranks.ply")) == expected);
    require_same_counts(in_core_stats, s[0]);
}

/// The streamed extract_bricks (to a MeshStreamWriter) writes the file
/// write_mesh writes of the in-core mesh, double-precision PLY (every bit
/// of every coordinate), for brick sizes 128 and 256 and 1 to 3 runs of
/// bricks at once, and counts the same; so does the streamed
/// extract_distributed on 2 and 3 ranks.
void require_streamed_match(const openvdb::GridBase& grid, const pqdc::ExtractOptions& options,
                            const pqdc::Mesh& in_core, const pqdc::ExtractStats& in_core_stats) {
    TempDir dir("streamed");
    pqdc::MeshWriteOptions wo;
    wo.precision = pqdc::VertexPrecision::float64;
    pqdc::write_mesh(in_core, dir.path("in_core.ply"), wo);
    const std::string expected = file_bytes(dir.path("in_core.ply"));
    // Brick size, and runs of bricks meshed at once (0: automatic, 2 on two cores).
    for (const auto& [size, runs] : {std::pair{128, 0}, std::pair{256, 1}, std::pair{128, 3}}) {
        INFO("streamed, brick size " << size << ", " << runs << " concurrent runs");
        pqdc::BrickOptions b;
        b.brick_size = size;
        b.concurrent_runs = runs;
        pqdc::MeshStreamWriter out(dir.path("streamed.ply"), wo, options.vertex_normals);
        std::uint64_t pieces = 0;
        pqdc::ExtractStats s;
        pqdc::extract_bricks(grid, options, b, out, [&](pqdc::Mesh&) { ++pieces; }, &s);
        out.finish();
        REQUIRE(pieces >= 1);
        REQUIRE(file_bytes(dir.path("streamed.ply")) == expected);
        require_same_counts(in_core_stats, s);
    }
    require_store_streamed_match(grid, options, expected, in_core_stats, dir);
    for (int ranks : {2, 3}) {
        // Each rank writes its part into the shared file, or (3 ranks) sends it to rank 0.
        const pqdc::PartTransfer transfer = ranks == 2 ? pqdc::PartTransfer::shared_file : pqdc::PartTransfer::through_root;
        INFO("streamed on " << ranks << " ranks, brick size 128");
        pqdc::BrickOptions b;
        b.brick_size = 128;
        std::vector<pqdc::ExtractStats> s(static_cast<std::size_t>(ranks));
        std::atomic<std::uint64_t> pieces{0};  // each rank counts its own pieces
        pqdc_test::ThreadRanks(ranks).run<int>([&](pqdc::RankGroup& group) {
            pqdc::MeshStreamWriter out(dir.path("distributed.ply"), wo, options.vertex_normals);
            pqdc::extract_distributed(grid, options, b, group, out, [&](pqdc::Mesh&) { ++pieces; },
                                      &s[std::size_t(group.rank())]);
            out.finish(group, transfer);
            return 0;
        });
        REQUIRE(pieces >= 1);
        REQUIRE(file_bytes(dir.path("distributed.ply")) == expected);
        require_same_counts(in_core_stats, s[0]);
    }
}

/// extract_bricks against extract for brick sizes 128, 256 and 4096 (all
/// threads) and 128 on one thread; extract_distributed on three ranks; for
/// grids also the streamed extract_bricks.
template <class Input>
void require_bricks_match(const Input& grid, const pqdc::ExtractOptions& options) {
    pqdc::ExtractStats in_core_stats;
    const pqdc::Mesh in_core = pqdc::extract(grid, options, &in_core_stats);
    REQUIRE(in_core.points.size() > 100);
    if constexpr (std::is_base_of_v<openvdb::GridBase, Input>) require_streamed_match(grid, options, in_core, in_core_stats);
    for (int size : {128, 256, 4096}) {
        INFO("brick size " << size);
        pqdc::BrickOptions b;
        b.brick_size = size;
        require_same_bytes(in_core, pqdc::extract_bricks(grid, options, b));
    }
    {
        INFO("three ranks, brick size 128");
        require_same_bytes(in_core, distributed(grid, options, 3));
    }
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    INFO("brick size 128, one thread");
    pqdc::BrickOptions b;
    b.brick_size = 128;
    require_same_bytes(in_core, pqdc::extract_bricks(grid, options, b));
}

openvdb::FloatGrid::Ptr sphere(double radius, const openvdb::Vec3f& centre, double band = 3.0) {
    return openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(float(radius), centre, 1.0f, float(band));
}

/// A level set of the box [lo, hi] (index space, voxel size 1): its faces
/// lie on lattice planes, so lattice points on them hold exactly 0.
openvdb::FloatGrid::Ptr box_level_set(const Coord& lo, const Coord& hi, float band = 3.0f) {
    auto grid = openvdb::FloatGrid::create(band);
    grid->setGridClass(openvdb::GRID_LEVEL_SET);
    auto acc = grid->getAccessor();
    const int w = int(std::ceil(band));
    for (int x = lo.x() - w; x <= hi.x() + w; ++x)
        for (int y = lo.y() - w; y <= hi.y() + w; ++y)
            for (int z = lo.z() - w; z <= hi.z() + w; ++z) {
                const Coord p(x, y, z);
                float inside = 1e9f, outside2 = 0;
                for (int a = 0; a < 3; ++a) {
                    inside = std::min(inside, float(std::min(p[a] - lo[a], hi[a] - p[a])));
                    const float d = float(std::max({lo[a] - p[a], p[a] - hi[a], 0}));
                    outside2 += d * d;
                }
                const float v = outside2 > 0 ? std::sqrt(outside2) : -inside;
                if (std::abs(v) < band) acc.setValue(p, v);
            }
    return grid;
}

TEST_CASE("bricks: extents are runs of whole level-1 nodes of the same volume", "[bricks]") {
    CHECK(pqdc::detail::brick_extent(128) == Coord(128));
    CHECK(pqdc::detail::brick_extent(256) == Coord(128, 128, 1024));
    CHECK(pqdc::detail::brick_extent(512) == Coord(128, 256, 4096));
    CHECK(pqdc::detail::brick_extent(1024) == Coord(128, 2048, 4096));
    CHECK(pqdc::detail::brick_extent(2048) == Coord(512, 4096, 4096));
    CHECK(pqdc::detail::brick_extent(4096) == Coord(4096));
    for (int s = 128; s <= 4096; s *= 2) {
        const Coord e = pqdc::detail::brick_extent(s);
        CHECK(double(e.x()) * e.y() * e.z() == double(s) * s * s);
    }
    pqdc::BrickOptions bad;
    for (int s : {0, 64, 100, 192, 8192}) {
        bad.brick_size = s;
        CHECK_THROWS_AS(pqdc::validate(bad), pqdc::option_error);
    }
    bad.brick_size = 256;
    for (int runs : {-1, 65}) {
        bad.concurrent_runs = runs;
        CHECK_THROWS_AS(pqdc::validate(bad), pqdc::option_error);
    }
    bad.concurrent_runs = 64;
    CHECK_NOTHROW(pqdc::validate(bad));
}

TEST_CASE("bricks: each brick's candidates are one contiguous run, lower neighbours first", "[bricks]") {
    // Across root boundaries (x = 0, z = -4096) and negative coordinates,
    // with a second sphere far away in another root child.
    auto grid = sphere(150, {0, 60, -4096});
    grid->tree().merge(sphere(40, {5000, -3000, 200})->tree());
    const std::vector<Coord> leaves = pqdc::detail::candidate_blocks(grid->tree(), 1.0, pqdc::ExtractOptions{});
    REQUIRE(leaves.size() > 1000);
    for (int size = 128; size <= 4096; size *= 2) {
        INFO("brick size " << size);
        const std::vector<pqdc::detail::BrickRun> runs = pqdc::detail::split_into_bricks(leaves, size);
        REQUIRE(runs.size() >= (size == 4096 ? 3u : 8u));
        std::map<Coord, std::size_t> index;  // brick min -> run
        std::size_t covered = 0;
        for (std::size_t k = 0; k < runs.size(); ++k) {
            REQUIRE(index.emplace(runs[k].box.min(), k).second);  // no brick appears twice
            REQUIRE(runs[k].box.dim() == pqdc::detail::brick_extent(size));
            REQUIRE(runs[k].begin == covered);
            covered = runs[k].end;
            bool inside = true;
            for (std::size_t i = runs[k].begin; i < runs[k].end; ++i) inside = inside && runs[k].box.isInside(leaves[i]);
            REQUIRE(inside);
        }
        REQUIRE(covered == leaves.size());
        const Coord e = pqdc::detail::brick_extent(size);
        for (std::size_t k = 0; k < runs.size(); ++k)
            for (int a = 0; a < 3; ++a) {
                Coord lower = runs[k].box.min();
                lower[a] -= e[a];
                const auto it = index.find(lower);
                if (it != index.end()) REQUIRE(it->second < k);
            }
    }
}

TEST_CASE("bricks: a brick tree holds the source's values and states in its box", "[bricks]") {
    // Leaves, tiles at all three levels (8^3 and 128^3 in internal nodes,
    // 4096^3 at the root), negative coordinates.
    openvdb::FloatTree src(5.0f);
    src.addTile(3, Coord(-4096, 0, 0), -2.0f, true);                   // root tile
    src.addTile(2, Coord(0, 0, 0), 3.0f, true);                        // 128^3 tile
    src.addTile(1, Coord(128, 8, 0), -1.0f, false);                    // 8^3 tile, inactive
    src.setValue(Coord(130, 0, 1), 7.0f);                              // leaves
    src.setValue(Coord(-1, -1, -1), 9.0f);
    src.setValue(Coord(255, 130, 127), 4.0f);
    src.setValueOff(Coord(129, 1, 2), -6.0f);
    for (const CoordBBox& box : {CoordBBox(Coord(-20, -20, -20), Coord(140, 140, 140)),
                                 CoordBBox(Coord(-4100, -3, -3), Coord(-4000, 20, 20)),
                                 CoordBBox(Coord(-300, -300, -300), Coord(300, 300, 300))}) {
        openvdb::FloatTree into(src.background());
        pqdc::detail::copy_tree_box(src, box, into);
        openvdb::tree::ValueAccessor<const openvdb::FloatTree> a(src);
        openvdb::tree::ValueAccessor<const openvdb::FloatTree> b(into);
        std::size_t checked = 0, differ = 0;
        for (int x = box.min().x(); x <= box.max().x(); x += 3)
            for (int y = box.min().y(); y <= box.max().y(); y += 3)
                for (int z = box.min().z(); z <= box.max().z(); z += 3) {
                    const Coord p(x, y, z);
                    differ += a.getValue(p) != b.getValue(p) || a.isValueOn(p) != b.isValueOn(p);
                    ++checked;
                }
        REQUIRE(differ == 0);
        for (const Coord& p : {Coord(130, 0, 1), Coord(-1, -1, -1), Coord(129, 1, 2)})
            if (box.isInside(p)) {
                REQUIRE(b.getValue(p) == a.getValue(p));
                REQUIRE(b.isValueOn(p) == a.isValueOn(p));
            }
        CHECK(checked > 1000);
    }
}

TEST_CASE("bricks: level set spheres across brick planes and root boundaries", "[bricks]") {
    pqdc::ExtractOptions o;
    SECTION("negative coordinates, the x = 0 and z = -4096 root boundaries") {
        require_bricks_match(*sphere(70, {0, -30, -4096}), o);
    }
    SECTION("quads, sharp gradient") {
        o.faces = pqdc::FaceType::quads;
        o.normals = pqdc::GridNormals::sharp;
        require_bricks_match(*sphere(50, {128, 128, 4096}), o);
    }
    SECTION("a region (bbox) cutting the surface open") {
        o.region.bbox = openvdb::BBoxd(openvdb::Vec3d(-100, -100, -20.5), openvdb::Vec3d(100, 15, 100));
        require_bricks_match(*sphere(60, {0, 0, 0}), o);
    }
}

TEST_CASE("bricks: surfaces lying exactly on brick planes", "[bricks]") {
    // Faces on x = 0 (a root and brick plane for every size), y = 128 (a
    // 128-brick plane) and z = 0, with exact zeros on them.
    auto grid = box_level_set(Coord(-40, 90, 0), Coord(0, 128, 30));
    pqdc::ExtractOptions o;
    require_bricks_match(*grid, o);
    o.normals = pqdc::GridNormals::sharp;
    o.faces = pqdc::FaceType::quads;
    require_bricks_match(*grid, o);
}

/// A fog volume: an active block filled as 8^3 tiles inside and leaves at
/// its boundary, across x = 0 and z = 0 (brick tiles at the other levels:
/// the copy test above); the surface runs along the tiles' faces.
openvdb::FloatGrid::Ptr fog_block_with_tiles() {
    auto grid = openvdb::FloatGrid::create(0.0f);
    grid->setGridClass(openvdb::GRID_FOG_VOLUME);
    grid->tree().fill(CoordBBox(Coord(-21, -3, -19), Coord(30, 44, 17)), 1.0f, true);
    std::size_t tiles = 0;
    for (auto it = grid->tree().cbeginValueOn(); it; ++it) tiles += !it.isVoxelValue();
    REQUIRE(tiles > 0);
    return grid;
}

/// A level set sphere across the x = 0 and z = 128 planes with a NaN hole
/// across both and an inactive strip, where the surface opens.
openvdb::FloatGrid::Ptr open_sphere_with_nan_hole() {
    auto grid = sphere(45, {0, 0, 127});
    auto acc = grid->getAccessor();
    for (int y = -4; y <= 4; ++y)
        for (int z = 120; z <= 136; ++z) acc.setValue(Coord(45, y, z), NAN);
    for (int x = -10; x <= 10; ++x)
        for (int z = 100; z <= 160; ++z)
            for (int y = 40; y <= 50; ++y) acc.setValueOff(Coord(x, y, z));
    return grid;
}

TEST_CASE("bricks: fog volume with active tiles", "[bricks]") {
    auto grid = fog_block_with_tiles();
    pqdc::ExtractOptions o;
    o.isovalue = 0.5;
    require_bricks_match(*grid, o);
    // A dent in a leaf, which also makes the noise estimate turn smoothing on.
    grid->tree().setValue(Coord(5, 5, 1), 0.2f);
    require_bricks_match(*grid, o);
}

TEST_CASE("bricks: NaN holes and open surfaces", "[bricks]") {
    pqdc::ExtractOptions o;
    require_bricks_match(*open_sphere_with_nan_hole(), o);
}

/// A noisy level-set sphere at the origin (on the brick planes x, y, z = 0)
/// and options that mesh it with classical quadrics, without denoising: the
/// surface folds in many places and sign flips make small islands.
std::pair<openvdb::FloatGrid::Ptr, pqdc::ExtractOptions> noisy_sphere_classical(double radius, double noise) {
    auto grid = sphere(radius, {0, 0, 0}, 4.0);
    pqdc::add_gaussian_noise(*grid, noise, 11);
    pqdc::ExtractOptions o;
    o.sigma_n = 0.0;
    o.denoise = pqdc::Denoise::off;
    return {grid, o};
}

TEST_CASE("bricks: small components removed, every run as in core, streamed in runs and on ranks",
          "[bricks][components]") {
    auto [grid, o] = noisy_sphere_classical(40, 0.35);
    o.min_component_voxels = 3.5;
    pqdc::ExtractStats s;
    const pqdc::Mesh m = pqdc::extract(*grid, o, &s);
    REQUIRE(s.components.removed_components > 10);  // the point: there are islands to remove
    CHECK(s.components.components == s.components.removed_components + 1);
    // What remove_small_components does to the mesh without the option, and the counts of the output.
    pqdc::ExtractOptions keep = o;
    keep.min_component_voxels = 0;
    pqdc::ExtractStats ks;
    const pqdc::Mesh all = pqdc::extract(*grid, keep, &ks);
    CHECK(ks.components.components == 0);
    pqdc::ComponentFilterOptions filter;
    filter.min_diagonal_voxels = 3.5;
    pqdc::ComponentFilterStats direct;
    require_same_bytes(m, pqdc::remove_small_components(all, grid->voxelSize()[0], filter, &direct));
    CHECK(direct.removed_faces == s.components.removed_faces);
    CHECK(s.vertices == m.points.size());
    CHECK(s.triangles == m.triangles.size());
    require_bricks_match(*grid, o);
    o.faces = pqdc::FaceType::quads;
    require_bricks_match(*grid, o);
}

TEST_CASE("bricks: a small component across brick planes goes in every run, a large one across them stays",
          "[bricks][components]") {
    // A droplet (diameter 3 voxels) centred on the corner where eight 128^3 bricks meet,
    // so every run of bricks and every rank holds a piece of it, and a sphere across the
    // planes x = 128 and y = 128.
    auto grid = sphere(30, {128, 128, 60});
    openvdb::tools::csgUnion(*grid, *sphere(1.5, {0.3f, 0.2f, 0.4f}));
    pqdc::ExtractOptions o;
    o.min_component_voxels = 8;
    pqdc::ExtractStats s;
    const pqdc::Mesh m = pqdc::extract(*grid, o, &s);
    REQUIRE(s.components.components == 2);
    REQUIRE(s.components.removed_components == 1);
    CHECK(s.components.smallest_kept_diagonal_voxels > 100);
    for (const openvdb::Vec3d& p : m.points) REQUIRE(p.length() > 10);  // the droplet is gone
    require_bricks_match(*grid, o);
    o.min_component_voxels = 2;  // now it stays
    pqdc::extract(*grid, o, &s);
    REQUIRE(s.components.removed_components == 0);
    require_bricks_match(*grid, o);
}

TEST_CASE("bricks: a removed droplet's triangles whose corners are all another run's go too",
          "[bricks][components]") {
    // A droplet of radius 2 voxels on the plane x = 128 and near y = z = 0:
    // split quads across those planes give triangles that hold none of
    // their own run's vertices, only the neighbouring runs'. Such faces of
    // the removed droplet were written with the numbers of unused vertices
    // (a face past the vertex count, or two wrong faces), streamed in
    // concurrent runs and on ranks.
    auto grid = sphere(30, {50, 50, 50});
    openvdb::tools::csgUnion(*grid, *sphere(2, {128.0f, 0.5f, -0.3f}));
    pqdc::ExtractOptions o;
    o.min_component_voxels = 10;
    pqdc::ExtractStats s;
    pqdc::extract(*grid, o, &s);
    REQUIRE(s.components.removed_components == 1);
    require_bricks_match(*grid, o);
}

TEST_CASE("bricks: vertex normals, every run the in-core normals, streamed too", "[bricks][normals]") {
    pqdc::ExtractOptions o;
    o.vertex_normals = true;
    SECTION("NaN holes (the cell's gradient stands in) and an open surface") {
        const auto grid = open_sphere_with_nan_hole();
        const pqdc::Mesh m = pqdc::extract(*grid, o);
        REQUIRE(m.normals.size() == m.points.size());
        // Every vertex gets a unit normal pointing outward, also next to the NaN voxels.
        std::size_t bad = 0;
        for (std::size_t i = 0; i < m.points.size(); ++i) {
            const openvdb::Vec3d radial = (m.points[i] - openvdb::Vec3d(0, 0, 127)).unitSafe();
            bad += !(std::abs(m.normals[i].length() - 1) < 1e-12 && m.normals[i].dot(radial) > 0.8);
        }
        CHECK(bad == 0);
        // The point: some central differences reach a NaN (the faces' normal stands in there in
        // compute_vertex_normals without an interior, the cell's gradient here).
        pqdc::Mesh by_faces = m;
        pqdc::compute_vertex_normals(by_faces, *grid);
        std::size_t differ = 0;
        for (std::size_t i = 0; i < m.normals.size(); ++i) differ += by_faces.normals[i] != m.normals[i];
        CHECK(differ > 0);
        require_bricks_match(*grid, o);
    }
    SECTION("a fog volume: inside above the isovalue, normals point down the values") {
        auto grid = fog_block_with_tiles();
        o.isovalue = 0.5;
        pqdc::ExtractStats s;
        const pqdc::Mesh m = pqdc::extract(*grid, o, &s);
        REQUIRE(s.interior == "above");
        pqdc::Mesh flipped = m;
        pqdc::compute_vertex_normals(flipped, *grid, pqdc::Interior::below_isovalue);
        REQUIRE(m.normals.size() == m.points.size());
        for (std::size_t i = 0; i < m.normals.size(); ++i) REQUIRE(m.normals[i] == -flipped.normals[i]);
        require_bricks_match(*grid, o);
    }
    SECTION("a writer and options that disagree about normals are refused") {
        const auto grid = sphere(30, {0, 0, 0});
        TempDir dir("normals_writer");
        pqdc::MeshStreamWriter out(dir.path("x.ply"), {}, false);
        try {
            pqdc::extract_bricks(*grid, o, pqdc::BrickOptions{}, out);
            FAIL("no error");
        } catch (const pqdc::option_error& e) {
            CHECK(std::string(e.what()).find("vertex_normals") != std::string::npos);
        }
    }
}

/// A noisy level set sphere with a NaN one leaf beyond the x = 0 plane: it
/// keeps the leaf next to the plane unsmoothed (smoothing skips leaves with
/// a NaN within two points), which a brick below the plane sees only with a
/// 16-voxel halo.
openvdb::FloatGrid::Ptr noisy_sphere_with_nan() {
    auto grid = sphere(40, {0, 0, 0}, 4.0);
    pqdc::add_gaussian_noise(*grid, 0.3, 7);
    REQUIRE(grid->tree().isValueOn(Coord(9, 40, 0)));
    grid->tree().setValue(Coord(9, 40, 0), NAN);
    return grid;
}

TEST_CASE("bricks: noisy volume, denoised automatically", "[bricks]") {
    const auto grid = noisy_sphere_with_nan();
    pqdc::ExtractOptions o;
    pqdc::ExtractStats s;
    pqdc::extract(*grid, o, &s);
    REQUIRE(s.denoise_radius > 0);  // the point: smoothing and the quadric filter are on
    REQUIRE(s.seconds("smooth field") > 0);
    require_bricks_match(*grid, o);
}

TEST_CASE("bricks: a streamed run in concurrent runs stops as a whole, with the first failure and no file",
          "[bricks]") {
    auto grid = sphere(150, {0, 0, 0});
    TempDir dir("streamed_stop");
    pqdc::BrickOptions b;
    b.brick_size = 128;
    for (int runs : {1, 2, 3}) {
        INFO(runs << " runs");
        b.concurrent_runs = runs;
        {
            // Cancelled by the caller partway through run 0's bricks.
            pqdc::ExtractOptions o;
            int calls = 0;
            o.progress = [&calls](double) { return ++calls < 4; };
            pqdc::MeshStreamWriter out(dir.path("stopped.ply"));
            REQUIRE_THROWS_AS(pqdc::extract_bricks(*grid, o, b, out), pqdc::cancelled_error);
        }
        {
            // Every run's brick exceeds the memory limit: its own error, not a hang.
            pqdc::ExtractOptions o;
            o.memory_limit_bytes = 4u << 20;
            pqdc::MeshStreamWriter out(dir.path("stopped.ply"));
            REQUIRE_THROWS_AS(pqdc::extract_bricks(*grid, o, b, out), pqdc::resource_error);
            REQUIRE_THROWS_WITH(pqdc::extract_bricks(*grid, o, b, out), Catch::Contains("(with its halo; others may need more; smaller bricks need less: BrickOptions::brick_size)"));
        }
        REQUIRE(!std::filesystem::exists(dir.path("stopped.ply")));
    }
}

TEST_CASE("bricks: streamed, the untangle stage repairs across brick planes as in core", "[bricks][untangle]") {
    // Folds on every side of the planes x, y, z = 0 between bricks.
    auto [grid, o] = noisy_sphere_classical(60, 0.3);
    o.normals = pqdc::GridNormals::central;
    pqdc::ExtractStats in_core_stats;
    const pqdc::Mesh in_core = pqdc::extract(*grid, o, &in_core_stats);
    REQUIRE(in_core_stats.untangle_found > 20);
    REQUIRE(in_core_stats.untangle_moved > 20);
    require_streamed_match(*grid, o, in_core, in_core_stats);
    SECTION("quads, one thread") {
        o.faces = pqdc::FaceType::quads;
        tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
        pqdc::ExtractStats s;
        const pqdc::Mesh quads = pqdc::extract(*grid, o, &s);
        REQUIRE(s.untangle_moved > 20);
        require_streamed_match(*grid, o, quads, s);
    }
    SECTION("vertices unconstrained: far from their cells the mesh is assembled in memory, same bytes") {
        o.containment = pqdc::Containment::unconstrained;
        pqdc::ExtractStats s;
        const pqdc::Mesh free = pqdc::extract(*grid, o, &s);
        require_streamed_match(*grid, o, free, s);
    }
}

TEST_CASE("streamed untangle: the part of the mesh near the seeds repairs as the whole mesh does",
          "[bricks][untangle]") {
    // A lattice sheet z in [0, 1) of N x N cells, a vertex anywhere in each
    // cell: its quads fold in many places.
    constexpr int n = 40;
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> offset(-0.49, 0.49);
    pqdc::Mesh mesh;
    std::vector<openvdb::Vec3d> safe;
    std::vector<pqdc::detail::ScratchVertex> vertices;
    double max_offset = 0;
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
            pqdc::detail::ScratchVertex v;
            v.cell = Coord(i, j, 0);
            v.config = 0x0f;  // inside below z = 0.5: one patch, its safe position the cell's center
            const openvdb::Vec3d center(i + 0.5, j + 0.5, 0.5);
            const openvdb::Vec3d d(offset(rng), offset(rng), offset(rng));
            v.position = center + d;
            max_offset = std::max({max_offset, std::abs(d.x()), std::abs(d.y()), std::abs(d.z())});
            vertices.push_back(v);
            mesh.points.push_back(v.position);
            safe.push_back(center);
        }
    std::vector<std::uint32_t> indices;
    for (int i = 1; i < n; ++i)
        for (int j = 1; j < n; ++j) {
            const std::uint32_t q[4] = {std::uint32_t((i - 1) * n + j - 1), std::uint32_t(i * n + j - 1),
                                        std::uint32_t(i * n + j), std::uint32_t((i - 1) * n + j)};
            mesh.quads.emplace_back(q[0], q[1], q[2], q[3]);
            indices.insert(indices.end(), q, q + 4);
        }
    pqdc::detail::UntangleSettings settings;
    const pqdc::detail::OffendingCorners first = pqdc::detail::find_offending_corners(mesh, settings);
    REQUIRE(first.vertices.size() > 20);
    const std::vector<std::uint64_t> seeds(first.vertices.begin(), first.vertices.end());

    pqdc::Mesh whole = mesh;
    pqdc::detail::UntangleCounters expected;
    REQUIRE(pqdc::detail::untangle(whole, safe, 1.0, settings, expected));
    REQUIRE(expected.rounds >= 1);

    TempDir dir("streamed_untangle");
    const openvdb::math::Transform::Ptr unit = openvdb::math::Transform::createLinearTransform(1.0);
    pqdc::detail::LatticeTransform lattice;
    lattice.transform = unit.get();
    // First reach 3 < 3 + 2 max_offset: no first part can be trusted, so the
    // stage must double it once and count only the run it keeps. On two and
    // three ranks, each holding a band of rows, the faces along a band's
    // lower edge use the rank before's vertices (foreign corners).
    for (int ranks : {1, 2, 3})
        for (int first_reach : {0, 3}) {
            INFO(ranks << " ranks, first reach " << first_reach);
            std::vector<pqdc::detail::UntangleCounters> counters(static_cast<std::size_t>(ranks));
            const auto results = pqdc_test::ThreadRanks(ranks).run<std::vector<pqdc::detail::MovedVertex>>(
                [&](pqdc::RankGroup& group) {
                    const int r = group.rank();
                    const std::uint32_t lo = std::uint32_t(r * n / ranks * n), hi = std::uint32_t((r + 1) * n / ranks * n);
                    pqdc::detail::StreamScratch scratch(dir.path("mesh.ply"), /*quads=*/true);
                    std::vector<std::uint32_t> own;
                    std::vector<pqdc::detail::ForeignCorner> foreign;
                    for (std::size_t q = 0; q < indices.size(); q += 4) {
                        if (indices[q + 2] < lo || indices[q + 2] >= hi) continue;  // corner 2 is the largest
                        for (std::size_t k = q; k < q + 4; ++k) {
                            if (indices[k] < lo)
                                foreign.push_back({own.size(), indices[k], Coord(int(indices[k]) / n, int(indices[k]) % n, 0)});
                            own.push_back(indices[k] < lo ? 0 : indices[k] - lo);
                        }
                    }
                    scratch.add_brick({vertices.begin() + lo, vertices.begin() + hi}, own, foreign);
                    scratch.number_from(lo);
                    return pqdc::detail::untangle_streamed(scratch, seeds, max_offset, vertices.size(), lattice, settings,
                                                           pqdc::ExtractOptions{}, counters[std::size_t(r)], group,
                                                           first_reach);
                });
            for (const auto& moved : results) {
                pqdc::Mesh part = mesh;
                for (const auto& [v, p] : moved) part.points[v] = p;
                REQUIRE(same_bytes(part.points, whole.points));
            }
            const pqdc::detail::UntangleCounters& c = counters[0];
            CHECK(c.pairs_before == expected.pairs_before);
            CHECK(c.moved_vertices == expected.moved_vertices);
            CHECK(c.snapped_vertices == expected.snapped_vertices);
            CHECK(c.rounds == expected.rounds);
        }
}

TEST_CASE("bricks: procedural field with exact crossings, uniform and adaptive", "[bricks][adaptive]") {
    const auto field = pqdc::make_procedural("sphere");
    pqdc::ProceduralSampling sampling;
    sampling.resolution = 200;
    pqdc::ExtractOptions o;
    const pqdc::Mesh in_core = pqdc::extract(*field, sampling, o);
    REQUIRE(in_core.points.size() > 1000);
    require_sizes_match(in_core, [&](const pqdc::BrickOptions& b) { return pqdc::extract_bricks(*field, sampling, o, b); });
    pqdc::AdaptiveOptions a;
    const pqdc::Mesh adaptive = pqdc::extract_adaptive(*field, sampling, a);
    REQUIRE(adaptive.points.size() > 500);
    require_sizes_match(adaptive,
                        [&](const pqdc::BrickOptions& b) { return pqdc::extract_adaptive_bricks(*field, sampling, a, b); });
    pqdc::BrickOptions b;
    b.brick_size = 128;
    const std::vector<pqdc::Mesh> ranks = pqdc_test::ThreadRanks(2).run<pqdc::Mesh>(
        [&](pqdc::RankGroup& group) { return pqdc::extract_distributed(*field, sampling, o, b, group); });
    require_same_bytes(in_core, ranks[0]);
    REQUIRE(ranks[1].empty());
    const std::vector<pqdc::Mesh> adaptive_ranks = pqdc_test::ThreadRanks(2).run<pqdc::Mesh>(
        [&](pqdc::RankGroup& group) { return pqdc::extract_adaptive_distributed(*field, sampling, a, b, group); });
    require_same_bytes(adaptive, adaptive_ranks[0]);
    REQUIRE(adaptive_ranks[1].empty());
}

TEST_CASE("distributed: ranks share the bricks in order, balanced by leaves", "[bricks][distributed]") {
    using pqdc::detail::BrickRun;
    // Five bricks of 10, 1, 1, 30 and 8 leaves (50 in all).
    std::vector<BrickRun> bricks;
    std::size_t at = 0;
    for (std::size_t n : {10, 1, 1, 30, 8}) {
        BrickRun r;
        r.begin = at;
        r.end = at += n;
        bricks.push_back(r);
    }
    using Share = std::pair<std::size_t, std::size_t>;
    CHECK(pqdc::detail::rank_bricks(bricks, 0, 1) == Share(0, 5));
    // Two ranks cut at 25 leaves: brick 3 (leaves 12-41) starts before it, so
    // rank 1 starts at brick 4. Bricks are never split.
    CHECK(pqdc::detail::rank_bricks(bricks, 0, 2) == Share(0, 4));
    CHECK(pqdc::detail::rank_bricks(bricks, 1, 2) == Share(4, 5));
    // More ranks than bricks: contiguous, covering, some empty.
    std::size_t next = 0, empty = 0;
    for (int r = 0; r < 8; ++r) {
        const Share s = pqdc::detail::rank_bricks(bricks, r, 8);
        CHECK(s.first == next);
        CHECK(s.first <= s.second);
        empty += s.first == s.second;
        next = s.second;
    }
    CHECK(next == bricks.size());
    CHECK(empty > 0);
    CHECK(pqdc::detail::rank_bricks({}, 1, 3) == Share(0, 0));
}

TEST_CASE("distributed: 1 to 4 ranks and more ranks than bricks give the in-core bytes and counts",
          "[bricks][distributed]") {
    // Two spheres in different root children (x < 0 and x >= 4096), so the
    // bricks are far apart and a rank's share can be empty.
    auto grid = sphere(40, {-20, 10, 5});
    auto other = sphere(30, {4100, 0, 0});
    grid->tree().merge(other->tree());
    pqdc::ExtractOptions o;
    pqdc::ExtractStats in_stats;
    const pqdc::Mesh in_core = pqdc::extract(*grid, o, &in_stats);
    REQUIRE(in_core.points.size() > 1000);
    for (int ranks : {1, 2, 4, 40}) {
        INFO(ranks << " ranks");
        pqdc::ExtractStats s;
        require_same_bytes(in_core, distributed(*grid, o, ranks, &s));
        CHECK(s.active_cells == in_stats.active_cells);
        CHECK(s.clamped_vertices == in_stats.clamped_vertices);
        CHECK(s.vertices == in_stats.vertices);
    }
}

TEST_CASE("distributed: a rank group that reports a rank outside it is refused", "[bricks][distributed]") {
    struct Broken : pqdc::RankGroup {
        int rank() const override { return 2; }
        int size() const override { return 2; }
        std::vector<std::string> gather_at_root(std::string) override { return {}; }
        std::string broadcast_from_root(std::string) override { return {}; }
        void send_to_root(std::string) override {}
        std::string receive_from(int) override { return {}; }
    } broken;
    auto grid = sphere(10, {0, 0, 0});
    REQUIRE_THROWS_AS(pqdc::extract_distributed(*grid, pqdc::ExtractOptions{}, pqdc::BrickOptions{}, broken),
                      pqdc::option_error);
    REQUIRE_THROWS_AS(
        pqdc::extract_adaptive_distributed(*grid, pqdc::AdaptiveOptions{}, pqdc::BrickOptions{}, broken),
        pqdc::option_error);
}

TEST_CASE("distributed: a part that does not parse is an internal error, not a wrong mesh",
          "[bricks][distributed]") {
    // Rank 0 of two, whose peer "sent" bytes of another format or byte order.
    struct Garbled : pqdc::RankGroup {
        int rank() const override { return 0; }
        int size() const override { return 2; }
        std::vector<std::string> gather_at_root(std::string own) override {
            return {std::move(own), std::string(40, '\x5a')};
        }
        std::string broadcast_from_root(std::string value) override { return value; }
        void send_to_root(std::string) override {}
        std::string receive_from(int) override { return std::string(40, '\x5a'); }
    } garbled;
    auto grid = sphere(30, {0, 0, 0});
    pqdc::BrickOptions b;
    b.brick_size = 128;
    REQUIRE_THROWS_AS(pqdc::extract_distributed(*grid, pqdc::ExtractOptions{}, b, garbled), std::logic_error);
    const TempDir dir("garbled");
    pqdc::MeshStreamWriter out(dir.path("garbled.ply"));
    REQUIRE_THROWS_AS(pqdc::extract_distributed(*grid, pqdc::ExtractOptions{}, b, garbled, out), std::logic_error);
    REQUIRE_THROWS_AS(pqdc::extract_adaptive_distributed(*grid, pqdc::AdaptiveOptions{}, b, garbled),
                      std::logic_error);
}

/// Leaves of a delay-loaded tree whose buffers are still in the file.
std::size_t leaves_in_file(const openvdb::FloatTree& tree) {
    std::size_t n = 0;
    for (auto it = tree.cbeginLeaf(); it; ++it) n += it->buffer().isOutOfCore();
    return n;
}

TEST_CASE("bricks: a delay-loaded .vdb is meshed without loading its leaves", "[bricks]") {
    namespace fs = std::filesystem;
    const TempDir tmp("bricks");
    const std::string path = tmp.path("sphere.vdb");
    auto grid = sphere(60, {-64, 0, 4096});
    grid->setName("sphere");
    pqdc::write_grid(*grid, path);

    const pqdc::LoadedGrid whole = pqdc::read_scalar_grid(path, "", pqdc::VolumeLoading::whole);
    pqdc::LoadedGrid delayed = pqdc::read_scalar_grid(path, "", pqdc::VolumeLoading::delayed);
    REQUIRE(!whole.delay_loaded);
    REQUIRE(delayed.delay_loaded);
    const auto& tree = static_cast<const openvdb::FloatGrid&>(*delayed.grid).tree();
    auto unloaded = [&] { return leaves_in_file(tree); };
    REQUIRE(unloaded() == tree.leafCount());
    REQUIRE(pqdc::in_core_bytes(*delayed.grid) >= tree.leafCount() * 512 * sizeof(float));

    pqdc::ExtractOptions o;
    const pqdc::Mesh in_core = pqdc::extract(*whole.grid, o);
    for (int size : {128, 4096}) {
        pqdc::BrickOptions b;
        b.brick_size = size;
        require_same_bytes(in_core, pqdc::extract_bricks(*delayed.grid, o, b));
    }
    CHECK(unloaded() == tree.leafCount());  // every value was read through copies

    // Chosen by size: the file's metadata records the grid's memory.
    CHECK(pqdc::read_scalar_grid(path, "", pqdc::VolumeLoading::delayed_if_larger, 1000).delay_loaded);
    CHECK(!pqdc::read_scalar_grid(path, "", pqdc::VolumeLoading::delayed_if_larger, 1ull << 40).delay_loaded);
}

TEST_CASE("volume io: a whole read decoded in parallel holds the serial read's grid, and no leaf in the file", "[bricks]") {
    const TempDir tmp("parallel_decoding");
    const std::string path = tmp.path("sphere.vdb");
    auto grid = sphere(60, {-64, 0, 4096});
    grid->setName("sphere");
    pqdc::write_grid(*grid, path);
    const pqdc::LoadedGrid serial = pqdc::read_scalar_grid(path);
    const pqdc::LoadedGrid parallel =
        pqdc::read_scalar_grid(path, "", pqdc::VolumeLoading::whole, 0, pqdc::LeafDecoding::parallel);
    CHECK(!parallel.delay_loaded);
    const auto& a = static_cast<const openvdb::FloatGrid&>(*serial.grid).tree();
    const auto& b = static_cast<const openvdb::FloatGrid&>(*parallel.grid).tree();
    CHECK(leaves_in_file(b) == 0);
    std::remove(path.c_str());  // a whole read owes the file nothing afterwards
    REQUIRE(a.leafCount() == b.leafCount());
    REQUIRE(a.leafCount() > 100);
    std::size_t differ = 0;
    for (auto la = a.cbeginLeaf(); la; ++la) {
        const auto* lb = b.probeConstLeaf(la->origin());
        differ += !lb || lb->getValueMask() != la->getValueMask() ||
                  std::memcmp(lb->buffer().data(), la->buffer().data(), sizeof(float) * la->SIZE) != 0;
    }
    CHECK(differ == 0);
    CHECK(a.activeVoxelCount() == b.activeVoxelCount());
    CHECK(a.activeTileCount() == b.activeTileCount());
    // Delayed when larger still means delayed: the parallel decoding is for whole reads only.
    pqdc::write_grid(*grid, path);
    CHECK(pqdc::read_scalar_grid(path, "", pqdc::VolumeLoading::delayed_if_larger, 1000, pqdc::LeafDecoding::parallel)
              .delay_loaded);
}

TEST_CASE("vertex normals refuse a face past the points, as every function taking a mesh", "[normals]") {
    const auto grid = sphere(20, {0, 0, 0});
    const auto field = pqdc::make_procedural("sphere");
    for (const bool quad : {false, true}) {
        pqdc::Mesh m;
        m.points = {{20, 0, 0}, {0, 20, 0}, {0, 0, 20}, {0, 0, -20}};
        if (quad) m.quads = {{0, 1, 2, 1000000}};
        else m.triangles = {{0, 1, 1000000}};
        INFO((quad ? "quad" : "triangle"));
        CHECK_THROWS_AS(pqdc::compute_vertex_normals(m, *grid), pqdc::input_error);
        CHECK_THROWS_WITH(pqdc::compute_vertex_normals_by_nodes(m, *grid),
                          Catch::Contains("refers to vertex 1000000") && Catch::Contains("only 4 points"));
        CHECK_THROWS_AS(pqdc::compute_vertex_normals(m, *field), pqdc::input_error);
        CHECK(m.normals.empty());
    }
}

TEST_CASE("bricks: vertex normals node by node equal the in-core ones and load no leaf", "[bricks]") {
    const TempDir tmp("bricks_normals");
    const std::string path = tmp.path("sphere.vdb");
    // Across node planes (x = 0, z = 4096, y = +-128 near the poles) and a root boundary.
    auto grid = sphere(60, {-64, 0, 4096});
    grid->setName("sphere");
    // A sheared, anisotropic map: the covector mapping must agree too.
    openvdb::math::Mat4d m = openvdb::math::Mat4d::identity();
    m.setRow(0, openvdb::Vec4d(0.5, 0.1, 0.0, 0.0));
    m.setRow(1, openvdb::Vec4d(0.0, 0.7, 0.2, 0.0));
    m.setRow(2, openvdb::Vec4d(0.0, 0.0, 1.1, 0.0));
    m.setRow(3, openvdb::Vec4d(3.0, -2.0, 1.0, 1.0));
    grid->setTransform(openvdb::math::Transform::createLinearTransform(m));
    pqdc::write_grid(*grid, path);
    const pqdc::LoadedGrid whole = pqdc::read_scalar_grid(path, "", pqdc::VolumeLoading::whole);
    const pqdc::LoadedGrid delayed = pqdc::read_scalar_grid(path, "", pqdc::VolumeLoading::delayed);
    const auto& tree = static_cast<const openvdb::FloatGrid&>(*delayed.grid).tree();
    auto unloaded = [&] { return leaves_in_file(tree); };
    pqdc::Mesh a = pqdc::extract(*whole.grid, pqdc::ExtractOptions());
    REQUIRE(a.points.size() > 1000);
    a.points.push_back(openvdb::Vec3d(std::numeric_limits<double>::quiet_NaN(), 0, 0));  // isolated, not finite
    a.points.push_back(openvdb::Vec3d(1e12, 0, 0));                                      // beyond the index range
    pqdc::Mesh b = a;
    pqdc::compute_vertex_normals(a, *whole.grid);
    pqdc::compute_vertex_normals_by_nodes(b, *delayed.grid);
    REQUIRE(a.normals.size() == a.points.size());
    CHECK(unloaded() == tree.leafCount());
    std::size_t differ = 0;
    for (std::size_t i = 0; i < a.normals.size(); ++i) differ += std::memcmp(&a.normals[i], &b.normals[i], sizeof(openvdb::Vec3d)) != 0;
    CHECK(differ == 0);
    CHECK(b.normals.back() == openvdb::Vec3d(0.0));  // no faces and no gradient
    // Node by node on an in-memory grid, too.
    pqdc::Mesh c = a;
    pqdc::compute_vertex_normals_by_nodes(c, *whole.grid);
    CHECK(std::memcmp(c.normals.data(), a.normals.data(), a.normals.size() * sizeof(openvdb::Vec3d)) == 0);

    // The per-vertex normals of a known interior: the same bits where the
    // gradient is usable, negated for the other interior, (0, 0, 0) where no
    // voxel is read; node by node the same, and no leaf loaded.
    pqdc::Mesh d = a, e = a, f = a;
    pqdc::compute_vertex_normals(d, *whole.grid, pqdc::Interior::below_isovalue);
    pqdc::compute_vertex_normals_by_nodes(e, *delayed.grid, pqdc::Interior::below_isovalue);
    pqdc::compute_vertex_normals(f, *whole.grid, pqdc::Interior::above_isovalue);
    CHECK(unloaded() == tree.leafCount());
    REQUIRE(d.normals.size() == a.points.size());
    CHECK(std::memcmp(d.normals.data(), a.normals.data(), (a.normals.size() - 2) * sizeof(openvdb::Vec3d)) == 0);
    CHECK(std::memcmp(e.normals.data(), d.normals.data(), d.normals.size() * sizeof(openvdb::Vec3d)) == 0);
    for (std::size_t i = 0; i < d.normals.size(); ++i) REQUIRE(f.normals[i] == -d.normals[i]);
    CHECK(d.normals[d.normals.size() - 2] == openvdb::Vec3d(0.0));
    CHECK(d.normals.back() == openvdb::Vec3d(0.0));
    CHECK_THROWS_AS(pqdc::compute_vertex_normals(d, *whole.grid, pqdc::Interior::automatic), pqdc::option_error);
}

/// A grid with what the store's candidate merge must get right: two root
/// children across x = 0 and negative coordinates, an interior tile of
/// another value, an active level-1 tile (its shell seeds blocks) and an
/// active root tile, which no brick file holds (the shell does).
openvdb::FloatGrid::Ptr tricky_store_grid() {
    auto grid = sphere(70, {0, 10, -20});
    grid->setName("ball");
    grid->tree().addTile(1, Coord(-8, 8, -16), -3.0f, false);
    grid->tree().addTile(2, Coord(256, -512, 128), -1.0f, true);
    grid->tree().addTile(3, Coord(8192, 0, 0), 2.0f, true);
    return grid;
}

TEST_CASE("bricks: a brick store meshes like its source", "[bricks]") {
    namespace fs = std::filesystem;
    const TempDir tmp("store");
    const fs::path dir = tmp.path("store");
    // Two root children (x < 0 and x >= 0), tiles, and a delay-loaded source.
    auto grid = tricky_store_grid();
    pqdc::write_grid(*grid, (dir.string() + "-src.vdb"));
    const pqdc::LoadedGrid src = pqdc::read_scalar_grid(dir.string() + "-src.vdb", "", pqdc::VolumeLoading::delayed);
    pqdc::BrickOptions b;
    b.brick_size = 128;
    const pqdc::BrickStoreSummary summary = pqdc::write_brick_store(*src.grid, dir.string(), b);
    CHECK(summary.bricks >= 8);
    CHECK(summary.leaves == static_cast<const openvdb::FloatGrid&>(*src.grid).tree().leafCount());
    REQUIRE(pqdc::is_brick_store(dir.string()));
    CHECK_THROWS_AS(pqdc::write_brick_store(*src.grid, dir.string(), b), pqdc::io_error);  // not empty
    const pqdc::LoadedGrid store = pqdc::read_brick_store(dir.string());
    REQUIRE(store.delay_loaded);
    REQUIRE(store.grid->getName() == "ball");
    const auto& a = grid->tree();
    const auto& t = static_cast<const openvdb::FloatGrid&>(*store.grid).tree();
    CHECK(t.leafCount() == a.leafCount());
    CHECK(t.activeTileCount() == a.activeTileCount());
    CHECK(t.getValue(Coord(-5, 10, -10)) == -3.0f);
    const pqdc::ExtractOptions o;
    const pqdc::Mesh in_core = pqdc::extract(*grid, o);
    for (int size : {128, 4096}) {
        pqdc::BrickOptions m;
        m.brick_size = size;
        require_same_bytes(in_core, pqdc::extract_bricks(*store.grid, o, m));
    }
}

TEST_CASE("bricks: a split stopped by its progress hook leaves no files", "[bricks]") {
    namespace fs = std::filesystem;
    const TempDir tmp("store_cancel");
    auto grid = tricky_store_grid();
    pqdc::write_grid(*grid, tmp.path("src.vdb"));
    const pqdc::LoadedGrid src = pqdc::read_scalar_grid(tmp.path("src.vdb"), "", pqdc::VolumeLoading::delayed);
    pqdc::BrickOptions b;
    b.brick_size = 128;
    // Whole: the fractions start at 0, rise and end at 1.
    std::vector<double> seen;
    const pqdc::BrickStoreSummary whole = pqdc::write_brick_store(*src.grid, tmp.path("whole"), b,
                                                                  [&](double f) { seen.push_back(f); return true; });
    REQUIRE(whole.bricks >= 8);
    CHECK(seen.size() == whole.bricks + 1);  // before the first brick, then after each
    CHECK(seen.front() == 0.0);
    CHECK(seen.back() == 1.0);
    CHECK(std::is_sorted(seen.begin(), seen.end()));
    // Stopped halfway, into a new directory and into an existing empty one.
    auto halfway = [](double f) { return f < 0.5; };
    CHECK_THROWS_AS(pqdc::write_brick_store(*src.grid, tmp.path("new"), b, halfway), pqdc::cancelled_error);
    CHECK_FALSE(fs::exists(tmp.path("new")));
    fs::create_directory(tmp.path("empty"));
    CHECK_THROWS_AS(pqdc::write_brick_store(*src.grid, tmp.path("empty"), b, halfway), pqdc::cancelled_error);
    CHECK(fs::is_directory(tmp.path("empty")));
    CHECK(fs::is_empty(tmp.path("empty")));
    // The procedural overload, stopped before its first brick.
    pqdc::ProceduralSampling sampling;
    sampling.resolution = 150;
    CHECK_THROWS_AS(pqdc::write_brick_store(*pqdc::make_procedural("sphere"), sampling, tmp.path("proc"), b,
                                            [](double) { return false; }),
                    pqdc::cancelled_error);
    CHECK_FALSE(fs::exists(tmp.path("proc")));
}

TEST_CASE("bricks: tree order of leaf origins is the order a tree visits them", "[bricks]") {
    auto grid = tricky_store_grid();
    grid->tree().merge(sphere(40, {5000, -3000, 200})->tree());
    std::vector<Coord> visited;
    for (auto it = grid->tree().cbeginLeaf(); it; ++it) visited.push_back(it->origin());
    REQUIRE(visited.size() > 1000);
    std::vector<Coord> sorted = visited;
    std::mt19937 rng(7);
    std::shuffle(sorted.begin(), sorted.end(), rng);
    std::sort(sorted.begin(), sorted.end(), pqdc::detail::tree_order_less);
    CHECK((sorted == visited));
    CHECK_FALSE(pqdc::detail::tree_order_less(visited[0], visited[0]));
}

TEST_CASE("bricks: a store read file by file has the assembled store's candidates, values and states",
          "[bricks]") {
    // Cache budgets of one byte (every file dropped as soon as another opens)
    // and of everything.
    const TempDir tmp("filewise");
    const auto grid = tricky_store_grid();
    pqdc::BrickOptions split;
    split.brick_size = 128;
    pqdc::write_brick_store(*grid, tmp.path("store"), split);
    const pqdc::LoadedGrid assembled = pqdc::read_brick_store(tmp.path("store"));
    const auto& whole = static_cast<const openvdb::FloatGrid&>(*assembled.grid).tree();
    const pqdc::BrickStore store(tmp.path("store"));
    REQUIRE(store.brick_files() >= 8);
    const auto& shell = static_cast<const openvdb::FloatGrid&>(store.shell());
    CHECK(shell.tree().leafCount() == 0);
    const pqdc::ExtractOptions o;
    // The root tile's shell alone seeds 1.5 M blocks: computed once.
    const std::vector<CoordBBox> clips = {CoordBBox::inf(), CoordBBox(Coord(-40, -30, -90), Coord(20, 70, 3))};
    std::vector<std::vector<Coord>> expected;
    for (const CoordBBox& clip : clips) expected.push_back(pqdc::detail::candidate_blocks(whole, 1.0, o, clip));
    for (std::uint64_t budget : {std::uint64_t(1), std::uint64_t(1) << 40}) {
        INFO("cache budget " << budget);
        const pqdc::detail::StoreBrickSource<openvdb::FloatTree> source(store.index(), shell, budget);
        for (std::size_t c = 0; c < clips.size(); ++c) {
            REQUIRE(expected[c].size() > 100);
            pqdc::detail::SoloRank alone;
            CHECK((source.candidate_blocks(1.0, o, clips[c], alone) == expected[c]));  // not printed: 1.5 M blocks
            // Shared among 3 ranks: each reads a third of the files.
            const std::vector<std::vector<Coord>> shared =
                pqdc_test::ThreadRanks(3).run<std::vector<Coord>>([&](pqdc::RankGroup& group) {
                    return source.candidate_blocks(1.0, o, clips[c], group);
                });
            for (const std::vector<Coord>& on_rank : shared) CHECK((on_rank == expected[c]));
        }
        // Boxes across brick and root planes: the same values and states.
        for (const CoordBBox& box : {CoordBBox(Coord(-20, -20, -100), Coord(140, 140, 40)),
                                     CoordBBox(Coord(250, -520, 120), Coord(260, -500, 140)),
                                     CoordBBox(Coord(8190, -3, -2), Coord(8200, 4, 6))}) {
            openvdb::FloatTree a(whole.background()), b(whole.background());
            pqdc::detail::copy_tree_box(whole, box, a);
            source.copy_box(box, b);
            std::uint64_t points = 0, differ = 0, on = 0;
            for (auto it = box.begin(); it; ++it) {
                ++points;
                on += whole.isValueOn(*it);
                differ += a.getValue(*it) != b.getValue(*it) || a.isValueOn(*it) != b.isValueOn(*it);
                // A sample: each lookup across a brick plane opens a file again at budget 1.
                if (points % 997 == 0) differ += source.is_value_on(*it) != whole.isValueOn(*it);
            }
            CHECK(points == box.volume());
            CHECK(on > 0);
            CHECK(differ == 0);
        }
        if (budget == 1) CHECK(source.files_opened() > store.brick_files());
        else CHECK(source.files_opened() == store.brick_files());  // the ranks' shares open each file once
    }
}

TEST_CASE("bricks: a store is meshed without reading the brick files away from the region", "[bricks]") {
    // A damaged file far from the region (its size kept, so only parsing it
    // fails) stops read_brick_store, which assembles the whole topology, but
    // not the run on a BrickStore, which opens only the files it meshes.
    const TempDir tmp("far");
    auto grid = sphere(60, {0, 0, 0});
    grid->tree().merge(sphere(30, {600, 0, 0})->tree());
    pqdc::BrickOptions split;
    split.brick_size = 128;
    pqdc::write_brick_store(*grid, tmp.path("store"), split);
    std::string far;
    {
        std::ifstream index(tmp.path("store") + "/index.txt");
        for (std::string line; std::getline(index, line);) {
            std::istringstream in(line);
            std::string word, file;
            int x = 0;
            if (in >> word >> file >> x && word == "brick" && x >= 512) far = file;
        }
    }
    REQUIRE(!far.empty());
    pqdc::ExtractOptions o;
    o.region.bbox = openvdb::BBoxd(openvdb::Vec3d(-70), openvdb::Vec3d(70));
    pqdc::MeshWriteOptions wo;
    wo.precision = pqdc::VertexPrecision::float64;
    pqdc::write_mesh(pqdc::extract(*grid, o), tmp.path("in_core.ply"), wo);
    {
        std::fstream f(tmp.path("store") + "/" + far, std::ios::in | std::ios::out | std::ios::binary);
        const std::string junk(64, 'x');
        f.write(junk.data(), std::streamsize(junk.size()));
    }
    CHECK_THROWS_AS(pqdc::read_brick_store(tmp.path("store")), pqdc::input_error);
    const pqdc::BrickStore store(tmp.path("store"));
    REQUIRE_FALSE(store.assembles_for(o));
    pqdc::MeshStreamWriter out(tmp.path("store.ply"), wo);
    pqdc::extract_bricks(store, o, split, out);
    out.finish();
    CHECK(file_bytes(tmp.path("store.ply")) == file_bytes(tmp.path("in_core.ply")));
    // Without the region the damaged file is read, and named.
    o.region = {};
    pqdc::MeshStreamWriter whole(tmp.path("whole.ply"), wo);
    CHECK_THROWS_WITH(pqdc::extract_bricks(store, o, split, whole), Catch::Contains(far));
}

TEST_CASE("bricks: a procedural field sampled brick by brick meshes like sample_field's grid", "[bricks]") {
    namespace fs = std::filesystem;
    const TempDir tmp("sampled");
    const fs::path dir = tmp.path("store");
    for (const std::string name : {"sphere", "box", "figure3"}) {
        const auto field = pqdc::make_procedural(name);
        for (double band : {0.0, 5.0}) {
            pqdc::ProceduralSampling sampling;
            sampling.resolution = 150;
            sampling.active_band_voxels = band;
            const openvdb::FloatGrid::Ptr whole = pqdc::sample_field(*field, sampling);
            // A restricted sample holds exactly the whole sample's leaves inside its nodes.
            const CoordBBox nodes(Coord(128, 0, 0), Coord(255, 127, 255));
            const openvdb::FloatGrid::Ptr part = pqdc::sample_field(*field, sampling, nodes);
            REQUIRE(part->tree().leafCount() > 0);
            std::size_t inside = 0;
            for (auto it = whole->tree().cbeginLeaf(); it; ++it) inside += nodes.isInside(it->origin());
            CHECK(part->tree().leafCount() == inside);
            for (auto it = part->tree().cbeginLeaf(); it; ++it) {
                const auto* same = whole->tree().probeConstLeaf(it->origin());
                REQUIRE(same);
                CHECK(same->getValueMask() == it->getValueMask());
                CHECK(std::memcmp(same->buffer().data(), it->buffer().data(), sizeof(float) * 512) == 0);
            }
            // Meshes are compared after a file round trip, like the store's: a
            // transform read back from a file maps points differently in the
            // last bits (1e-14 world units here).
            pqdc::write_grid(*whole, dir.string() + ".vdb");
            const pqdc::LoadedGrid reread = pqdc::read_scalar_grid(dir.string() + ".vdb", "", pqdc::VolumeLoading::whole);
            const pqdc::Mesh expected = pqdc::extract(*reread.grid, {});
            REQUIRE(expected.points.size() > 1000);
            for (int size : {128, 256}) {
                INFO(name << ", band " << band << ", brick size " << size);
                fs::remove_all(dir);
                pqdc::BrickOptions b;
                b.brick_size = size;
                const pqdc::BrickStoreSummary summary = pqdc::write_brick_store(*field, sampling, dir.string(), b);
                CHECK(summary.leaves == whole->tree().leafCount());
                const pqdc::LoadedGrid store = pqdc::read_brick_store(dir.string());
                CHECK(store.grid->getName() == whole->getName());
                CHECK(store.grid->getGridClass() == openvdb::GRID_LEVEL_SET);
                CHECK(store.grid->transform() == whole->transform());
                require_same_bytes(expected, pqdc::extract_bricks(*store.grid, {}, b));
            }
        }
    }
}

/// The bricks of 128 that small_sphere_store writes.
pqdc::BrickOptions small_bricks() {
    pqdc::BrickOptions b;
    b.brick_size = 128;
    return b;
}

/// A store of the procedural sphere at 150 cells (8 bricks of 128) in `dir`.
void write_small_sphere_store(const std::filesystem::path& dir) {
    pqdc::ProceduralSampling sampling;
    sampling.resolution = 150;
    pqdc::write_brick_store(*pqdc::make_procedural("sphere"), sampling, dir.string(), small_bricks());
}

/// The lines of the index.txt of the store in `dir`.
std::vector<std::string> index_lines(const std::filesystem::path& dir) {
    std::vector<std::string> lines;
    std::ifstream in(dir / "index.txt");
    for (std::string line; std::getline(in, line);) lines.push_back(line);
    return lines;
}

/// Rewrites the index.txt of the format 3 store in `dir` as format 2 (no
/// checksums), as stores were written before them: the checks behind the
/// checksums are what still guards such stores.
void strip_checksums(const std::filesystem::path& dir) {
    std::vector<std::string> lines = index_lines(dir);
    REQUIRE(lines.size() > 2);
    REQUIRE(lines[0] == "pqdc-brick-store 3");
    lines[0] = "pqdc-brick-store 2";
    lines[1] = "shell grid.vdb";
    std::ofstream out(dir / "index.txt", std::ios::trunc);
    for (const std::string& line : lines)
        out << (line.rfind("brick ", 0) == 0 ? line.substr(0, line.rfind(' ')) : line) << "\n";
}

TEST_CASE("bricks: a brick file cut short gives a short error naming it", "[bricks]") {
    // OpenVDB quoted a garbage map name from such a file (2.9 GB of message)
    // after allocating about 8 GB for it; the index's sizes refuse it first.
    namespace fs = std::filesystem;
    const TempDir tmp("cut");
    const fs::path dir = tmp.path("store");
    write_small_sphere_store(dir);
    std::string last;  // the last brick file, as tests/mpi/run.sh cuts it
    for (const auto& entry : fs::directory_iterator(dir))
        if (entry.path().filename().string().rfind("brick-", 0) == 0) last = std::max(last, entry.path().string());
    REQUIRE(!last.empty());
    fs::resize_file(last, 2000);
    try {
        pqdc::read_brick_store(dir.string());
        FAIL("a cut brick file should be refused");
    } catch (const pqdc::input_error& e) {
        const std::string what = e.what();
        INFO(what.substr(0, 400));
        CHECK(what.find(fs::path(last).filename().string()) != std::string::npos);
        CHECK(what.find("is 2000 bytes, index.txt says") != std::string::npos);
        CHECK(what.size() < 500);
    }
}

TEST_CASE("bricks: an index without brick sizes is still read, and a bad size is refused", "[bricks]") {
    namespace fs = std::filesystem;
    const TempDir tmp("sizes");
    const fs::path dir = tmp.path("store");
    write_small_sphere_store(dir);
    const pqdc::BrickOptions b = small_bricks();
    const pqdc::Mesh expected = pqdc::extract_bricks(*pqdc::read_brick_store(dir.string()).grid, {}, b);
    REQUIRE(expected.points.size() > 1000);
    const fs::path index = dir / "index.txt";
    std::vector<std::string> lines = index_lines(dir);
    REQUIRE(lines.size() > 4);
    REQUIRE(lines.back().rfind("end ", 0) == 0);
    const std::string& last_brick = lines[lines.size() - 2];
    REQUIRE(std::count(last_brick.begin(), last_brick.end(), ' ') == 9);  // size and checksum: fields 9 and 10
    // Format 2, as stores were written before the checksums: read alike.
    strip_checksums(dir);
    require_same_bytes(expected, pqdc::extract_bricks(*pqdc::read_brick_store(dir.string()).grid, {}, b));
    lines = index_lines(dir);
    auto write_index = [&](const std::function<std::string(const std::string&)>& edit) {
        std::ofstream out(index, std::ios::trunc);
        for (const std::string& line : lines) out << (line.rfind("brick ", 0) == 0 ? edit(line) : line) << "\n";
    };
    // As the thirteenth session's stores were written: eight fields.
    write_index([](const std::string& line) { return line.substr(0, line.rfind(' ')); });
    require_same_bytes(expected, pqdc::extract_bricks(*pqdc::read_brick_store(dir.string()).grid, {}, b));
    // An index that lost or gained brick lines (a cut copy) is refused: it
    // meshed part of the volume without a word. Version 1 had no end line.
    const std::vector<std::string> whole = lines;
    auto write_lines = [&](const std::vector<std::string>& l) {
        std::ofstream out(index, std::ios::trunc);
        for (const std::string& line : l) out << line << "\n";
    };
    lines.erase(lines.end() - 2);  // a brick line
    write_lines(lines);
    CHECK_THROWS_WITH(pqdc::read_brick_store(dir.string()), Catch::Contains("lines were lost or added"));
    lines.pop_back();  // and the end line: cut short
    write_lines(lines);
    CHECK_THROWS_WITH(pqdc::read_brick_store(dir.string()), Catch::Contains("has no end line"));
    lines[0] = "pqdc-brick-store 1";
    write_lines(lines);
    CHECK(pqdc::read_brick_store(dir.string()).grid);
    lines = whole;
    lines.push_back(whole[2]);
    write_lines(lines);
    CHECK_THROWS_WITH(pqdc::read_brick_store(dir.string()), Catch::Contains("goes on after its end line"));
    lines = whole;
    write_index([](const std::string& line) { return line.substr(0, line.rfind(' ')) + " 12x"; });
    CHECK_THROWS_WITH(pqdc::read_brick_store(dir.string()), Catch::Contains("index.txt has a bad line"));
    write_index([](const std::string& line) { return line + "1"; });  // ten times the size
    CHECK_THROWS_WITH(pqdc::read_brick_store(dir.string()), Catch::Contains("bytes, index.txt says"));
}

TEST_CASE("bricks: a damaged brick file or grid.vdb is refused by its checksum before it is parsed", "[bricks]") {
    // A flipped bit keeps the file's size: such a brick meshed silently into
    // another surface, or crashed OpenVDB's reader in pqdc-mpi's ranks.
    namespace fs = std::filesystem;
    const TempDir tmp("checksum");
    const fs::path dir = tmp.path("store");
    write_small_sphere_store(dir);
    const pqdc::BrickOptions b = small_bricks();
    const fs::path index = dir / "index.txt";
    std::vector<std::string> lines = index_lines(dir);
    REQUIRE(lines.size() > 4);
    // The largest brick file: most of it is leaf values.
    std::string largest;
    for (const auto& entry : fs::directory_iterator(dir))
        if (entry.path().filename().string().rfind("brick-", 0) == 0 &&
            (largest.empty() || fs::file_size(entry.path()) > fs::file_size(largest)))
            largest = entry.path().string();
    REQUIRE(!largest.empty());
    auto flip_middle_byte = [](const std::string& path) {
        std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
        const std::streamoff at = std::streamoff(std::filesystem::file_size(path) / 2);
        char c = 0;
        f.seekg(at);
        f.get(c);
        f.seekp(at);
        f.put(char(c ^ 0x10));
    };
    const std::string expected_message = "' does not match the checksum index.txt records for it";
    flip_middle_byte(largest);
    CHECK_THROWS_WITH(pqdc::read_brick_store(dir.string()),
                      Catch::Contains(fs::path(largest).filename().string() + expected_message));
    {
        // File by file: refused when the run opens it.
        const pqdc::BrickStore store(dir.string());
        pqdc::MeshStreamWriter out(tmp.path("out.ply"), {}, false);
        CHECK_THROWS_WITH(pqdc::extract_bricks(store, {}, b, out), Catch::Contains(expected_message));
    }
    flip_middle_byte(largest);  // back as written
    const pqdc::Mesh expected = pqdc::extract_bricks(*pqdc::read_brick_store(dir.string()).grid, {}, b);
    CHECK(expected.points.size() > 1000);
    flip_middle_byte((dir / "grid.vdb").string());
    CHECK_THROWS_WITH(pqdc::BrickStore(dir.string()), Catch::Contains("grid.vdb" + expected_message));
    CHECK_THROWS_WITH(pqdc::read_brick_store(dir.string()), Catch::Contains("grid.vdb" + expected_message));
    flip_middle_byte((dir / "grid.vdb").string());
    CHECK(pqdc::BrickStore(dir.string()).brick_files() > 1);
    // A format 3 line without its checksum, or with a malformed one.
    auto write_brick_lines = [&](const std::function<std::string(const std::string&)>& edit) {
        std::ofstream out(index, std::ios::trunc);
        for (const std::string& line : lines) out << (line.rfind("brick ", 0) == 0 ? edit(line) : line) << "\n";
    };
    write_brick_lines([](const std::string& line) { return line.substr(0, line.rfind(' ')); });
    CHECK_THROWS_WITH(pqdc::BrickStore(dir.string()), Catch::Contains("(no checksum)"));
    write_brick_lines([](const std::string& line) { return line.substr(0, line.rfind(' ')) + " 0123456789ABCDEF"; });
    CHECK_THROWS_WITH(pqdc::BrickStore(dir.string()), Catch::Contains("(no checksum)"));
    write_brick_lines([](const std::string& line) { return line + " more"; });
    CHECK_THROWS_WITH(pqdc::BrickStore(dir.string()), Catch::Contains("index.txt has a bad line"));
    std::vector<std::string> edited = lines;
    edited[1] = "shell grid.vdb";
    {
        std::ofstream out(index, std::ios::trunc);
        for (const std::string& line : edited) out << line << "\n";
    }
    CHECK_THROWS_WITH(pqdc::BrickStore(dir.string()), Catch::Contains("index.txt has a bad line 'shell grid.vdb'"));
}

TEST_CASE("bricks: files of another volume, swapped or left out are refused by name", "[bricks]") {
    // Each meshed silently: another volume's grid.vdb at its scale (48 times
    // too large), swapped files and a removed line with holes.
    namespace fs = std::filesystem;
    const TempDir tmp("foreign");
    const fs::path dir = tmp.path("store"), other = tmp.path("other");
    write_small_sphere_store(dir);
    {
        pqdc::ProceduralSampling sampling;
        sampling.resolution = 100;
        pqdc::write_brick_store(*pqdc::make_procedural("sphere"), sampling, other.string(), small_bricks());
    }
    const auto refused = [&](const std::string& expected) {
        INFO("expected: " << expected);
        CHECK_THROWS_WITH(pqdc::read_brick_store(dir.string()), Catch::Contains(expected));
        // The streamed run opens the files one at a time: the same checks
        // (of grid.vdb when the store is opened).
        const auto streamed = [&] {
            const pqdc::BrickStore store(dir.string());
            pqdc::MeshStreamWriter out(tmp.path("out.ply"), {}, false);
            pqdc::extract_bricks(store, {}, small_bricks(), out);
        };
        CHECK_THROWS_WITH(streamed(), Catch::Contains(expected));
    };
    const auto copy = [](const fs::path& from, const fs::path& to) {
        fs::copy_file(from, to, fs::copy_options::overwrite_existing);
    };
    copy(dir / "grid.vdb", tmp.path("grid.vdb"));
    copy(other / "grid.vdb", dir / "grid.vdb");
    refused("grid.vdb' does not match the checksum");
    copy(tmp.path("grid.vdb"), dir / "grid.vdb");
    // Behind the checksums, for stores written before them (and a checksum
    // that happened to match), the files' contents are checked.
    strip_checksums(dir);
    copy(other / "grid.vdb", dir / "grid.vdb");
    refused("has another transform");
    copy(tmp.path("grid.vdb"), dir / "grid.vdb");
    REQUIRE(pqdc::read_brick_store(dir.string()).grid);

    // Two files swapped, their sizes in index.txt swapped as well.
    const fs::path index = dir / "index.txt";
    std::vector<std::string> lines = index_lines(dir);
    REQUIRE(lines.size() > 5);
    const std::vector<std::string> whole = lines;
    auto write_lines = [&](const std::vector<std::string>& l) {
        std::ofstream out(index, std::ios::trunc);
        for (const std::string& line : l) out << line << "\n";
    };
    const auto size_of = [](const std::string& line) { return line.substr(line.rfind(' ') + 1); };
    const auto with_size = [](const std::string& line, const std::string& size) {
        return line.substr(0, line.rfind(' ') + 1) + size;
    };
    lines[2] = with_size(whole[2], size_of(whole[3]));
    lines[3] = with_size(whole[3], size_of(whole[2]));
    write_lines(lines);
    const auto swap_files = [&] {
        fs::rename(dir / "brick-000000.vdb", tmp.path("swap.vdb"));
        fs::rename(dir / "brick-000001.vdb", dir / "brick-000000.vdb");
        fs::rename(tmp.path("swap.vdb"), dir / "brick-000001.vdb");
    };
    swap_files();
    refused("holds voxels outside its box");
    swap_files();

    // A line taken out, the end line's count lowered to match.
    lines = whole;
    lines.erase(lines.begin() + 3);
    lines.back() = "end " + std::to_string(lines.size() - 3);
    write_lines(lines);
    CHECK_THROWS_WITH(pqdc::read_brick_store(dir.string()), Catch::Contains("expected 'brick-000001.vdb'"));
    // A later format is named as such ("not a pqdc brick store" before),
    // and a store without its grid.vdb as damaged ("check the path").
    lines = whole;
    lines[0] = "pqdc-brick-store 4";
    write_lines(lines);
    CHECK_THROWS_WITH(pqdc::read_brick_store(dir.string()), Catch::Contains("of format 'pqdc-brick-store 4', newer"));
    // CRLF line endings (a copy through Windows): read as written. It was
    // "of format 'pqdc-brick-store 2', newer than this pqdc reads ('pqdc-brick-store 2')".
    {
        std::ofstream out(index, std::ios::trunc);
        for (const std::string& line : whole) out << line << "\r\n";
    }
    CHECK(pqdc::read_brick_store(dir.string()).grid);
    write_lines(whole);
    REQUIRE(pqdc::read_brick_store(dir.string()).grid);
    fs::remove(dir / "grid.vdb");
    CHECK_THROWS_WITH(pqdc::BrickStore(dir.string()), Catch::Contains("has no grid.vdb"));
}

TEST_CASE("bricks: an infinite active band samples a dense volume", "[bricks]") {
    pqdc::ProceduralSampling sampling;
    sampling.resolution = 40;
    sampling.active_band_voxels = std::numeric_limits<double>::infinity();
    const auto field = pqdc::make_procedural("sphere");
    const openvdb::FloatGrid::Ptr dense = pqdc::sample_field(*field, sampling);
    CHECK(dense->tree().activeVoxelCount() == pqdc::procedural_index_bbox(*field, sampling).volume());
    sampling.active_band_voxels = -1;
    CHECK_THROWS_AS(pqdc::sample_field(*field, sampling), pqdc::option_error);
    // Far from the surface the values are the field's own, not clamped to the band.
    sampling.active_band_voxels = std::numeric_limits<double>::infinity();
    CHECK(dense->tree().getValue(Coord(0, 0, 0)) > 10 * dense->voxelSize()[0]);
}

TEST_CASE("bricks: the memory limit counts cell records as they accrue, not every candidate", "[bricks]") {
    // A dense volume: every leaf is a candidate, few hold surface.
    pqdc::ProceduralSampling sampling;
    sampling.resolution = 128;
    sampling.active_band_voxels = std::numeric_limits<double>::infinity();
    const openvdb::FloatGrid::Ptr dense = pqdc::sample_field(*pqdc::make_procedural("sphere"), sampling);
    const pqdc::Mesh expected = pqdc::extract(*dense, {});
    REQUIRE(expected.points.size() > 10000);
    pqdc::ExtractOptions limited;
    limited.memory_limit_bytes = std::size_t(16) << 20;
    // In core every candidate may become a surface leaf: refused up front.
    CHECK_THROWS_AS(pqdc::extract(*dense, limited), pqdc::resource_error);
    pqdc::BrickOptions b;
    b.brick_size = 128;
    require_same_bytes(expected, pqdc::extract_bricks(*dense, limited, b));
    limited.memory_limit_bytes = std::size_t(1) << 20;
    try {
        pqdc::extract_bricks(*dense, limited, b);
        FAIL("a 1 MiB limit should be refused");
    } catch (const pqdc::resource_error& e) {
        CHECK(std::string(e.what()).find("cell records") != std::string::npos);
    }
}

// Adaptive mode brick by brick (extract_adaptive_bricks): the same bytes as
// extract_adaptive, whose finest level is rebuilt from the bricks' cells.

/// Rank 0's mesh of extract_adaptive_distributed over `ranks` thread ranks,
/// bricks of 128; requires every other rank's mesh to be empty. `stats`: rank 0's.
template <class Input>
pqdc::Mesh adaptive_distributed(const Input& input, const pqdc::AdaptiveOptions& options, int ranks,
                                pqdc::AdaptiveStats* stats = nullptr) {
    pqdc::BrickOptions b;
    b.brick_size = 128;
    const std::vector<pqdc::Mesh> meshes =
        pqdc_test::ThreadRanks(ranks).run<pqdc::Mesh>([&](pqdc::RankGroup& group) {
            return pqdc::extract_adaptive_distributed(input, options, b, group, group.rank() == 0 ? stats : nullptr);
        });
    for (std::size_t r = 1; r < meshes.size(); ++r) REQUIRE(meshes[r].empty());
    return meshes[0];
}

/// The octree's counters, which a run by bricks must report as the in-core
/// run does: the bricks merge their lowest levels themselves, each parent
/// counted once, in the brick holding it (not again in the ring around
/// another brick).
void require_same_octree_counts(const pqdc::AdaptiveStats& a, const pqdc::AdaptiveStats& b) {
    using S = pqdc::AdaptiveStats;
    for (std::uint64_t S::*count : std::initializer_list<std::uint64_t S::*>
         {&S::active_cells, &S::crossing_edges, &S::degenerate_normals, &S::clamped_vertices, &S::fallback_vertices,
          &S::non_finite_values, &S::merges, &S::refused_error, &S::refused_topology, &S::refused_containment, &S::refused_balance,
          &S::refused_pinned, &S::surface_leaves, &S::empty_leaves, &S::dual_cells, &S::untangle_pinned_cells})
        CHECK(a.*count == b.*count);
    CHECK(a.leaves_per_level == b.leaves_per_level);
}

/// extract_adaptive_bricks against extract_adaptive for brick sizes 128,
/// 256 and 4096 (all threads), 128 on two threads and on one;
/// extract_adaptive_distributed on three ranks; the same counters.
template <class Input>
void require_adaptive_bricks_match(const Input& grid, const pqdc::AdaptiveOptions& options,
                                   std::size_t min_points = 100) {
    pqdc::AdaptiveStats in_core_stats;
    const pqdc::Mesh in_core = pqdc::extract_adaptive(grid, options, &in_core_stats);
    REQUIRE(in_core.points.size() > min_points);
    {
        INFO("three ranks, brick size 128");
        pqdc::AdaptiveStats s;
        require_same_bytes(in_core, adaptive_distributed(grid, options, 3, &s));
        require_same_octree_counts(s, in_core_stats);
    }
    for (int size : {128, 256, 4096}) {
        INFO("brick size " << size);
        pqdc::BrickOptions b;
        b.brick_size = size;
        pqdc::AdaptiveStats s;
        require_same_bytes(in_core, pqdc::extract_adaptive_bricks(grid, options, b, &s));
        require_same_octree_counts(s, in_core_stats);
    }
    pqdc::BrickOptions b;
    b.brick_size = 128;
    for (int threads : {2, 1}) {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
        INFO("brick size 128, threads " << threads);
        require_same_bytes(in_core, pqdc::extract_adaptive_bricks(grid, options, b));
    }
}

TEST_CASE("adaptive bricks: a CAD level set (fandisk)", "[bricks][adaptive]") {
    const pqdc::LoadedGrid g =
        pqdc::read_scalar_grid(std::string(PQDC_SOURCE_DIR) + "/volumes/fandisk.vdb", "", pqdc::VolumeLoading::whole);
    pqdc::AdaptiveOptions o;
    require_adaptive_bricks_match(*g.grid, o, 1000);
}

TEST_CASE("adaptive bricks: spheres across brick planes and root boundaries, negative coordinates",
          "[bricks][adaptive]") {
    pqdc::AdaptiveOptions o;
    SECTION("the x = 0 and z = -4096 root boundaries") { require_adaptive_bricks_match(*sphere(70, {0, -30, -4096}), o); }
    SECTION("small cells, sharp gradient, quads") {
        o.max_cell_size_voxels = 4;  // roots below a leaf's 8 voxels
        o.base.normals = pqdc::GridNormals::sharp;
        o.base.faces = pqdc::FaceType::quads;
        require_adaptive_bricks_match(*sphere(40, {-128, 128, 0}), o);
    }
    SECTION("a region cutting the surface open") {
        o.base.region.bbox = openvdb::BBoxd(openvdb::Vec3d(-100, -100, -20.5), openvdb::Vec3d(100, 15, 100));
        require_adaptive_bricks_match(*sphere(60, {0, 0, 0}), o);
    }
}

TEST_CASE("adaptive bricks: surfaces lying exactly on brick planes", "[bricks][adaptive]") {
    auto grid = box_level_set(Coord(-40, 90, 0), Coord(0, 128, 30));
    pqdc::AdaptiveOptions o;
    require_adaptive_bricks_match(*grid, o);
}

TEST_CASE("adaptive bricks: fog volume with active tiles", "[bricks][adaptive]") {
    pqdc::AdaptiveOptions o;
    o.base.isovalue = 0.5;
    require_adaptive_bricks_match(*fog_block_with_tiles(), o);
}

TEST_CASE("adaptive bricks: NaN holes and open surfaces", "[bricks][adaptive]") {
    pqdc::AdaptiveOptions o;
    require_adaptive_bricks_match(*open_sphere_with_nan_hole(), o);
}

TEST_CASE("adaptive bricks: noisy volume, smoothed brick by brick", "[bricks][adaptive]") {
    const auto grid = noisy_sphere_with_nan();
    pqdc::AdaptiveOptions o;
    pqdc::AdaptiveStats s;
    pqdc::extract_adaptive(*grid, o, &s);
    REQUIRE(s.seconds("smooth field") > 0);  // the point: the smoothed field is meshed
    require_adaptive_bricks_match(*grid, o);
    // By bricks the smoothing has no stage of its own: each brick smooths
    // its values, and the later stages each leaf they read.
}

TEST_CASE("adaptive bricks: noisy dense volume, probed beyond the smoothed band", "[bricks][adaptive]") {
    // Every voxel active: the empty leaves beside the surface's root cells
    // are probed where the grid holds values, not background, so the
    // smoothed copy must hold the leaves around those roots too.
    const auto field = pqdc::make_procedural("sphere");
    pqdc::ProceduralSampling sampling;
    sampling.resolution = 72;
    sampling.active_band_voxels = std::numeric_limits<double>::infinity();
    const openvdb::FloatGrid::Ptr grid = pqdc::sample_field(*field, sampling);
    pqdc::add_gaussian_noise(*grid, 0.3 * grid->voxelSize()[0], 3);
    pqdc::AdaptiveOptions o;
    o.max_cell_size_voxels = 16;
    pqdc::AdaptiveStats s;
    pqdc::extract_adaptive(*grid, o, &s);
    REQUIRE(s.seconds("smooth field") > 0);
    require_adaptive_bricks_match(*grid, o);
}

TEST_CASE("adaptive bricks: the untangle stage's rebuilds read the bricks again", "[bricks][adaptive]") {
    // The input of the [adaptive] thread test whose untangle stage pins
    // cells and rebuilds the octree (stage "hermite" runs again).
    const auto field = pqdc::make_procedural("figure3");
    pqdc::ProceduralSampling sampling;
    sampling.resolution = 48;
    pqdc::AdaptiveOptions o;
    o.max_error_voxels = 0.2;
    o.max_cell_size_voxels = 8;
    pqdc::AdaptiveStats s;
    const pqdc::Mesh in_core = pqdc::extract_adaptive(*field, sampling, o, &s);
    REQUIRE(s.untangle_pinned_cells > 0);
    pqdc::BrickOptions b;
    b.brick_size = 128;
    pqdc::AdaptiveStats sb;
    require_same_bytes(in_core, pqdc::extract_adaptive_bricks(*field, sampling, o, b, &sb));
    CHECK(sb.untangle_pinned_cells == s.untangle_pinned_cells);
    const openvdb::FloatGrid::Ptr grid = pqdc::sample_field(*field, sampling);  // the grid path too
    const pqdc::Mesh grid_in_core = pqdc::extract_adaptive(*grid, o);
    require_same_bytes(grid_in_core, pqdc::extract_adaptive_bricks(*grid, o, b));
    // Distributed, rank 0 runs the rebuilds alone after the other ranks have stopped.
    const std::vector<pqdc::Mesh> ranks = pqdc_test::ThreadRanks(3).run<pqdc::Mesh>(
        [&](pqdc::RankGroup& group) { return pqdc::extract_adaptive_distributed(*field, sampling, o, b, group); });
    require_same_bytes(in_core, ranks[0]);
    pqdc::AdaptiveStats sd;
    require_same_bytes(grid_in_core, adaptive_distributed(*grid, o, 2, &sd));
    CHECK(sd.untangle_pinned_cells > 0);
}

TEST_CASE("adaptive bricks: a dense brick store is meshed without loading the grid's leaves",
          "[bricks][adaptive]") {
    const TempDir tmp("adaptive-store");
    const auto field = pqdc::make_procedural("sphere");
    pqdc::ProceduralSampling sampling;
    sampling.resolution = 150;
    sampling.active_band_voxels = std::numeric_limits<double>::infinity();  // every leaf a candidate
    pqdc::BrickOptions b;
    b.brick_size = 128;
    pqdc::write_brick_store(*field, sampling, tmp.path("store"), b);
    const pqdc::LoadedGrid store = pqdc::read_brick_store(tmp.path("store"));
    const auto& tree = static_cast<const openvdb::FloatGrid&>(*store.grid).tree();
    auto loaded = [&] { return tree.leafCount() - leaves_in_file(tree); };
    REQUIRE(loaded() == 0);
    // In core from the store's own values (a file round trip maps points in the last bits).
    const pqdc::LoadedGrid whole = pqdc::read_brick_store(tmp.path("store"));
    pqdc::AdaptiveOptions o;
    o.max_cell_size_voxels = 8;  // the probes then stay within about a leaf of the surface
    const pqdc::Mesh in_core = pqdc::extract_adaptive(*whole.grid, o);
    REQUIRE(in_core.points.size() > 1000);
    require_same_bytes(in_core, pqdc::extract_adaptive_bricks(*store.grid, o, b));
    // Every stage reads copies of the leaves (the bricks, then leaf by leaf:
    // adaptive/source_values.hpp), which hold the values only while they are
    // read: the grid's own leaves all stay in the files. (Its accessors would
    // load every leaf they touch, for the rest of the run.)
    std::size_t loaded_leaves = 0;
    for (auto it = tree.cbeginLeaf(); it; ++it) loaded_leaves += !it->buffer().isOutOfCore();
    INFO(loaded_leaves << " of " << tree.leafCount() << " leaves loaded");
    CHECK(tree.leafCount() > 1000);
    CHECK(loaded_leaves == 0);
    pqdc::BrickOptions bad;
    bad.brick_size = 100;
    CHECK_THROWS_AS(pqdc::extract_adaptive_bricks(*store.grid, o, bad), pqdc::option_error);
}

#ifdef __linux__
/// This process's resident pages of mapped files, from /proc/self/status (KiB).
long resident_file_kib() {
    std::ifstream status("/proc/self/status");
    std::string key;
    long kib = -1;
    while (status >> key) {
        if (key == "RssFile:") status >> kib;
        else status.ignore(1 << 10, '\n');
    }
    return kib;
}

TEST_CASE("bricks: mapped volume pages are handed back between bricks", "[bricks]") {
    namespace fs = std::filesystem;
    const TempDir tmp("mapped");
    const fs::path dir = tmp.path("store");
    pqdc::ProceduralSampling sampling;
    sampling.resolution = 128;
    sampling.active_band_voxels = std::numeric_limits<double>::infinity();  // 8.6 MB of values
    pqdc::write_brick_store(*pqdc::make_procedural("sphere"), sampling, dir.string());
    {
        const pqdc::LoadedGrid store = pqdc::read_brick_store(dir.string());
        const auto& tree = static_cast<const openvdb::FloatGrid&>(*store.grid).tree();
        // Load every leaf through copies, as the bricks do: their pages become resident.
        const long before = resident_file_kib();
        double sum = 0;
        for (auto it = tree.cbeginLeaf(); it; ++it) {
            const openvdb::FloatTree::LeafNodeType copy(*it);
            sum += copy.getValue(0);
        }
        const long loaded = resident_file_kib();
        INFO("RssFile before " << before << " KiB, loaded " << loaded << " KiB (sum " << sum << ")");
        CHECK(pqdc::detail::release_mapped_volume_pages() > 0);
        const long released = resident_file_kib();
        INFO("released " << released << " KiB");
        REQUIRE(loaded - before > 2000);
        CHECK(loaded - released > (loaded - before) / 2);
    }
    // Closed: no mapping is left to advise.
    CHECK(pqdc::detail::release_mapped_volume_pages() == 0);
}
#endif

#ifdef PQDC_CLI_PATH

pqdc_test::RunResult pqdc_in(const pqdc_test::ScratchDir& dir, std::vector<std::string> args) {
    pqdc_test::RunSpec spec;
    spec.args = std::move(args);
    spec.cwd = dir.dir();
    return pqdc_test::run_program(PQDC_CLI_PATH, spec);
}

#ifdef PQDC_BRICKS_PATH
/// `pqdc-bricks split in.vdb -o in.bricks --brick-size 128` in the scratch directory.
void split_into_store(const pqdc_test::ScratchDir& dir) {
    pqdc_test::RunSpec spec;
    spec.cwd = dir.dir();
    spec.args = {"split", "in.vdb", "-o", "in.bricks", "--brick-size", "128"};
    const auto split = pqdc_test::run_program(PQDC_BRICKS_PATH, spec);
    INFO(split.err);
    REQUIRE(split.exit_code == 0);
}
#endif

TEST_CASE("bricks: pqdc --out-of-core writes the in-core bytes", "[bricks][cli]") {
    pqdc_test::ScratchDir dir("bricks_cli");
    auto grid = sphere(70, {0, 20, -30});
    grid->setName("sphere");
    pqdc::write_grid(*grid, dir.path("in.vdb"));
    const auto plain = pqdc_in(dir, {"in.vdb", "-o", "plain.ply", "-q"});
    REQUIRE(plain.exit_code == 0);
    const std::string expected = file_bytes(dir.path("plain.ply"));
    REQUIRE(expected.size() > 10000);
    for (const std::vector<std::string>& extra :
         {std::vector<std::string>{"--out-of-core"}, {"--brick-size", "128"}, {"--brick-size", "4096", "--threads", "1"},
          {"--brick-size", "128", "--brick-runs", "1"}, {"--brick-size", "128", "--brick-runs", "3"}}) {
        std::vector<std::string> args{"in.vdb", "-o", "bricks.ply", "-q"};
        args.insert(args.end(), extra.begin(), extra.end());
        INFO(extra.back());
        REQUIRE(pqdc_in(dir, args).exit_code == 0);
        REQUIRE(file_bytes(dir.path("bricks.ply")) == expected);
    }
    // --brick-runs alone meshes out of core too (it was ignored in core).
    REQUIRE(pqdc_in(dir, {"in.vdb", "-o", "runs.ply", "-q", "--brick-runs", "2", "--stats", "runs.json"}).exit_code == 0);
    CHECK(file_bytes(dir.path("runs.ply")) == expected);
    CHECK(file_bytes(dir.path("runs.json")).find("\"write pieces\"") != std::string::npos);
}

TEST_CASE("bricks: pqdc --vertex-normals out of core and from a store writes the in-core bytes", "[bricks][cli]") {
    pqdc_test::ScratchDir dir("bricks_cli_normals");
    auto grid = sphere(70, {0, 20, -30});  // across the node planes x = 0 and z = 0
    grid->setName("sphere");
    pqdc::write_grid(*grid, dir.path("in.vdb"));
    REQUIRE(pqdc_in(dir, {"in.vdb", "-o", "plain.ply", "-q", "--vertex-normals"}).exit_code == 0);
    const std::string expected = file_bytes(dir.path("plain.ply"));
    REQUIRE(expected.find("property float nx") != std::string::npos);
#ifdef PQDC_BRICKS_PATH
    split_into_store(dir);
    REQUIRE(pqdc_in(dir, {"in.bricks", "-o", "store.ply", "-q", "--vertex-normals"}).exit_code == 0);
    CHECK(file_bytes(dir.path("store.ply")) == expected);
#endif
    for (const std::vector<std::string>& extra :
         {std::vector<std::string>{"--out-of-core"}, {"--brick-size", "128", "--threads", "1"}}) {
        std::vector<std::string> args{"in.vdb", "-o", "bricks.ply", "-q", "--vertex-normals", "--stats", "s.json"};
        args.insert(args.end(), extra.begin(), extra.end());
        INFO(extra.front());
        REQUIRE(pqdc_in(dir, args).exit_code == 0);
        CHECK(file_bytes(dir.path("bricks.ply")) == expected);
        // Streamed piece by piece, not assembled: the streamed run's last stage ran.
        CHECK(file_bytes(dir.path("s.json")).find("\"write pieces\"") != std::string::npos);
    }
}

TEST_CASE("bricks: pqdc --min-component out of core streams and writes the in-core bytes", "[bricks][cli]") {
    pqdc_test::ScratchDir dir("bricks_cli_islands");
    auto grid = sphere(40, {0, 20, -30}, 4.0);
    grid->setName("sphere");
    pqdc::add_gaussian_noise(*grid, 0.35, 5);
    pqdc::write_grid(*grid, dir.path("in.vdb"));
    const std::vector<std::string> base{"in.vdb", "-q", "--sigma-n", "0", "--denoise", "off", "--min-component", "3.5",
                                        "--stats"};
    auto run = [&](const std::string& out, const std::string& stats, std::vector<std::string> extra) {
        std::vector<std::string> args = base;
        args.push_back(stats);
        args.insert(args.end(), {"-o", out});
        args.insert(args.end(), extra.begin(), extra.end());
        const auto r = pqdc_in(dir, args);
        INFO(r.err);
        REQUIRE(r.exit_code == 0);
    };
    run("in.ply", "in.json", {});
    const std::string in_stats = file_bytes(dir.path("in.json"));
    REQUIRE(in_stats.find("\"removed\": 0") == std::string::npos);  // islands were removed
    for (const std::vector<std::string>& extra :
         {std::vector<std::string>{"--out-of-core"}, {"--brick-size", "128", "--vertex-normals"}}) {
        INFO(extra.back());
        run("ooc.ply", "ooc.json", extra);
        if (extra.back() == "--vertex-normals") run("in.ply", "in.json", {"--vertex-normals"});
        CHECK(file_bytes(dir.path("ooc.ply")) == file_bytes(dir.path("in.ply")));
        const std::string ooc_stats = file_bytes(dir.path("ooc.json"));
        CHECK(ooc_stats.find("\"write pieces\"") != std::string::npos);  // streamed
        const auto block = [](const std::string& json) { return json.substr(json.find("\"components\": {")); };
        CHECK(block(ooc_stats) == block(file_bytes(dir.path("in.json"))));
    }
}

TEST_CASE("bricks: a brick over --memory-limit points to --brick-size, which works", "[bricks][cli]") {
    // It said only "raise --memory-limit" after the in-core run had said
    // "add --out-of-core": two pieces of advice, the second one failing too.
    pqdc_test::ScratchDir dir("bricks_advice");
    REQUIRE(pqdc_in(dir, {"--procedural", "figure3", "--resolution", "256", "--write-volume", "f.vdb", "-q"})
                .exit_code == 0);
    const auto r = pqdc_in(dir, {"f.vdb", "--out-of-core", "--memory-limit", "40", "-o", "g.ply", "-q"});
    CHECK(r.exit_code == 1);
    CHECK(r.err.find("smaller bricks need less: --brick-size, down to 128") != std::string::npos);
    CHECK(pqdc_in(dir, {"f.vdb", "--brick-size", "128", "--memory-limit", "40", "-o", "g.ply", "-q"}).exit_code == 0);
}

TEST_CASE("bricks: pqdc goes out of core when the grid exceeds --memory-limit, uniform and adaptive",
          "[bricks][adaptive][cli]") {
    // A 17 MiB grid, a small region of it: only the grid does not fit in 8 MiB.
    pqdc_test::ScratchDir dir("bricks_auto");
    REQUIRE(pqdc_in(dir, {"--procedural", "sphere", "--resolution", "300", "--write-volume", "s.vdb", "-q"})
                .exit_code == 0);
    for (const std::vector<std::string>& mode : {std::vector<std::string>{}, {"--adaptive"}}) {
        INFO(mode.size() << " mode options");
        std::vector<std::string> args{"s.vdb", "-o", "plain.ply", "--bbox", "-1,-1,0.95,1,1,1"};
        args.insert(args.end(), mode.begin(), mode.end());
        REQUIRE(pqdc_in(dir, args).exit_code == 0);
        args[2] = "auto.ply";
        args.insert(args.end(), {"--memory-limit", "8"});
        const auto r = pqdc_in(dir, args);
        INFO(r.err);
        REQUIRE(r.exit_code == 0);
        CHECK(r.err.find("brick by brick") != std::string::npos);
        REQUIRE(file_bytes(dir.path("auto.ply")).size() > 1000);
        REQUIRE(file_bytes(dir.path("auto.ply")) == file_bytes(dir.path("plain.ply")));
    }
}

TEST_CASE("bricks: an empty out-of-core mesh is explained without reading the volume", "[bricks][cli]") {
    pqdc_test::ScratchDir dir("bricks_empty");
    auto grid = sphere(20, {0, 0, 0});
    grid->setName("ball");
    pqdc::write_grid(*grid, dir.path("in.vdb"));
    const auto outside = pqdc_in(dir, {"in.vdb", "-o", "a.ply", "--bbox", "100,100,100,101,101,101"});
    INFO(outside.err);
    CHECK(outside.exit_code == 0);
    CHECK(outside.err.find("no surface in grid 'ball' inside the region") != std::string::npos);
    const auto beyond = pqdc_in(dir, {"in.vdb", "-o", "b.ply", "--out-of-core", "--isovalue", "50"});
    INFO(beyond.err);
    CHECK(beyond.exit_code == 0);
    CHECK(beyond.err.find("meshed out of core; its value range was not read") != std::string::npos);
    // In core the range is read and named.
    const auto in_core = pqdc_in(dir, {"in.vdb", "-o", "c.ply", "--isovalue", "50"});
    CHECK(in_core.err.find("the isovalue 50 is outside that range") != std::string::npos);
}

TEST_CASE("bricks: pqdc refuses bad brick options, naming them", "[bricks][cli]") {
    pqdc_test::ScratchDir dir("bricks_errors");
    auto grid = sphere(20, {0, 0, 0});
    pqdc::write_grid(*grid, dir.path("in.vdb"));
    const std::vector<std::pair<std::vector<std::string>, std::string>> cases = {
        {{"--brick-size", "100"}, "--brick-size"},
        {{"--brick-size", "8192"}, "--brick-size"},
        {{"--brick-size", "abc"}, "--brick-size"},
        {{"--brick-runs", "0"}, "--brick-runs"},
        {{"--brick-runs", "65"}, "--brick-runs"},
    };
    for (const auto& [extra, named] : cases) {
        std::vector<std::string> args{"in.vdb", "-o", "out.ply"};
        args.insert(args.end(), extra.begin(), extra.end());
        const auto r = pqdc_in(dir, args);
        INFO(extra[0] << " " << extra[1] << ": " << r.err);
        CHECK(r.exit_code == 2);
        CHECK(r.err.find(named) != std::string::npos);
        CHECK(!std::filesystem::exists(dir.path("out.ply")));
    }
}

#ifdef PQDC_BRICKS_PATH
TEST_CASE("bricks: pqdc meshes a pqdc-bricks store with the .vdb's bytes", "[bricks][cli]") {
    pqdc_test::ScratchDir dir("bricks_store");
    auto grid = sphere(60, {-10, 0, 30});
    pqdc::write_grid(*grid, dir.path("in.vdb"));
    split_into_store(dir);
    pqdc_test::RunSpec spec;
    spec.cwd = dir.dir();
    REQUIRE(pqdc_in(dir, {"in.vdb", "-o", "a.ply", "-q"}).exit_code == 0);
    REQUIRE(pqdc_in(dir, {"in.bricks", "-o", "b.ply", "-q"}).exit_code == 0);
    REQUIRE(file_bytes(dir.path("a.ply")).size() > 10000);
    REQUIRE(file_bytes(dir.path("a.ply")) == file_bytes(dir.path("b.ply")));
    // The streamed run opens the store file by file (pqdc::BrickStore): another grid is refused by name.
    const auto other = pqdc_in(dir, {"in.bricks", "--grid", "nope", "-o", "c.ply", "-q"});
    CHECK(other.exit_code != 0);
    CHECK(other.err.find("holds grid") != std::string::npos);
    CHECK(other.err.find("'nope'") != std::string::npos);
    CHECK(other.err.find("drop --grid") != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(dir.path("c.ply")));
    spec.args = {"split", "in.vdb", "-o", "in.bricks"};  // not empty any more
    CHECK(pqdc_test::run_program(PQDC_BRICKS_PATH, spec).exit_code == 1);
    spec.args = {"split", "in.vdb", "-o", "other", "--brick-size", "300"};
    const auto bad = pqdc_test::run_program(PQDC_BRICKS_PATH, spec);
    CHECK(bad.exit_code == 2);
    CHECK(bad.err.find("--brick-size") != std::string::npos);
    // A write that fails (a file size limit) leaves no half store that
    // would block the next try, and says why; the new directory goes too.
    spec.args = {"split", "in.vdb", "-o", "cut.bricks", "--brick-size", "128"};
    spec.file_size_limit_bytes = 4096;
    const auto cut = pqdc_test::run_program(PQDC_BRICKS_PATH, spec);
    CHECK(cut.exit_code == 1);
    CHECK(cut.err.find("File too large") != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(dir.path("cut.bricks")));
    // Files without an index (an interrupted pqdc-bricks) are named an incomplete store.
    std::filesystem::create_directories(dir.path("half.bricks"));
    std::filesystem::copy_file(dir.path("in.bricks/grid.vdb"), dir.path("half.bricks/grid.vdb"));
    const auto half = pqdc_in(dir, {"half.bricks", "-o", "h.ply", "-q"});
    CHECK(half.exit_code == 1);
    CHECK(half.err.find("incomplete brick store") != std::string::npos);
}

TEST_CASE("bricks: pqdc-bricks procedural writes a store with the sampled volume's bytes", "[bricks][cli]") {
    pqdc_test::ScratchDir dir("bricks_procedural");
    REQUIRE(pqdc_in(dir, {"--procedural", "figure3", "--resolution", "200", "--write-volume", "f.vdb", "-q"})
                .exit_code == 0);
    pqdc_test::RunSpec spec;
    spec.cwd = dir.dir();
    spec.args = {"procedural", "figure3", "--resolution", "200", "-o", "f.bricks", "--brick-size", "128"};
    const auto made = pqdc_test::run_program(PQDC_BRICKS_PATH, spec);
    INFO(made.err);
    REQUIRE(made.exit_code == 0);
    REQUIRE(pqdc_in(dir, {"f.vdb", "-o", "a.ply", "-q"}).exit_code == 0);
    REQUIRE(pqdc_in(dir, {"f.bricks", "-o", "b.ply", "-q"}).exit_code == 0);
    REQUIRE(file_bytes(dir.path("a.ply")).size() > 10000);
    REQUIRE(file_bytes(dir.path("a.ply")) == file_bytes(dir.path("b.ply")));
    const std::vector<std::pair<std::vector<std::string>, std::string>> refused = {
        {{"procedural", "torus", "-o", "t.bricks"}, "torus"},
        {{"procedural", "sphere", "-o", "t.bricks", "--active-band", "-2"}, "--active-band"},
        {{"procedural", "sphere", "-o", "t.bricks", "--grid", "g"}, "--grid"},
        {{"split", "f.vdb", "-o", "t.bricks", "--resolution", "64"}, "--resolution"},
        {{"procedural", "sphere", "-o", "t.bricks", "--resolution", "2"}, "--resolution"},
    };
    for (const auto& [args, named] : refused) {
        spec.args = args;
        const auto r = pqdc_test::run_program(PQDC_BRICKS_PATH, spec);
        INFO(args[1] << ": " << r.err);
        CHECK(r.exit_code == 2);
        CHECK(r.err.find(named) != std::string::npos);
        CHECK(!std::filesystem::exists(dir.path("t.bricks/index.txt")));
    }
    // A missing parent directory is an error, as for every file pqdc writes (it made the whole path).
    spec.args = {"procedural", "sphere", "-o", "no/such/dir/t.bricks", "--resolution", "64"};
    const auto nested = pqdc_test::run_program(PQDC_BRICKS_PATH, spec);
    CHECK(nested.exit_code == 1);
    CHECK(nested.err.find("does not exist; create it first") != std::string::npos);
    CHECK(!std::filesystem::exists(dir.path("no")));
}

TEST_CASE("bricks: pqdc-bricks interrupted leaves no store and no brick files", "[bricks][cli][robust]") {
    // Figure 3 at 1024 cells in 128-voxel bricks: about a hundred brick
    // files over several seconds. The signal comes while they are written
    // (each brick is checked for it) or, on a slow start, before: either way
    // nothing may be left, and an existing directory stays, empty. It left
    // the bricks written so far, which blocked the next try ("not empty").
    pqdc_test::ScratchDir dir("bricks_interrupt");
    std::filesystem::create_directory(dir.path("kept"));
    for (const auto& [sig, out] :
         {std::pair<int, std::string>{SIGINT, "new.bricks"}, {SIGTERM, "kept"}, {SIGHUP, "hup.bricks"}}) {
        pqdc_test::RunSpec spec;
        spec.cwd = dir.dir();
        spec.args = {"procedural", "figure3", "--resolution", "1024", "-o", out, "--brick-size", "128"};
        spec.signal = sig;
        // Late enough that the handler is installed even under a sanitizer on a
        // busy machine (at 1.5 s an ASan run once died of the signal itself).
        spec.signal_after_seconds = 3.0;
        const auto r = pqdc_test::run_program(PQDC_BRICKS_PATH, spec);
        INFO(out << ": " << r.err);
        CHECK(r.exit_code == 128 + sig);
        CHECK(r.err.find("interrupted; no store written") != std::string::npos);
        CHECK(dir.entries() == std::vector<std::string>{"kept"});
        CHECK(std::filesystem::is_empty(dir.path("kept")));
    }
}

TEST_CASE("adaptive bricks: pqdc --adaptive meshes a store and out of core with the in-core bytes",
          "[bricks][adaptive][cli]") {
    pqdc_test::ScratchDir dir("adaptive_bricks_cli");
    auto grid = sphere(60, {-10, 0, 30});
    grid->setName("sphere");
    pqdc::write_grid(*grid, dir.path("in.vdb"));
    REQUIRE(pqdc_in(dir, {"in.vdb", "--adaptive", "-o", "plain.ply", "-q"}).exit_code == 0);
    const std::string expected = file_bytes(dir.path("plain.ply"));
    REQUIRE(expected.size() > 10000);
    REQUIRE(expected != [&] {  // adaptive differs from uniform: the runs below are adaptive ones
        REQUIRE(pqdc_in(dir, {"in.vdb", "-o", "uniform.ply", "-q"}).exit_code == 0);
        return file_bytes(dir.path("uniform.ply"));
    }());
    for (const std::vector<std::string>& extra :
         {std::vector<std::string>{"--out-of-core"}, {"--brick-size", "128", "--threads", "1"}}) {
        std::vector<std::string> args{"in.vdb", "--adaptive", "-o", "bricks.ply", "-q"};
        args.insert(args.end(), extra.begin(), extra.end());
        const auto r = pqdc_in(dir, args);
        INFO(extra[0] << ": " << r.err);
        REQUIRE(r.exit_code == 0);
        REQUIRE(file_bytes(dir.path("bricks.ply")) == expected);
    }
    split_into_store(dir);
    REQUIRE(pqdc_in(dir, {"in.bricks", "--adaptive", "-o", "store.ply", "-q"}).exit_code == 0);
    REQUIRE(file_bytes(dir.path("store.ply")) == expected);
    // The library's normals and component filter on the assembled adaptive mesh, read node by node.
    const std::vector<std::string> more{"--vertex-normals", "--min-component", "3.5"};
    std::vector<std::string> args{"in.vdb", "--adaptive", "-o", "plain_n.ply", "-q"};
    args.insert(args.end(), more.begin(), more.end());
    REQUIRE(pqdc_in(dir, args).exit_code == 0);
    const std::string with_normals = file_bytes(dir.path("plain_n.ply"));
    REQUIRE(with_normals.find("property float nx") != std::string::npos);
    args[0] = "in.bricks";
    args[3] = "store_n.ply";
    REQUIRE(pqdc_in(dir, args).exit_code == 0);
    CHECK(file_bytes(dir.path("store_n.ply")) == with_normals);
}

#endif  // PQDC_BRICKS_PATH

#endif  // PQDC_CLI_PATH

}  // namespace
