// Adaptive extraction (octree dual marching cubes with probabilistic
// quadrics): the driver. See include/pqdc/adaptive.hpp for the method.
//
// The pipeline, each stage in the file named after it, all in index space:
//   candidates  lattice/candidates.hpp   blocks that may hold a cell with an active corner
//   noise estimate lattice/noise_estimate.hpp, then lattice/auto_parameters.cpp
//   smooth field lattice/smooth_field.hpp (noisy grids; the bilateral
//               quadric filter of the uniform extractor is not in the octree yet)
//   hermite     adaptive/finest_level.hpp the finest level: cells, Hermite data, vertices,
//               merged at once into the levels of up to 8-voxel cells brick
//               by brick (adaptive/brick_levels.hpp, finest_bricks.hpp), so
//               that the finest level is never held whole
//   octree      adaptive/simplify.hpp     bottom-up merges of the levels above
//   dual grid   adaptive/dual_grid.cpp    leaf ids, dual cells
//   polygons    adaptive/polygonize.cpp   marching cubes, collapse.cpp, repair.cpp,
//                                         relax.cpp, angle_flips.cpp
//   untangle    adaptive/untangle.hpp     exact check; refine, move, or the uniform mesh
// Untangle first maps the vertices to world space (and flips the winding for
// mirrored transforms) with the lattice transform the uniform extractor uses,
// so that it checks what will be stored.
//
// In core the bricks read the grid itself (slabs of kInCoreBrickSize).
// Brick by brick (pqdc::extract_adaptive_bricks, issue 14) the noise
// estimate, the smooth field and stage "hermite" read the values one brick
// at a time, copied (adaptive/finest_bricks.hpp), and the later stages read
// them leaf by leaf (bricks/source_values.hpp); the nodes are the same,
// so are the bytes.
//
// Progress (and cancellation) comes between chunks of every long stage, so
// that Ctrl-C in Python is answered within a fraction of a second; its
// fractions: candidates and noise estimate to 0.04, smooth field to 0.1,
// hermite to 0.29, octree to 0.4, dual grid to 0.51, polygons to 0.85, the
// check to 0.95, rebuilds in the rest.
#include "pqdc/adaptive.hpp"
#include "pqdc/bricks.hpp"
#include "pqdc/distributed.hpp"

#include "adaptive/bridges.hpp"
#include "adaptive/dual_grid.hpp"
#include "adaptive/field_probe.hpp"
#include "adaptive/finest_bricks.hpp"
#include "adaptive/finest_level.hpp"
#include "adaptive/octree.hpp"
#include "adaptive/polygonize.hpp"
#include "adaptive/simplify.hpp"
#include "normals/outward_normal.hpp"
#include "postprocess/islands.hpp"
#include "bricks/source_values.hpp"
#include "adaptive/untangle.hpp"
#include "lattice/auto_parameters.hpp"
#include "lattice/candidates.hpp"
#include "lattice/crossings.hpp"
#include "lattice/interior.hpp"
#include "lattice/noise_estimate.hpp"
#include "lattice/procedural_grid.hpp"
#include "lattice/region.hpp"
#include "lattice/resources.hpp"
#include "lattice/smooth_field.hpp"
#include "lattice/stage_timer.hpp"
#include "lattice/index_range.hpp"
#include "lattice/transform.hpp"
#include "lattice/untangle.hpp"
#include "pqdc/exceptions.hpp"
#include "pqdc/measure.hpp"
#include "bricks/brick_source.hpp"
#include "scale/brick_values.hpp"
#include "bricks/bricks.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <cmath>
#include <functional>
#include <optional>
#include <string>

