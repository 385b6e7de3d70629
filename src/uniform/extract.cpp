// Uniform dual contouring with probabilistic plane quadrics: the driver.
//
// The pipeline, each stage in the file named after it; every stage is
// leaf-parallel and deterministic (per-leaf counts, an exclusive prefix sum,
// then each leaf fills its own slice of preallocated arrays), in the manner
// of OpenVDB's VolumeToMesh::operator():
//   candidates      lattice/candidates.hpp       blocks that may hold a cell with an active corner
//   noise estimate  lattice/noise_estimate.hpp   residuals of local linear fits near the surface
//   (parameters)    lattice/auto_parameters.cpp  sigma_n, gradient stencil, quadric filter
//   cells           per candidate leaf, with its values fetched once:
//                     fetch           lattice/value_block.hpp
//                     classify        uniform/classify.cpp (configurations, ambiguous faces)
//                     place vertices  uniform/place_vertices.hpp (Hermite samples, quadrics, filter, solve)
//   gather          per-leaf vertex lists concatenated in leaf order
//   faces           uniform/faces.cpp (one quad or two triangles per crossing edge)
//   untangle        uniform/untangle.cpp: the quad-star check and the repair of
//                   lattice/untangle.cpp towards the safe positions (uniform/safe_positions.cpp)
//                   (no self-intersections), then unused vertices are dropped
// The stages that read values do so through a values policy: InCoreValues
// (the whole tree in memory), for pqdc::extract_bricks BrickValues
// (scale/brick_values.hpp: one brick's copy at a time), and for
// pqdc::extract_distributed DistributedValues (scale/distributed_values.hpp:
// each rank its own bricks, the results gathered at rank 0). Same bytes.
#include "pqdc/extract.hpp"
#include "pqdc/brick_store.hpp"
#include "pqdc/bricks.hpp"
#include "pqdc/distributed.hpp"

#include "io/mesh_stream_impl.hpp"
#include "lattice/auto_parameters.hpp"
#include "lattice/candidates.hpp"
#include "lattice/crossings.hpp"
#include "lattice/interior.hpp"
#include "lattice/noise_estimate.hpp"
#include "lattice/region.hpp"
#include "lattice/resources.hpp"
#include "lattice/smooth_field.hpp"
#include "lattice/stage_timer.hpp"
#include "lattice/transform.hpp"
#include "lattice/untangle.hpp"
#include "normals/outward_normal.hpp"
#include "postprocess/islands.hpp"
#include "pqdc/exceptions.hpp"
#include "scale/brick_values.hpp"
#include "scale/distributed_values.hpp"
#include "scale/rank_exchange.hpp"
#include "scale/source_values.hpp"
#include "scale/stream_components.hpp"
#include "scale/store_source.hpp"
#include "scale/stream_cells.hpp"
#include "scale/stream_numbering.hpp"
#include "scale/stream_output.hpp"
#include "scale/stream_untangle.hpp"
#include "scale/thread_shares.hpp"
#include "uniform/cell_tree.hpp"
#include "uniform/cells.hpp"
#include "uniform/faces.hpp"
#include "uniform/safe_positions.hpp"
#include "uniform/untangle.hpp"

#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <memory>
#include <string>
#include <vector>

namespace pqdc::detail {
namespace {

/// The values of a tree held in memory, read directly (the in-core run).
/// The brick driver's counterpart is scale/brick_values.hpp.
template <class TreeT>
class InCoreValues {
public:
    using Tree = TreeT;
    InCoreValues(const TreeT& tree, const Signing& signing) : tree_(tree), signing_(signing) {}

    /// Memory per candidate leaf that is checked before stage "cells": all
    /// its results may be held at once (here, every candidate a surface leaf).
    static constexpr double kCandidateBytes = double(LeafResults::kEntryBytes + kCellRecordBytes);

    std::vector<openvdb::Coord> candidate_blocks(const ExtractOptions& options, const openvdb::CoordBBox& clip) const {
        return detail::candidate_blocks(tree_, kCandidateBytes, options, clip);
    }

    NoiseEstimate estimate_noise(const std::vector<openvdb::Coord>& leaves) const {
        return detail::estimate_noise(tree_, signing_, leaves);
    }

