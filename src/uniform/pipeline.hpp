// The uniform pipeline's stages strung together, for every way of reading
// the values. The in-core driver (uniform/extract.cpp) and the brick and
// distributed drivers (scale/extract_bricks.cpp) differ only in the values
// policy they pass, so all three give the same bytes:
//   values.candidate_blocks(options, clip)   stage "candidates"
//   values.estimate_noise(leaves)            stage "noise estimate"
//   values.run_cells(stage, smooth, ...)     stage "cells" over every candidate leaf
// and, one level up, in the reading policy that makes the values:
//   reading.check()                          throws option_error for its own options
//   reading.with_values(tree, signing, body) body(values)
//   reading.by_bricks()                      vertex normals read node by node too
#pragma once

#include "lattice/auto_parameters.hpp"
#include "lattice/candidates.hpp"
#include "lattice/crossings.hpp"
#include "lattice/interior.hpp"
#include "lattice/procedural_grid.hpp"
#include "lattice/region.hpp"
#include "lattice/resources.hpp"
#include "lattice/stage_timer.hpp"
#include "lattice/index_range.hpp"
#include "lattice/transform.hpp"
#include "lattice/untangle.hpp"
#include "normals/outward_normal.hpp"
#include "postprocess/islands.hpp"
#include "pqdc/exceptions.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/procedural.hpp"
#include "pqdc/vertex_normals.hpp"
#include "uniform/cell_tree.hpp"
#include "uniform/cells.hpp"
#include "uniform/faces.hpp"
#include "uniform/gather.hpp"
#include "uniform/untangle.hpp"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <memory>
#include <string>
#include <vector>

namespace pqdc::detail {

/// Stages "cells", "gather", "faces" and "untangle" with one crossing oracle,
/// reading values through `values`.
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
    // brick; the streamed runs (scale/extract_bricks.cpp) keep it on disk.
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

/// The whole pipeline over the values behind `values`, the mesh in memory.
template <class Values, class OracleFor>
Mesh extract_tree(const Values& values, const Signing& signing, const LatticeTransform& xf,
                  const ExtractOptions& options, FieldKind kind, const OracleFor& with_oracle,
                  ExtractStats& stats) {
    return extract_tree_with(values, xf, options, kind, with_oracle, stats, [&](const auto& oracle, auto&... a) {
        return mesh_cells(values, signing, oracle, xf, a..., stats);
    });
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
    check_index_range(grid.tree(), grid.getName());
    GridSetUp g{check_transform(grid.transform(), grid.getName()), choose_interior(grid, options), {}, {}};
    g.signing = signing_for(g.interior, options);
    g.kind = field_kind(g.signing, g.xf.cubic);
    return g;
}

/// A run of `grid` with the whole mesh in memory, its values read as
/// `reading` says; then small components, the input report and normals.
template <class GridT, class Reading>
Mesh extract_grid(const GridT& grid, const ExtractOptions& options, const Reading& reading, ExtractStats* stats_out) {
    validate(options);
    reading.check();
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
    Mesh mesh = reading.with_values(grid.tree(), g.signing, [&](const auto& values) {
        return extract_tree(values, g.signing, g.xf, run, g.kind, GridOracles{}, stats);
    });
    remove_islands(mesh, grid.transform(), options, stats);
    report_input(grid, g.interior, options, mesh.points.size(), [&] {
        if (!active) return vertices_at_active_edge(grid, mesh);
        using Accessor = openvdb::tree::ValueAccessor<const openvdb::MaskTree, false>;
        return vertices_at_active_edge(grid.transform(), mesh, [&] {
            return [acc = Accessor(*active)](const openvdb::Coord& c) { return acc.isValueOn(c); };
        });
    }, stats);
    if (options.vertex_normals) add_vertex_normals(mesh, grid, g.interior.side, reading.by_bricks());
    if (stats_out) *stats_out = std::move(stats);
    return mesh;
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
template <class Reading>
Mesh extract_any_grid(const openvdb::GridBase& grid, const ExtractOptions& options, const Reading& reading,
                      ExtractStats* stats) {
    return with_scalar_grid(grid, [&](const auto& typed) { return extract_grid(typed, options, reading, stats); });
}

/// A procedural run: the sampled grid in memory, values read as `reading`
/// says, crossings and normals from the field itself.
template <class Reading>
Mesh extract_procedural(const ScalarField& field, const ProceduralSampling& sampling, const ExtractOptions& options,
                        const Reading& reading, ExtractStats* stats) {
    validate(options);
    reading.check();
    const openvdb::FloatGrid::Ptr grid = sample_procedural_grid(field, sampling, options);
    const LatticeTransform xf = check_transform(grid->transform(), "procedural");
    const Signing signing;  // sampled values are f itself: inside negative, surface at 0
    const ExactOracle oracle{field, grid->transform()};
    const auto with_oracle = [&](GridNormals, const auto& body) { return body(oracle); };
    ExtractStats s;
    // The samples are this run's own: freed once read, as a caller may free a grid.
    ExtractOptions run = options;
    run.values_done = [&grid] {
        grid->clear();
        return_freed_memory();
    };
    Mesh mesh = reading.with_values(grid->tree(), signing, [&](const auto& values) {
        return extract_tree(values, signing, xf, run, FieldKind::analytic, with_oracle, s);
    });
    s.interior = "below";
    s.interior_reason = "procedural field: inside negative";
    remove_islands(mesh, grid->transform(), options, s);
    report_empty_field(mesh, options, s);
    if (options.vertex_normals) compute_outward_vertex_normals(mesh, field);
    if (stats) *stats = std::move(s);
    return mesh;
}

}  // namespace pqdc::detail