namespace pqdc {
namespace {

using namespace adaptive_detail;
using openvdb::Coord;
using detail::StageTimer;

std::string coord_string(const Coord& c) {
    return "(" + std::to_string(c.x()) + ", " + std::to_string(c.y()) + ", " + std::to_string(c.z()) + ")";
}


/// The octree's frame: root size from the options, Morton origin one root
/// below the data (so that root neighbours have codes). Throws input_error
/// when the active voxels span more than the codes can address.
Octree octree_frame(const openvdb::CoordBBox& bbox, const AdaptiveOptions& options, const std::string& name) {
    Octree tree;
    while ((1 << tree.top) < options.max_cell_size_voxels) ++tree.top;
    const int root = 1 << tree.top;
    auto floor_to_root = [&](int v) { return int(std::floor(double(v) / root)) * root; };
    tree.offset = Coord(floor_to_root(bbox.min().x()), floor_to_root(bbox.min().y()), floor_to_root(bbox.min().z())) -
                  Coord(root);
    const Coord span = bbox.max() - tree.offset + Coord(2 * root + 8);
    if (span.x() >= (1 << kCoordBits) || span.y() >= (1 << kCoordBits) || span.z() >= (1 << kCoordBits))
        throw input_error("grid '" + name + "': active voxels span " + coord_string(bbox.dim()) +
                          " voxels, more than the adaptive extractor's 2^19 per axis; crop the grid");
    tree.levels.resize(tree.top + 1);
    return tree;
}

/// Bricks of stage "hermite" in core (a BrickOptions::brick_size: slabs of
/// 128 x 2048 x 4096 voxels). The ring around a brick is built twice, so
/// thin slabs cost time; these cost 1.01-1.09x the wall time of the whole
/// finest level (sphere, fog, armadillo level sets) and hold a slab's finest
/// cells instead of all of them (0.30-0.80x the peak RSS).
constexpr int kInCoreBrickSize = 1024;

/// Stage "hermite"'s counters.
struct FinestTotals {
    std::uint64_t crossings = 0, degenerate = 0, clamped = 0, fallback = 0, cells = 0, non_finite = 0, open = 0;
};

FinestTotals totals_of(const FinestCounters& c) {
    return {c.crossings, c.degenerate, c.clamped, c.fallback, c.cells, c.non_finite, c.open};
}

/// Adds every counter of `from` to `to` (FinestCounters or MergeCounters).
template <class Counters>
void add_counts(const Counters& from, Counters& to) {
    const auto source = counter_fields(from);
    const auto target = counter_fields(to);
    for (std::size_t i = 0; i < source.size(); ++i) *target[i] += source[i]->load();
}

/// Builds tree.levels[0..L], stage "hermite" and the first L merge levels,
/// brick by brick (lower_levels_in_core, or run_by_bricks' copies),
/// counting into the counters; returns L. The pinned cells are the round's.
using LowerLevelsBuilder = std::function<int(Octree&, const PinnedCells&, FinestCounters&, MergeCounters&,
                                             const detail::ProgressSpan&)>;

/// Stages "hermite" to "polygons": the index-space mesh of an octree in
/// which no merged leaf contains a pinned cell. `tree` is the empty frame;
/// `build` makes stage "hermite" and the lowest merge levels; the span
/// covers the four stages.
template <class GridT>
Mesh contour(const GridT& grid, const detail::Signing& signing, const FieldSource& field,
             const AdaptiveOptions& options, const detail::Region& region, Octree tree, const PinnedCells& pinned,
             const ShapeLimits& shape, const LowerLevelsBuilder& build, const detail::ProgressSpan& span,
             StageTimer& timer, AdaptiveStats& stats) {
    MergeCounters merges;
    FinestCounters counts;
    const int built = build(tree, pinned, counts, merges, span.part(0.0, 0.25));
    const FinestTotals finest = totals_of(counts);
    stats.active_cells = finest.cells;
    timer.done("hermite");

    const detail::ProgressSpan octree_span = span.part(0.25, 0.4);
    for (int level = built; level < tree.top; ++level)
        tree.levels[level + 1] = build_parent_level(
            grid, field, tree, level, signing, options, pinned, region, merges,
            octree_span.part(double(level - built) / (tree.top - built), double(level + 1 - built) / (tree.top - built)));
    // The quadrics are done with (the vertices are placed); the dual grid
    // and the polygons need only the tree, so give their memory back.
    for (Level& level : tree.levels) std::vector<CellQuadrics>().swap(level.quadrics);
    timer.done("octree");

    const LeafNumbering numbering = number_leaves(tree);
    const std::vector<DualCell> dual = generate_dual_cells(tree, numbering, span.part(0.4, 0.55));
    timer.done("dual grid");

    Mesh mesh = polygonize_dual_cells(tree, numbering, dual, field, options.base.faces, pinned, shape, stats,
                                      span.part(0.55, 1.0));
    if (!region.unbounded()) {
        detail::keep_faces_in_region(region, mesh);
        stats.vertices = mesh.points.size();
        stats.triangles = mesh.triangles.size();
        stats.quads = mesh.quads.size();
    }
    timer.done("polygons");

    stats.crossing_edges = finest.crossings;
    stats.degenerate_normals = finest.degenerate;
    stats.clamped_vertices = finest.clamped;
    stats.fallback_vertices = finest.fallback;
    stats.non_finite_values = finest.non_finite;
    stats.boundary_crossings = finest.open;
    stats.merges = merges.merges;
    stats.refused_error = merges.refused_error;
    stats.refused_topology = merges.refused_topology;
    stats.refused_containment = merges.refused_containment;
    stats.refused_balance = merges.refused_balance;
    stats.refused_pinned = merges.refused_pinned;
    return mesh;
}

/// Stages "hermite" to "polygons", then "untangle": the world-space mesh.
/// `build`: stage "hermite" and the lowest merge levels, in core or by bricks.
template <class GridT>
Mesh run(const GridT& grid, const detail::LatticeTransform& xf, const detail::Signing& signing,
         const FieldSource& field, const AdaptiveOptions& options, const detail::Region& region, const Octree& frame,
         const UniformFallback& fallback, const detail::Progress& progress, StageTimer& timer, AdaptiveStats& stats,
         const LowerLevelsBuilder& build) {
    const AdaptiveStats before = stats;
    auto rebuild = [&](const PinnedCells& pinned, const ShapeLimits& shape, const detail::ProgressSpan& span,
                       AdaptiveStats& round) {
        round = before;
        StageTimer round_timer(round);
        return contour(grid, signing, field, options, region, frame, pinned, shape, build, span, round_timer, round);
    };
    Mesh mesh = contour(grid, signing, field, options, region, frame, PinnedCells{}, ShapeLimits{}, build,
                        detail::ProgressSpan(progress, 0.1, 0.75), timer, stats);
    PinnedCells pinned;
    mesh = refine_bridges(std::move(mesh), rebuild, field, frame, options.max_error_voxels, pinned,
                          detail::ProgressSpan(progress, 0.75, 0.85), stats);
    timer.done("bridges");
    mesh = untangle_adaptive(std::move(mesh), rebuild, xf, frame, options.base, pinned, fallback, progress, stats);
    timer.done("untangle");
    return mesh;
}

/// A grid holding `tree`, with `grid`'s transform, name and class.
template <class GridT>
typename GridT::Ptr grid_like(const GridT& grid, std::unique_ptr<typename GridT::TreeType> tree) {
    const typename GridT::Ptr out = GridT::create(typename GridT::TreePtrType(std::move(tree)));
    out->setTransform(grid.transform().copy());
    out->setName(grid.getName());
    out->setGridClass(grid.getGridClass());
    return out;
}

/// Stages "hermite" to "untangle" brick by brick (see the file comment):
/// the finest level and the lowest merge levels from `values`' bricks
/// (smoothed first with `smooth`), then the later stages on the source's
/// values read leaf by leaf (smoothed leaf by leaf with `smooth`).
/// `exact_field`: the procedural field, which every merge and the polygons
/// probe instead (null: they probe the values). With a `group` the ranks share the
/// first build's bricks and only rank 0 goes on (the others return an empty
/// mesh); rank 0 alone runs the untangle stage's rebuilds.
template <class GridT, class Oracle>
Mesh run_by_bricks(const detail::BrickValues<typename GridT::TreeType>& values,
                   const detail::LatticeTransform& xf, const detail::Signing& signing, const Oracle& oracle,
                   const FieldSource* exact_field, bool smooth,
                   const AdaptiveOptions& options, const detail::Region& region, const Octree& frame,
                   const std::vector<Coord>& blocks, RankGroup* group, const UniformFallback& fallback,
                   const detail::Progress& progress, StageTimer& timer, AdaptiveStats& stats) {
    // With ranks the levels are built first (the other ranks stop after
    // them) and handed over once; rebuilds (with pinned cells) run the
    // bricks again, as in core they run stage "hermite" again.
    std::optional<Octree> first;
    int first_top = 0;
    FinestCounters first_finest;
    MergeCounters first_merges;
    const LowerLevelsBuilder by_bricks = [&](Octree& tree, const PinnedCells& pinned, FinestCounters& finest,
                                             MergeCounters& merges, const detail::ProgressSpan& span) {
        if (!first)
            return lower_levels_by_bricks<GridT>(values, blocks, smooth, signing, oracle, options, region, pinned,
                                                 exact_field, tree, finest, merges, progress, span);
        for (int level = 0; level <= first_top; ++level) tree.levels[level] = std::move(first->levels[level]);
        first.reset();
        add_counts(first_finest, finest);
        add_counts(first_merges, merges);
        return first_top;
    };
    // The later stages read the source's values leaf by leaf, smoothed as
    // in core with `smooth` (bricks/source_values.hpp), or the procedural field.
    // Smoothed leaves (noisy grids) are costly to make again: their caches
    // may take a sixteenth of the memory limit.
    using Near = detail::SourceValues<typename GridT::TreeType>;
    const std::size_t cache_leaves = Near::cache_leaves_for(smooth, detail::memory_limit(options.base) / 16,
                                                            tbb::this_task_arena::max_concurrency());
    const Near near(values.source(), smooth ? &signing : nullptr, cache_leaves);
    const GridField<Near> near_field(near, signing);
    const FieldSource& probed = exact_field ? *exact_field : near_field;
    if (group) {
        first = frame;
        first_top = lower_levels_by_bricks<GridT>(values, blocks, smooth, signing, oracle, options, region,
                                                  PinnedCells{}, exact_field, *first, first_finest, first_merges,
                                                  progress, detail::ProgressSpan(progress, 0.04, 0.1), group);
        if (group->rank() != 0) return Mesh{};
    }
    return run(near, xf, signing, probed, options, region, frame, fallback, progress, timer, stats, by_bricks);
}

/// How a run reads the volume's values: in core (`bricks` null), brick by
/// brick, or brick by brick shared among the ranks of `group`.
struct ValueReading {
    const BrickOptions* bricks = nullptr;
    RankGroup* group = nullptr;  ///< with bricks: extract_adaptive_distributed
};

/// The whole pipeline; FieldKind::analytic: procedural crossings (no noise
/// estimate). `reading`: in core, brick by brick or shared among ranks.
template <class GridT, class OracleFor>
Mesh extract_tree(const GridT& grid, const detail::LatticeTransform& xf, const detail::Signing& signing,
                  const FieldSource& field, const AdaptiveOptions& options, detail::FieldKind kind,
                  const OracleFor& with_oracle, const UniformFallback& fallback, const ValueReading& reading,
                  AdaptiveStats& stats) {
    const detail::Progress progress(options.base);
    StageTimer timer(stats);
    progress.report(0.0);
    const std::string name = grid.getName().empty() ? std::string("(unnamed)") : grid.getName();
    const openvdb::CoordBBox bbox = grid.evalActiveVoxelBoundingBox();
    if (bbox.empty()) {
        timer.finish();
        return Mesh{};
    }
    Octree tree = octree_frame(bbox, options, name);
    const detail::Region region(options.base.region, *xf.transform);
    std::vector<Coord> blocks = detail::candidate_blocks(
        grid.tree(), double(sizeof(openvdb::MaskTree::LeafNodeType) + sizeof(Coord)), options.base,
        region.cell_bounds());
    timer.done("candidates");
    progress.report(0.02);

    using TreeT = typename GridT::TreeType;
    const detail::TreeBrickSource<TreeT> brick_source(grid.tree());
    std::optional<detail::BrickValues<TreeT>> values;
    if (reading.bricks) values.emplace(brick_source, signing, reading.bricks->brick_size);
    const detail::NoiseEstimate noise = kind == detail::FieldKind::analytic ? detail::NoiseEstimate{}
                                        : values ? values->estimate_noise(blocks)
                                                 : detail::estimate_noise(grid.tree(), signing, blocks);
    detail::ChosenParameters chosen = detail::choose_parameters(options.base, noise, kind);
    chosen.filter = {};  // not in the octree yet
    detail::record_parameters(chosen, kind, stats);
    AdaptiveOptions resolved = options;
    resolved.base = chosen.options;
    timer.done("noise estimate");
    progress.report(0.04);
    if (values) {
        Mesh mesh = with_oracle(resolved.base.normals, [&](const auto& oracle) {
            const FieldSource* exact = kind == detail::FieldKind::analytic ? &field : nullptr;
            return run_by_bricks<GridT>(*values, xf, signing, oracle, exact, chosen.smooth_field, resolved,
                                 region, tree, blocks, reading.group, fallback, progress, timer, stats);
        });
        timer.finish();
        progress.report(1.0);
        return mesh;
    }

    typename GridT::Ptr smoothed;
    std::optional<GridField<GridT>> smoothed_field;
    if (chosen.smooth_field) {
        const detail::ProgressSpan smoothing(progress, 0.04, 0.1);
        smoothed = grid_like(grid, detail::smooth_field(grid.tree(), signing, &smoothing));
        smoothed_field.emplace(*smoothed, signing);
        timer.done("smooth field");
        progress.report(0.1);
    }
    const GridT& source = smoothed ? *smoothed : grid;
    const FieldSource& source_field = smoothed_field ? static_cast<const FieldSource&>(*smoothed_field) : field;
    Mesh mesh = with_oracle(resolved.base.normals, [&](const auto& oracle) {
        const FieldSource* exact = kind == detail::FieldKind::analytic ? &field : nullptr;
        const LowerLevelsBuilder in_bricks = [&](Octree& t, const PinnedCells& pinned, FinestCounters& finest,
                                                 MergeCounters& merges, const detail::ProgressSpan& span) {
            return lower_levels_in_core(source, blocks, kInCoreBrickSize, signing, oracle, resolved, region, pinned,
                                        exact, t, finest, merges, span);
        };
        return run(source, xf, signing, source_field, resolved, region, tree, fallback, progress, timer, stats,
                   in_bricks);
    });
    timer.finish();
    progress.report(1.0);
    return mesh;
}

/// The uniform options for untangle's fallback: the same, with progress
/// continuing from `from` to the end of the adaptive run's range.
ExtractOptions fallback_options(const ExtractOptions& base, double from) {
    ExtractOptions o = base;
    // The adaptive run removes islands from and adds normals to whichever mesh it returns.
    o.vertex_normals = false;
    o.min_component_voxels = 0;
    o.values_done = nullptr;  // the adaptive run reads the grid to its end
    if (base.progress) o.progress = [cb = base.progress, from](double f) { return cb(from + (1.0 - from) * f); };
    return o;
}

/// Validates what `reading` names.
void check_reading(const ValueReading& reading) {
    if (reading.bricks) validate(*reading.bricks);
    if (reading.group) detail::check_rank_group(*reading.group);
}

/// stats.boundary_crossings counts the finest level's crossings that lack
/// a cell: where a uniform mesh is open. The octree can close them (leaves
/// without a value take their neighbours' side); then the count, which
/// summaries report as "open where ...", goes to 0.
void recount_open_crossings(const Mesh& mesh, AdaptiveStats& s) {
    if (s.boundary_crossings && !mesh.points.empty() && measure_topology(mesh).boundary_edge_count == 0)
        s.boundary_crossings = 0;
}

/// `reading`: see ValueReading; the fallback meshes by bricks too, on rank 0
/// alone (the other ranks have stopped).
template <class GridT>
Mesh extract_grid(const GridT& grid, const AdaptiveOptions& options, const ValueReading& reading,
                  AdaptiveStats* stats) {
    validate(options);
    check_reading(reading);
    detail::check_index_range(grid.tree(), grid.getName());
    const detail::LatticeTransform xf = detail::check_transform(grid.transform(), grid.getName());
    const InteriorChoice interior = choose_interior(grid, options.base);
    const detail::Signing signing = detail::signing_for(interior, options.base);
    const GridField<GridT> field(grid, signing);
    AdaptiveStats s;
    const UniformFallback fallback = [&](ExtractStats& u, double from) {
        return reading.bricks ? extract_bricks(grid, fallback_options(options.base, from), *reading.bricks, &u)
                              : extract(grid, fallback_options(options.base, from), &u);
    };
    Mesh mesh = extract_tree(grid, xf, signing, field, options, detail::field_kind(signing, xf.cubic),
                             detail::GridOracles{}, fallback, reading, s);
    recount_open_crossings(mesh, s);
    detail::remove_islands(mesh, grid.transform(), options.base, s);
    detail::report_input(grid, interior, options.base, mesh, s);
    if (options.base.vertex_normals) detail::add_vertex_normals(mesh, grid, interior.side, reading.bricks);
    if (stats) *stats = std::move(s);
    return mesh;
}

/// extract_grid for a float or double grid; other types throw input_error.
Mesh extract_any_grid(const openvdb::GridBase& grid, const AdaptiveOptions& options, const ValueReading& reading,
                      AdaptiveStats* stats) {
    if (const auto* f = dynamic_cast<const openvdb::FloatGrid*>(&grid)) return extract_grid(*f, options, reading, stats);
    if (const auto* d = dynamic_cast<const openvdb::DoubleGrid*>(&grid)) return extract_grid(*d, options, reading, stats);
    throw input_error("grid '" + grid.getName() + "' holds " + grid.valueType() +
                      " values; pqdc meshes scalar float or double grids (convert it, or pick another grid with --grid)");
}

/// The procedural run: the sampled grid in memory (on every rank), stage
/// "hermite" as `reading` says.
Mesh extract_procedural(const ScalarField& field, const ProceduralSampling& sampling, const AdaptiveOptions& options,
                        const ValueReading& reading, AdaptiveStats* stats) {
    validate(options);
    check_reading(reading);
    const openvdb::FloatGrid::Ptr grid = detail::sample_procedural_grid(field, sampling, options.base);
    const detail::LatticeTransform xf = detail::check_transform(grid->transform(), "procedural");
    const ProceduralField exact(field, grid->transform());
    const detail::ExactOracle oracle{field, grid->transform()};
    AdaptiveStats s;
    const UniformFallback fallback = [&](ExtractStats& u, double from) {
        return reading.bricks
                   ? extract_bricks(field, sampling, fallback_options(options.base, from), *reading.bricks, &u)
                   : extract(field, sampling, fallback_options(options.base, from), &u);
    };
    Mesh mesh = extract_tree(*grid, xf, detail::Signing{}, exact, options, detail::FieldKind::analytic,
                             [&](GridNormals, const auto& body) { return body(oracle); }, fallback, reading, s);
    s.interior = "below";
    s.interior_reason = "procedural field: inside negative";
    recount_open_crossings(mesh, s);
    detail::remove_islands(mesh, grid->transform(), options.base, s);
    detail::report_empty_field(mesh, options.base, s);
    if (options.base.vertex_normals) compute_outward_vertex_normals(mesh, field);
    if (stats) *stats = std::move(s);
    return mesh;
}

}  // namespace

Mesh extract_adaptive(const openvdb::FloatGrid& grid, const AdaptiveOptions& options, AdaptiveStats* stats) {
    return extract_grid(grid, options, {}, stats);
}

Mesh extract_adaptive(const openvdb::DoubleGrid& grid, const AdaptiveOptions& options, AdaptiveStats* stats) {
    return extract_grid(grid, options, {}, stats);
}

Mesh extract_adaptive(const openvdb::GridBase& grid, const AdaptiveOptions& options, AdaptiveStats* stats) {
    return extract_any_grid(grid, options, {}, stats);
}

Mesh extract_adaptive(const ScalarField& field, const ProceduralSampling& sampling, const AdaptiveOptions& options,
                      AdaptiveStats* stats) {
    return extract_procedural(field, sampling, options, {}, stats);
}

Mesh extract_adaptive_bricks(const openvdb::FloatGrid& grid, const AdaptiveOptions& options,
                             const BrickOptions& bricks, AdaptiveStats* stats) {
    return extract_grid(grid, options, {&bricks}, stats);
}

Mesh extract_adaptive_bricks(const openvdb::DoubleGrid& grid, const AdaptiveOptions& options,
                             const BrickOptions& bricks, AdaptiveStats* stats) {
    return extract_grid(grid, options, {&bricks}, stats);
}

Mesh extract_adaptive_bricks(const openvdb::GridBase& grid, const AdaptiveOptions& options,
                             const BrickOptions& bricks, AdaptiveStats* stats) {
    return extract_any_grid(grid, options, {&bricks}, stats);
}

Mesh extract_adaptive_bricks(const ScalarField& field, const ProceduralSampling& sampling,
                             const AdaptiveOptions& options, const BrickOptions& bricks, AdaptiveStats* stats) {
    return extract_procedural(field, sampling, options, {&bricks}, stats);
}

Mesh extract_adaptive_distributed(const openvdb::GridBase& grid, const AdaptiveOptions& options,
                                  const BrickOptions& bricks, RankGroup& group, AdaptiveStats* stats) {
    return extract_any_grid(grid, options, {&bricks, &group}, stats);
}

Mesh extract_adaptive_distributed(const ScalarField& field, const ProceduralSampling& sampling,
                                  const AdaptiveOptions& options, const BrickOptions& bricks, RankGroup& group,
                                  AdaptiveStats* stats) {
    return extract_procedural(field, sampling, options, {&bricks, &group}, stats);
}

}  // namespace pqdc