    /// Stage "cells" over every candidate leaf; with `smooth`, of the smoothed field.
    template <class Stage>
    void run_cells(Stage& stage, bool smooth, const Progress& progress, StageTimer& timer) const {
        std::unique_ptr<TreeT> smoothed;
        if (smooth) {
            const ProgressSpan smoothing(progress, 0.0, 0.0);
            smoothed = smooth_field(tree_, signing_, &smoothing);
            timer.done("smooth field");
        }
        stage.run(smoothed ? *smoothed : tree_, 0, stage.leaves().size(), progress, 0.0, 0.45);
    }

private:
    const TreeT& tree_;
    const Signing& signing_;
};

/// Stage "gather": the cell leaves into one tree (faces look up neighbours
/// across leaves) and the per-leaf vertex lists into mesh.points, in leaf order.
void gather_vertices(LeafResults& r, const ExtractOptions& options, const Progress& progress, CellTree& cells,
                     std::vector<CellLeaf*>& leaves, std::vector<std::uint64_t>& first, Mesh& mesh) {
    const std::size_t n = r.cells.size();
    leaves.assign(n, nullptr);
    {
        openvdb::tree::ValueAccessor<CellTree, false> acc(cells);
        for (std::size_t i = 0; i < n; ++i)
            if (r.cells[i]) {
                leaves[i] = r.cells[i].get();
                acc.addLeaf(r.cells[i].release());
            }
    }
    first.assign(n + 1, 0);
    for (std::size_t i = 0; i < n; ++i) first[i + 1] = first[i] + r.points[i].size();
    const std::uint64_t nverts = first.back();
    if (nverts >= (std::uint64_t(1) << 32))
        throw resource_error("the mesh would have " + std::to_string(nverts) +
                             " vertices, more than 32-bit face indices can address; mesh the volume in parts");
    check_memory(double(nverts) * double(2 * sizeof(openvdb::Vec3d) + 2 * 3 * sizeof(openvdb::Vec3I)), options, "mesh");
    mesh.points.resize(nverts);
    parallel_chunks(n, progress, 0.45, 0.46, [&](std::size_t i) {
        std::copy(r.points[i].begin(), r.points[i].end(), mesh.points.begin() + std::ptrdiff_t(first[i]));
        std::vector<openvdb::Vec3d>().swap(r.points[i]);
    });
}

/// Stages "cells", "gather", "faces" and "untangle" with one crossing oracle,
/// reading values through `values` (InCoreValues or BrickValues).
template <class Values, class Oracle>
Mesh mesh_cells(const Values& values, const Signing& signing, const Oracle& oracle, const LatticeTransform& xf,
                const Region& region, const std::vector<openvdb::Coord>& leaves, const ChosenParameters& chosen,
                const Progress& progress, StageTimer& timer, ExtractStats& stats) {
    LeafResults results(leaves.size());
    {
        CellStage<typename Values::Tree, Oracle> stage(signing, oracle, xf, region, leaves, chosen, results);
        values.run_cells(stage, chosen.smooth_field, progress, timer);
        stage.add_stats(stats);
    }
    timer.done("cells");
    // The last read of the values: the caller may free its grid before the
    // mesh's arrays exist (ExtractOptions::values_done), unless it will
    // read it again (normals at the end, or to explain an empty mesh).
    const bool faces = std::any_of(results.faces.begin(), results.faces.end(), [](std::uint32_t n) { return n > 0; });
    if (chosen.options.values_done && faces && !chosen.options.vertex_normals) chosen.options.values_done();

    // From here on the whole mesh is in memory, also when meshing brick by
    // brick (issue 14, phase 1); streaming these stages is the next phase.
    CellTree cells(CellValue(0));
    std::vector<CellLeaf*> cell_leaves;
    std::vector<std::uint64_t> first;
    Mesh mesh;
    gather_vertices(results, chosen.options, progress, cells, cell_leaves, first, mesh);
    stats.vertices = mesh.points.size();
    return_freed_memory();  // the per-leaf vertex lists, before the faces and safe positions
    timer.done("gather");

    count_boundary_crossings(cells, cell_leaves, results.faces, results.incidences, progress, stats);
    std::vector<std::uint8_t> sides;
    build_quads(cells, cell_leaves, first, results.faces, xf, chosen.options, progress, mesh, sides);
    count_faces(chosen.options, mesh.quads.size(), stats);
    // What the check needs of the cell records (8 bytes a vertex), then
    // the records go: freed before the triangles (24 bytes a quad against
    // the quads' 16) and the check, they are not part of the run's peak.
    VertexCells vertex_cells(cell_leaves, first, mesh.points.size());
    cell_leaves.clear();
    cells.clear();
    results = LeafResults(0);
    // Hand the freed records back: glibc keeps them in its arenas (fragments
    // of many per-leaf vectors), and the check below would grow past them.
    // Measured on a 12.7 M-voxel sphere: 230 MB less peak RSS.
    return_freed_memory();
    if (chosen.options.faces == FaceType::triangles) split_quads(sides, xf, chosen.options, mesh);
    std::vector<std::uint8_t>().swap(sides);
    timer.done("faces");

    untangle_lattice_mesh(mesh, std::move(vertex_cells), xf, chosen.options, progress, stats);
    drop_unused_vertices(mesh);
    stats.vertices = mesh.points.size();
    timer.done("untangle");
    progress.report(1.0);
    return mesh;
}

/// The set-up stages (candidates, noise estimate, parameters), then
/// mesh_with(oracle, region, leaves, chosen, progress, timer) for the rest.
/// For grids the automatic settings look at the noise estimate; procedural
/// fields (FieldKind::analytic) have exact crossings and normals.
template <class Values, class OracleFor, class Mesher>
Mesh extract_tree_with(const Values& values, const LatticeTransform& xf, const ExtractOptions& options,
                       FieldKind kind, const OracleFor& with_oracle, ExtractStats& stats, const Mesher& mesh_with) {
    const Progress progress(options);
    StageTimer timer(stats);
    const Region region(options.region, *xf.transform);
    const std::vector<openvdb::Coord> leaves = values.candidate_blocks(options, region.cell_bounds());
    if (leaves.size() >= (std::size_t(1) << 32))  // a cell leaf's index is its 32-bit transient data
        throw resource_error("the volume has too many leaf nodes to mesh in one piece; mesh it in parts");
    timer.done("candidates");
    progress.report(0.0);  // cancellation points between the set-up stages

    const NoiseEstimate noise = kind == FieldKind::analytic ? NoiseEstimate{} : values.estimate_noise(leaves);
    const ChosenParameters chosen = choose_parameters(options, noise, kind);
    record_parameters(chosen, kind, stats);
    timer.done("noise estimate");
    progress.report(0.0);

    Mesh mesh = with_oracle(chosen.options.normals, [&](const auto& oracle) {
        return mesh_with(oracle, region, leaves, chosen, progress, timer);
    });
    timer.finish();
    return mesh;
}

/// The whole pipeline over the values behind `values` (InCoreValues or
/// BrickValues), the mesh in memory.
template <class Values, class OracleFor>
Mesh extract_tree(const Values& values, const Signing& signing, const LatticeTransform& xf,
                  const ExtractOptions& options, FieldKind kind, const OracleFor& with_oracle,
                  ExtractStats& stats) {
    return extract_tree_with(values, xf, options, kind, with_oracle, stats, [&](const auto& oracle, auto&... a) {
        return mesh_cells(values, signing, oracle, xf, a..., stats);
    });
}

/// Where a streamed run writes: the writer (each rank's receives its part,
/// finished by the caller with finish(group)), the hook each piece passes,
/// the ranks that share the run, and how many runs of bricks each process
/// meshes at once (BrickOptions::concurrent_runs).
struct StreamTarget {
    MeshStreamWriter& out;
    const std::function<void(Mesh&)>& each_piece;
    RankGroup& group;
    int concurrent_runs = 1;
    /// each_piece must see the pieces in file order, on one thread (a
    /// caller's hook): concurrent runs then send theirs to run 0.
    bool pieces_in_order = false;
};

/// The streamed pipeline (issue 14, phases 2 and 3) over values read brick
/// by brick, the mesh never whole in memory, for rank `group.rank()` of the
/// ranks (or in-process shares) that each mesh their own run of bricks:
//   cells and faces  scale/stream_cells.hpp      each brick with a one-leaf halo, to
//                                                 scratch files; the first exact check
//   numbering        scale/stream_numbering.hpp  the ranks' vertex counts exchanged
//   untangle         scale/stream_untangle.hpp   only near that check's findings
//   write pieces     scale/stream_output.hpp     moves applied, unused vertices dropped
/// Same bytes and counters as mesh_cells(). Returns false, having written
/// nothing, when a vertex lies 1.5 voxels or more from its cell's center
/// (containment off; every rank agrees): the untangle stage is not local then.
template <class TreeT, class Oracle>
bool stream_share(const BrickValues<TreeT>& values, const Signing& signing, const Oracle& oracle,
                  const LatticeTransform& xf, const Region& region, const std::vector<openvdb::Coord>& leaves,
                  const ChosenParameters& chosen, const Progress& progress, StageTimer& timer, ExtractStats& stats,
                  RankGroup& group, const StreamTarget& target) {
    StreamScratch scratch(target.out.path(), chosen.options.faces == FaceType::quads);
    const StreamedCells mine = stream_cells(values, signing, oracle, xf, region, leaves, chosen, group.rank(),
                                            group.size(), progress, 0.0, 0.8, scratch);
    const StreamNumbering numbering = number_streamed(mine, leaves.size(), scratch, group);
    timer.done("cells and faces");
    if (!(numbering.counts.max_offset < kStreamMaxOffset)) return false;
    numbering.counts.add_to(stats, chosen.options.faces == FaceType::triangles);

    UntangleSettings untangling;
    untangling.stored = chosen.options.stored_precision;
    untangling.progress = [&progress](double f) {
        progress.report(0.8 + 0.05 * f);
        return true;
    };
    UntangleCounters c;
    const std::vector<MovedVertex> moved =
        untangle_streamed(scratch, numbering.seeds, numbering.counts.max_offset, numbering.vertices, xf, untangling,
                          chosen.options, c, group);
    if (c.pairs_before != numbering.counts.pairs)
        throw std::logic_error("internal error: the streamed untangle stage found " + std::to_string(c.pairs_before) +
                               " intersecting pairs where the bricks found " + std::to_string(numbering.counts.pairs) +
                               "; nothing was written. Please report this with the input and options");
    c.add_to(stats);
    timer.done("untangle");

    if (chosen.options.min_component_voxels > 0) {
        remove_streamed_islands(scratch, moved, numbering.foreign, component_voxel_size(*xf.transform),
                                chosen.options.min_component_voxels, group, stats.components);
        (chosen.options.faces == FaceType::triangles ? stats.triangles : stats.quads) -= stats.components.removed_faces;
        timer.done("components");
    }

    const UsedNumbering used = number_used(scratch, numbering.foreign, group);
    stats.vertices = used.total;  // before the pieces: report_input's edge count looks at it
    // Each rank or concurrent run formats its own part, unless a hook must see the pieces in order.
    const bool distributed = &group == &target.group && group.size() > 1;
    const PieceParts parts =
        distributed || !target.pieces_in_order ? PieceParts::each_rank_its_writer : PieceParts::all_to_rank_0;
    if (distributed) StreamWriterParts::hold_rank_part(target.out);
    // Concurrent runs call the caller's hook from their own threads, and it
    // reads run 0's counts (the vertex count just set): a barrier orders them.
    else if (group.size() > 1 && parts == PieceParts::each_rank_its_writer) all_gather(group, std::string());
    write_streamed(scratch, used, numbering.foreign, moved, group, parts, target.out, target.each_piece,
                   ProgressSpan(progress, 0.85, 1.0));
    timer.done("write pieces");
    return true;
}

/// Memory per candidate leaf of one run of bricks: its cells-stage entry
/// and its first vertex's number.
constexpr double kRunLeafBytes = double(LeafResults::kEntryBytes + sizeof(std::uint64_t));

/// BrickOptions::concurrent_runs, resolved for `leaves` candidate leaves.
int concurrent_runs(int asked, std::size_t leaves, const ExtractOptions& options) {
    if (asked > 0) return asked;
    int n = int(std::min<std::size_t>({4, std::size_t(tbb::this_task_arena::max_concurrency()),
                                       tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism)}));
    while (n > 1 && double(n) * double(leaves) * kRunLeafBytes > double(memory_limit(options)) / 8) --n;
    return std::max(n, 1);
}

/// stream_share() on `runs` threads of this process at once, each an
/// in-process rank with its own run of bricks (scale/thread_shares.hpp).
/// Run 0, on this thread, reports progress, times the stages and counts;
/// the others only stop when asked. Returns what stream_share() returns.
template <class TreeT, class Oracle>
bool stream_in_runs(int runs, const BrickValues<TreeT>& values, const Signing& signing, const Oracle& oracle,
                    const LatticeTransform& xf, const Region& region, const std::vector<openvdb::Coord>& leaves,
                    const ChosenParameters& chosen, const Progress& progress, StageTimer& timer, ExtractStats& stats,
                    const StreamTarget& target) {
    bool streamed = false;
    // Runs after the first format their pieces into writers of their own,
    // appended to the caller's in run order at the end.
    std::vector<std::unique_ptr<MeshStreamWriter>> parts(static_cast<std::size_t>(runs));
    for (std::size_t r = 1; r < parts.size() && !target.pieces_in_order; ++r)
        parts[r] = StreamWriterParts::sibling(target.out);
    run_in_shares(runs, [&](RankGroup& share, const std::function<bool()>& wanted) {
        if (share.rank() == 0) {
            streamed = stream_share(values, signing, oracle, xf, region, leaves, chosen, progress, timer, stats, share,
                                    target);
            return;
        }
        ExtractOptions quiet = chosen.options;
        quiet.progress = [&wanted](double) { return wanted(); };
        const Progress stop_when_asked(quiet);
        ExtractStats ignored;
        StageTimer untimed(ignored);
        MeshStreamWriter& out = parts[std::size_t(share.rank())] ? *parts[std::size_t(share.rank())] : target.out;
        const StreamTarget own{out, target.each_piece, target.group, target.concurrent_runs, target.pieces_in_order};
        stream_share(values, signing, oracle, xf, region, leaves, chosen, stop_when_asked, untimed, ignored, share,
                     own);
    });
    if (streamed)
        for (std::size_t r = 1; r < parts.size(); ++r)
            if (parts[r]) StreamWriterParts::absorb(target.out, *parts[r]);
    return streamed;
}

/// The streamed pipeline, run as target says: on this process alone, in
/// concurrent runs, or as one rank of several. When the untangle stage is
/// not local (stream_share), the mesh is assembled in memory instead,
/// reading values through `whole` (BrickValues or DistributedValues), and
/// written in one piece. Returns an empty mesh: the mesh went to `target`.
template <class TreeT, class Whole, class Oracle>
Mesh stream_cells_to(const BrickValues<TreeT>& values, const Whole& whole, const Signing& signing,
                     const Oracle& oracle, const LatticeTransform& xf, const Region& region,
                     const std::vector<openvdb::Coord>& leaves, const ChosenParameters& chosen,
                     const Progress& progress, StageTimer& timer, ExtractStats& stats, const StreamTarget& target) {
    const int runs = target.group.size() == 1 ? concurrent_runs(target.concurrent_runs, leaves.size(), chosen.options) : 1;
    const bool streamed =
        runs > 1 ? stream_in_runs(runs, values, signing, oracle, xf, region, leaves, chosen, progress, timer, stats, target)
                 : stream_share(values, signing, oracle, xf, region, leaves, chosen, progress, timer, stats,
                                target.group, target);
    if (streamed) return {};
    Mesh mesh = mesh_cells(whole, signing, oracle, xf, region, leaves, chosen, progress, timer, stats);
    if (target.group.rank() != 0) return {};
    remove_islands(mesh, *xf.transform, chosen.options, stats);
    if (target.each_piece) target.each_piece(mesh);
    target.out.append(mesh);
    return {};
}

/// How a run reads the volume's values: in core (`bricks` null), brick by
/// brick, or brick by brick shared among the ranks of `group`.
struct ValueReading {
    const BrickOptions* bricks = nullptr;
    RankGroup* group = nullptr;  ///< with bricks: extract_distributed
};

void check_reading(const ValueReading& reading) {
    if (reading.bricks) validate(*reading.bricks);
    if (reading.group) check_rank_group(*reading.group);
}

/// body(values) with `tree`'s values read as `reading` says: the runs
/// differ only here.
template <class TreeT, class Body>
Mesh with_values(const TreeT& tree, const Signing& signing, const ValueReading& reading, const Body& body) {
    if (!reading.bricks) return body(InCoreValues<TreeT>(tree, signing));
    const TreeBrickSource<TreeT> source(tree);
    if (reading.group) return body(DistributedValues<TreeT>(source, signing, reading.bricks->brick_size, *reading.group));
    return body(BrickValues<TreeT>(source, signing, reading.bricks->brick_size));
}

/// What a grid's run decides before it reads any value: the map to world
/// space, the interior rule and the kind of field.
struct GridSetUp {
    LatticeTransform xf;
    InteriorChoice interior;
    Signing signing;
    FieldKind kind;
};

/// The set-up of meshing `grid` with (validated) `options`.
template <class GridT>
GridSetUp set_up(const GridT& grid, const ExtractOptions& options) {
    GridSetUp g{check_transform(grid.transform(), grid.getName()), choose_interior(grid, options), {}, {}};
    g.signing = signing_for(g.interior, options);
    g.kind = field_kind(g.signing, g.xf.cubic);
    return g;
}

template <class GridT>
Mesh extract_grid(const GridT& grid, const ExtractOptions& options, const ValueReading& reading,
                  ExtractStats* stats_out) {
    validate(options);
    check_reading(reading);
    const GridSetUp g = set_up(grid, options);
    ExtractStats stats;
    ExtractOptions run = options;
    // What report_input() reads of a freed grid: its active voxels (a mask
    // tree, a bit per voxel), kept only when its warning may need them.
    std::unique_ptr<openvdb::MaskTree> active;
    if (options.values_done)
        run.values_done = [&] {
            if (isovalue_is_background(grid, options)) return;  // the warning reads values
            if (may_warn_of_active_edge_after_cells(stats))
                active = std::make_unique<openvdb::MaskTree>(grid.tree(), false, openvdb::TopologyCopy());
            options.values_done();
            return_freed_memory();  // before the mesh's arrays: the peak drops by the grid
        };
    Mesh mesh = with_values(grid.tree(), g.signing, reading, [&](const auto& values) {
        return extract_tree(values, g.signing, g.xf, run, g.kind, GridOracles{}, stats);
    });
    remove_islands(mesh, grid.transform(), options, stats);
    report_input(grid, g.interior, options, mesh.points.size(), [&] {
        if (!active) return vertices_at_active_edge(grid, mesh);
        return vertices_at_active_edge(grid.transform(), mesh, [&](const openvdb::Coord& c) { return active->isValueOn(c); });
    }, stats);
    if (options.vertex_normals) add_vertex_normals(mesh, grid, g.interior.side, reading.bricks);
    if (stats_out) *stats_out = std::move(stats);
    return mesh;
}

/// The streamed run (stream_cells_to) of the volume behind `source`, read
/// brick by brick by the ranks of `group`. `grid`: the volume's grid, or a
/// brick store's shell; only its metadata, transform and background are
/// read here, every voxel's state and value through `source`.
template <class GridT>
void stream_source(const GridT& grid, const BrickSource<typename GridT::TreeType>& source,
                   const ExtractOptions& options, const BrickOptions& bricks, RankGroup& group, MeshStreamWriter& out,
                   const std::function<void(Mesh&)>& each_piece, ExtractStats* stats_out) {
    if (options.vertex_normals != out.with_normals())
        throw option_error(std::string("ExtractOptions::vertex_normals is ") +
                           (options.vertex_normals ? "set but the writer for '" : "not set but the writer for '") +
                           out.path() + "' was made " + (out.with_normals() ? "with" : "without") +
                           " normals; make the two agree");
    const GridSetUp g = set_up(grid, options);
    ExtractStats stats;
    // Each piece's normals read the raw values leaf by leaf, as the in-core run reads the grid.
    using TreeT = typename GridT::TreeType;
    const SourceValues<TreeT> raw(source);
    // For report_input, counted as the pieces pass when it may warn (concurrent runs count theirs at once).
    std::atomic<std::int64_t> at_edge{0};
    const std::function<void(Mesh&)> piece = [&](Mesh& mesh) {
        if (options.vertex_normals) mesh.normals = outward_normals(raw, grid.transform(), g.signing.sign, mesh.points);
        if (may_warn_of_active_edge(stats))
            at_edge += vertices_at_active_edge(grid.transform(), mesh,
                                               [&](const openvdb::Coord& p) { return source.is_value_on(p); });
        if (each_piece) each_piece(mesh);
    };
    const StreamTarget target{out, piece, group, bricks.concurrent_runs, bool(each_piece)};
    const BrickValues<TreeT> values(source, g.signing, bricks.brick_size, &group);
    const auto stream = [&](const auto& whole) {
        extract_tree_with(values, g.xf, options, g.kind, GridOracles{}, stats, [&](const auto& oracle, auto&... a) {
            return stream_cells_to(values, whole, g.signing, oracle, g.xf, a..., stats, target);
        });
    };
    if (group.size() == 1) stream(values);
    else stream(DistributedValues<TreeT>(source, g.signing, bricks.brick_size, group));
    std::int64_t edge = at_edge;
    if (group.size() > 1) {  // each rank saw its own pieces
        edge = 0;
        for (std::int64_t n : all_gather_values(group, std::vector<std::int64_t>{at_edge}, "the active-edge counts")) edge += n;
    }
    report_input(grid, g.interior, options, stats.vertices, [&] { return edge; }, stats);
    if (stats_out) *stats_out = std::move(stats);
}

/// stream_source() of a grid whose tree is in memory or delay-loaded.
template <class GridT>
void stream_grid(const GridT& grid, const ExtractOptions& options, const BrickOptions& bricks, RankGroup& group,
                 MeshStreamWriter& out, const std::function<void(Mesh&)>& each_piece, ExtractStats* stats_out) {
    validate(options);
    validate(bricks);
    check_rank_group(group);
    const TreeBrickSource<typename GridT::TreeType> source(grid.tree());
    stream_source(grid, source, options, bricks, group, out, each_piece, stats_out);
}

/// f(the grid as a FloatGrid or DoubleGrid); input_error for other value types.
template <class F>
auto with_scalar_grid(const openvdb::GridBase& grid, const F& f) {
    if (const auto* typed = dynamic_cast<const openvdb::FloatGrid*>(&grid)) return f(*typed);
    if (const auto* typed = dynamic_cast<const openvdb::DoubleGrid*>(&grid)) return f(*typed);
    throw input_error("grid '" + grid.getName() + "' holds " + grid.valueType() +
                      " values; pqdc meshes scalar float or double grids (convert it, or pick another grid with --grid)");
}

/// extract_grid for a float or double grid; other types throw input_error.
Mesh extract_any_grid(const openvdb::GridBase& grid, const ExtractOptions& options, const ValueReading& reading,
                      ExtractStats* stats) {
    return with_scalar_grid(grid, [&](const auto& typed) { return extract_grid(typed, options, reading, stats); });
}


/// stream_source() of a brick store read file by file (StoreBrickSource),
/// or of its assembled grid when the options need the whole topology.
void stream_store(const BrickStore& store, const ExtractOptions& options, const BrickOptions& bricks,
                  RankGroup& group, MeshStreamWriter& out, const std::function<void(Mesh&)>& each_piece,
                  ExtractStats* stats) {
    validate(options);
    validate(bricks);
    check_rank_group(group);
    if (store.assembles_for(options)) {
        const LoadedGrid whole = read_brick_store(store.path());
        with_scalar_grid(*whole.grid,
                         [&](const auto& typed) { stream_grid(typed, options, bricks, group, out, each_piece, stats); });
        return;
    }
    with_scalar_grid(store.shell(), [&](const auto& shell) {
        using TreeT = typename std::decay_t<decltype(shell)>::TreeType;
        const StoreBrickSource<TreeT> source(store.index(), shell.tree(), memory_limit(options) / 8);
        stream_source(shell, source, options, bricks, group, out, each_piece, stats);
    });
}
}  // namespace
}  // namespace pqdc::detail

