// The uniform pipeline brick by brick, in one process or across the ranks
// of a distributed run (issue 14): pqdc::extract_bricks and
// pqdc::extract_distributed.
//
// Two ways, one output, the same bytes as the in-core pqdc::extract:
// - The mesh in memory (the functions that return a Mesh): the in-core
//   pipeline (uniform/pipeline.hpp) with another values policy, BrickValues
//   (scale/brick_values.hpp: one brick's copy at a time) or, across ranks,
//   DistributedValues (scale/distributed_values.hpp: each rank its own
//   bricks, the results gathered at rank 0).
// - Streamed (the functions that take a MeshStreamWriter): the mesh never
//   whole in memory, each rank or concurrent run meshing its own run of
//   bricks through the stages of stream_share() below, from a grid in
//   memory, a delay-loaded grid or a brick store read file by file.
#include "pqdc/brick_store.hpp"
#include "pqdc/bricks.hpp"
#include "pqdc/distributed.hpp"

#include "bricks/source_values.hpp"
#include "bricks/store_source.hpp"
#include "io/mesh_stream_impl.hpp"
#include "ranks/rank_exchange.hpp"
#include "ranks/thread_shares.hpp"
#include "scale/brick_values.hpp"
#include "scale/distributed_values.hpp"
#include "scale/stream_cells.hpp"
#include "scale/stream_components.hpp"
#include "scale/stream_numbering.hpp"
#include "scale/stream_output.hpp"
#include "scale/stream_untangle.hpp"
#include "uniform/pipeline.hpp"

#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace pqdc::detail {
namespace {

/// Throws option_error for bad brick options or an unusable rank group
/// (null: this process alone).
void check_brick_run(const BrickOptions& bricks, RankGroup* group) {
    validate(bricks);
    if (group) check_rank_group(*group);
}

/// The reading policy (uniform/pipeline.hpp) of a run with the mesh in
/// memory and the values read brick by brick, by this process alone or
/// shared among the ranks of `group`.
struct BrickReading {
    const BrickOptions& bricks;
    RankGroup* group = nullptr;  ///< extract_distributed's

    void check() const { check_brick_run(bricks, group); }
    bool by_bricks() const { return true; }
    template <class TreeT, class Body>
    Mesh with_values(const TreeT& tree, const Signing& signing, const Body& body) const {
        const TreeBrickSource<TreeT> source(tree);
        if (group) return body(DistributedValues<TreeT>(source, signing, bricks.brick_size, *group));
        return body(BrickValues<TreeT>(source, signing, bricks.brick_size));
    }
};

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
    warn_unresolved(c, untangling.stored, stats);
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
/// in-process rank with its own run of bricks (ranks/thread_shares.hpp).
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
            at_edge += vertices_at_active_edge(grid.transform(), mesh, [&] {
                return [&](const openvdb::Coord& p) { return source.is_value_on(p); };
            });
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
    report_input(grid, g.interior, options, stats.vertices, [&] { return edge; }, stats, ValuesIn::files);
    if (stats_out) *stats_out = std::move(stats);
}

/// stream_source() of a grid whose tree is in memory or delay-loaded.
template <class GridT>
void stream_grid(const GridT& grid, const ExtractOptions& options, const BrickOptions& bricks, RankGroup& group,
                 MeshStreamWriter& out, const std::function<void(Mesh&)>& each_piece, ExtractStats* stats_out) {
    validate(options);
    check_brick_run(bricks, &group);
    const TreeBrickSource<typename GridT::TreeType> source(grid.tree());
    stream_source(grid, source, options, bricks, group, out, each_piece, stats_out);
}

/// stream_source() of a brick store read file by file (StoreBrickSource),
/// or of its assembled grid when the options need the whole topology.
void stream_store(const BrickStore& store, const ExtractOptions& options, const BrickOptions& bricks,
                  RankGroup& group, MeshStreamWriter& out, const std::function<void(Mesh&)>& each_piece,
                  ExtractStats* stats) {
    validate(options);
    check_brick_run(bricks, &group);
    if (store.assembles_for(options)) {
        const LoadedGrid whole = read_brick_store(store.path());
        with_scalar_grid(*whole.grid,
                         [&](const auto& typed) { stream_grid(typed, options, bricks, group, out, each_piece, stats); });
        return;
    }
    with_scalar_grid(store.shell(), [&](const auto& shell) {
        using TreeT = typename std::decay_t<decltype(shell)>::TreeType;
        const StoreBrickSource<TreeT> source(store.index(), shell, memory_limit(options) / 8);
        stream_source(shell, source, options, bricks, group, out, each_piece, stats);
    });
}