namespace pqdc {

Mesh extract(const openvdb::FloatGrid& grid, const ExtractOptions& options, ExtractStats* stats) {
    return detail::extract_grid(grid, options, {}, stats);
}

Mesh extract(const openvdb::DoubleGrid& grid, const ExtractOptions& options, ExtractStats* stats) {
    return detail::extract_grid(grid, options, {}, stats);
}

Mesh extract(const openvdb::GridBase& grid, const ExtractOptions& options, ExtractStats* stats) {
    return detail::extract_any_grid(grid, options, {}, stats);
}

namespace {

/// Every procedural run: the sampled grid in memory, values read as
/// `reading` says.
Mesh extract_procedural(const ScalarField& field, const ProceduralSampling& sampling, const ExtractOptions& options,
                        const detail::ValueReading& reading, ExtractStats* stats) {
    validate(options);
    detail::check_reading(reading);
    const openvdb::FloatGrid::Ptr grid = sample_field(field, sampling);
    const detail::LatticeTransform xf = detail::check_transform(grid->transform(), "procedural");
    const detail::Signing signing;  // sampled values are f itself: inside negative, surface at 0
    const detail::ExactOracle oracle{field, grid->transform()};
    const auto with_oracle = [&](GridNormals, const auto& body) { return body(oracle); };
    ExtractStats s;
    // The samples are this run's own: freed once read, as a caller may free a grid.
    ExtractOptions run = options;
    run.values_done = [&grid] {
        grid->clear();
        detail::return_freed_memory();
    };
    Mesh mesh = detail::with_values(grid->tree(), signing, reading, [&](const auto& values) {
        return detail::extract_tree(values, signing, xf, run, detail::FieldKind::analytic, with_oracle, s);
    });
    s.interior = "below";
    s.interior_reason = "procedural field: inside negative";
    detail::remove_islands(mesh, grid->transform(), options, s);
    if (options.vertex_normals) compute_outward_vertex_normals(mesh, field);
    if (stats) *stats = std::move(s);
    return mesh;
}

template <class TreeT>
std::uint64_t tree_bytes(const TreeT& tree) {
    // An out-of-core leaf's memUsage counts its file reference, not its values.
    std::uint64_t unloaded = 0;
    for (auto it = tree.cbeginLeaf(); it; ++it) unloaded += it->buffer().isOutOfCore();
    return tree.memUsage() + unloaded * TreeT::LeafNodeType::SIZE * sizeof(typename TreeT::ValueType);
}

}  // namespace

Mesh extract(const ScalarField& field, const ProceduralSampling& sampling, const ExtractOptions& options,
             ExtractStats* stats) {
    return extract_procedural(field, sampling, options, {}, stats);
}

void validate(const BrickOptions& options) {
    const int s = options.brick_size;
    if (s < 128 || s > 4096 || (s & (s - 1)))
        throw option_error("BrickOptions::brick_size is " + std::to_string(s) +
                           "; it must be a power of two from 128 to 4096 (voxels)");
    if (options.concurrent_runs < 0 || options.concurrent_runs > 64)
        throw option_error("BrickOptions::concurrent_runs is " + std::to_string(options.concurrent_runs) +
                           "; it must be 0 (automatic) or 1 to 64");
}

Mesh extract_bricks(const openvdb::FloatGrid& grid, const ExtractOptions& options, const BrickOptions& bricks,
                    ExtractStats* stats) {
    return detail::extract_grid(grid, options, {&bricks}, stats);
}

Mesh extract_bricks(const openvdb::DoubleGrid& grid, const ExtractOptions& options, const BrickOptions& bricks,
                    ExtractStats* stats) {
    return detail::extract_grid(grid, options, {&bricks}, stats);
}

Mesh extract_bricks(const openvdb::GridBase& grid, const ExtractOptions& options, const BrickOptions& bricks,
                    ExtractStats* stats) {
    return detail::extract_any_grid(grid, options, {&bricks}, stats);
}

void extract_bricks(const openvdb::GridBase& grid, const ExtractOptions& options, const BrickOptions& bricks,
                    MeshStreamWriter& out, const std::function<void(Mesh&)>& each_piece, ExtractStats* stats) {
    detail::SoloRank one;
    detail::with_scalar_grid(
        grid, [&](const auto& typed) { detail::stream_grid(typed, options, bricks, one, out, each_piece, stats); });
}

Mesh extract_bricks(const ScalarField& field, const ProceduralSampling& sampling, const ExtractOptions& options,
                    const BrickOptions& bricks, ExtractStats* stats) {
    return extract_procedural(field, sampling, options, {&bricks}, stats);
}

Mesh extract_distributed(const openvdb::GridBase& grid, const ExtractOptions& options, const BrickOptions& bricks,
                         RankGroup& group, ExtractStats* stats) {
    return detail::extract_any_grid(grid, options, {&bricks, &group}, stats);
}

void extract_distributed(const openvdb::GridBase& grid, const ExtractOptions& options, const BrickOptions& bricks,
                         RankGroup& group, MeshStreamWriter& out, const std::function<void(Mesh&)>& each_piece,
                         ExtractStats* stats) {
    detail::with_scalar_grid(
        grid, [&](const auto& typed) { detail::stream_grid(typed, options, bricks, group, out, each_piece, stats); });
}

void extract_bricks(const BrickStore& store, const ExtractOptions& options, const BrickOptions& bricks,
                    MeshStreamWriter& out, const std::function<void(Mesh&)>& each_piece, ExtractStats* stats) {
    detail::SoloRank one;
    detail::stream_store(store, options, bricks, one, out, each_piece, stats);
}

void extract_distributed(const BrickStore& store, const ExtractOptions& options, const BrickOptions& bricks,
                         RankGroup& group, MeshStreamWriter& out, const std::function<void(Mesh&)>& each_piece,
                         ExtractStats* stats) {
    detail::stream_store(store, options, bricks, group, out, each_piece, stats);
}

Mesh extract_distributed(const ScalarField& field, const ProceduralSampling& sampling, const ExtractOptions& options,
                         const BrickOptions& bricks, RankGroup& group, ExtractStats* stats) {
    return extract_procedural(field, sampling, options, {&bricks, &group}, stats);
}

std::uint64_t effective_memory_limit(const ExtractOptions& options) { return detail::memory_limit(options); }

std::uint64_t in_core_bytes(const openvdb::GridBase& grid) {
    if (const auto* f = dynamic_cast<const openvdb::FloatGrid*>(&grid)) return tree_bytes(f->tree());
    if (const auto* d = dynamic_cast<const openvdb::DoubleGrid*>(&grid)) return tree_bytes(d->tree());
    return grid.memUsage();
}

}  // namespace pqdc