template <class TreeT>
std::uint64_t tree_bytes(const TreeT& tree) {
    // An out-of-core leaf's memUsage counts its file reference, not its values.
    std::uint64_t unloaded = 0;
    for (auto it = tree.cbeginLeaf(); it; ++it) unloaded += it->buffer().isOutOfCore();
    return tree.memUsage() + unloaded * TreeT::LeafNodeType::SIZE * sizeof(typename TreeT::ValueType);
}

}  // namespace
}  // namespace pqdc::detail

namespace pqdc {

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
    return detail::extract_grid(grid, options, detail::BrickReading{bricks}, stats);
}

Mesh extract_bricks(const openvdb::DoubleGrid& grid, const ExtractOptions& options, const BrickOptions& bricks,
                    ExtractStats* stats) {
    return detail::extract_grid(grid, options, detail::BrickReading{bricks}, stats);
}

Mesh extract_bricks(const openvdb::GridBase& grid, const ExtractOptions& options, const BrickOptions& bricks,
                    ExtractStats* stats) {
    return detail::extract_any_grid(grid, options, detail::BrickReading{bricks}, stats);
}

Mesh extract_bricks(const ScalarField& field, const ProceduralSampling& sampling, const ExtractOptions& options,
                    const BrickOptions& bricks, ExtractStats* stats) {
    return detail::extract_procedural(field, sampling, options, detail::BrickReading{bricks}, stats);
}

void extract_bricks(const openvdb::GridBase& grid, const ExtractOptions& options, const BrickOptions& bricks,
                    MeshStreamWriter& out, const std::function<void(Mesh&)>& each_piece, ExtractStats* stats) {
    detail::SoloRank one;
    detail::with_scalar_grid(
        grid, [&](const auto& typed) { detail::stream_grid(typed, options, bricks, one, out, each_piece, stats); });
}

void extract_bricks(const BrickStore& store, const ExtractOptions& options, const BrickOptions& bricks,
                    MeshStreamWriter& out, const std::function<void(Mesh&)>& each_piece, ExtractStats* stats) {
    detail::SoloRank one;
    detail::stream_store(store, options, bricks, one, out, each_piece, stats);
}

Mesh extract_distributed(const openvdb::GridBase& grid, const ExtractOptions& options, const BrickOptions& bricks,
                         RankGroup& group, ExtractStats* stats) {
    return detail::extract_any_grid(grid, options, detail::BrickReading{bricks, &group}, stats);
}

Mesh extract_distributed(const ScalarField& field, const ProceduralSampling& sampling, const ExtractOptions& options,
                         const BrickOptions& bricks, RankGroup& group, ExtractStats* stats) {
    return detail::extract_procedural(field, sampling, options, detail::BrickReading{bricks, &group}, stats);
}

void extract_distributed(const openvdb::GridBase& grid, const ExtractOptions& options, const BrickOptions& bricks,
                         RankGroup& group, MeshStreamWriter& out, const std::function<void(Mesh&)>& each_piece,
                         ExtractStats* stats) {
    detail::with_scalar_grid(
        grid, [&](const auto& typed) { detail::stream_grid(typed, options, bricks, group, out, each_piece, stats); });
}

void extract_distributed(const BrickStore& store, const ExtractOptions& options, const BrickOptions& bricks,
                         RankGroup& group, MeshStreamWriter& out, const std::function<void(Mesh&)>& each_piece,
                         ExtractStats* stats) {
    detail::stream_store(store, options, bricks, group, out, each_piece, stats);
}

std::uint64_t in_core_bytes(const openvdb::GridBase& grid) {
    if (const auto* f = dynamic_cast<const openvdb::FloatGrid*>(&grid)) return detail::tree_bytes(f->tree());
    if (const auto* d = dynamic_cast<const openvdb::DoubleGrid*>(&grid)) return detail::tree_bytes(d->tree());
    return grid.memUsage();
}

std::uint64_t effective_memory_limit(const ExtractOptions& options) { return detail::memory_limit(options); }

}  // namespace pqdc
