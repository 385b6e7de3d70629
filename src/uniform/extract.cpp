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
//   untangle        lattice/untangle.cpp with uniform/safe_positions.cpp (no
//                   self-intersections), then unused vertices are dropped
#include "pqdc/extract.hpp"

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
#include "lattice/value_block.hpp"
#include "pqdc/exceptions.hpp"
#include "uniform/cell_tree.hpp"
#include "uniform/classify.hpp"
#include "uniform/faces.hpp"
#include "uniform/place_vertices.hpp"
#include "uniform/safe_positions.hpp"
#include "uniform/region_cells.hpp"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace pqdc::detail {
namespace {

/// What the cells stage leaves per candidate leaf.
struct LeafResults {
    std::vector<std::unique_ptr<CellLeaf>> cells;
    std::vector<std::vector<openvdb::Vec3d>> points;
    std::vector<std::uint32_t> faces, incidences;

    explicit LeafResults(std::size_t n) : cells(n), points(n), faces(n, 0), incidences(n, 0) {}
};

/// Stage "cells": fetch, classify and place vertices, one pass per leaf so
/// that its values are fetched once.
template <class TreeT, class Oracle>
void extract_cells(const TreeT& src, const Signing& signing, const Oracle& oracle, const LatticeTransform& xf,
                   const Region& region, const std::vector<openvdb::Coord>& leaves, const ChosenParameters& chosen,
                   const Progress& progress, LeafResults& out, ExtractStats& stats) {
    const ExtractOptions& options = chosen.options;
    const int margin = hermite_margin(Oracle::kMargin, chosen.filter);
    // Not registered with the tree (the tree is const here): cheap to create.
    using Accessor = openvdb::tree::ValueAccessor<const TreeT, /*IsSafe=*/false>;
    struct Scratch {
        DenseBlock block;
        DenseBlock wide;  // margin > 1: the same points with more margin, for stencils and the filter
        LeafCells classified;
        CrossingCache cache;
        place_detail::OwnQuadrics own;
        std::vector<std::uint32_t> first_vertex;
        VertexCounters counters;
        std::uint64_t non_finite = 0, cells = 0;
        std::optional<Accessor> acc;  // kept across leaves: neighbouring leaves share nodes
        std::optional<Region::Probe> in_region;
    };
    tbb::enumerable_thread_specific<Scratch> scratch;
    parallel_chunks(leaves.size(), progress, 0.0, 0.45, [&](std::size_t li) {
        const openvdb::Coord origin = leaves[li];
        Scratch& s = scratch.local();
        if (!s.acc) s.acc.emplace(src);
        if (!corners_may_cross(*s.acc, origin, signing)) return;
        // One point below (lower neighbours, gradient stencil), two above
        // (corners, upper neighbours, gradient stencil).
        fetch_block(*s.acc, origin - openvdb::Coord(1), kLeafDim + 3, signing, s.block);
        if (block_is_one_sided(s.block)) return;
        classify_leaf(s.block, s.classified);
        s.non_finite += s.classified.non_finite;
        if (!region.unbounded()) {
            if (!s.in_region) s.in_region.emplace(region);
            restrict_leaf_cells(s.block, origin, *s.in_region, s.classified);
        }
        if (s.classified.cells.empty()) return;
        if (margin > 1) fetch_block(*s.acc, origin - openvdb::Coord(margin), kLeafDim + 1 + 2 * margin, signing, s.wide);
        const DenseBlock& hermite_block = margin > 1 ? s.wide : s.block;
        place_leaf_vertices(oracle, hermite_block, s.classified, origin, xf, options, chosen.filter, s.cache,
                                s.own, out.points[li], s.first_vertex, s.counters);
        auto leaf = std::make_unique<CellLeaf>(origin, std::int64_t(0), false);
        for (std::size_t i = 0; i < s.classified.cells.size(); ++i) {
            const ClassifiedCell& c = s.classified.cells[i];
            leaf->setValueOn(CellLeaf::coordToOffset(origin + c.local),
                             pack_cell(c.config, c.joined, s.first_vertex[i], std::int64_t(li)));
        }
        s.cells += s.classified.cells.size();
        out.cells[li] = std::move(leaf);
        out.faces[li] = s.classified.faces;
        out.incidences[li] = s.classified.incidences;
    });
    for (const Scratch& s : scratch) {
        stats.degenerate_normals += s.cache.degenerate_owned;
        stats.clamped_vertices += s.counters.clamped;
        stats.fallback_vertices += s.counters.fallback;
        stats.multi_vertex_cells += s.counters.multi;
        stats.non_finite_values += s.non_finite;
        stats.active_cells += s.cells;
    }
}

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

/// Stages "cells", "gather", "faces" and "untangle" with one crossing oracle.
template <class TreeT, class Oracle>
Mesh mesh_cells(const TreeT& tree, const Signing& signing, const Oracle& oracle, const LatticeTransform& xf,
                const Region& region, const std::vector<openvdb::Coord>& leaves, const ChosenParameters& chosen,
                const Progress& progress, StageTimer& timer, ExtractStats& stats) {
    LeafResults results(leaves.size());
    extract_cells(tree, signing, oracle, xf, region, leaves, chosen, progress, results, stats);
    timer.done("cells");

    CellTree cells(std::int64_t(0));
    std::vector<CellLeaf*> cell_leaves;
    std::vector<std::uint64_t> first;
    Mesh mesh;
    gather_vertices(results, chosen.options, progress, cells, cell_leaves, first, mesh);
    stats.vertices = mesh.points.size();
    timer.done("gather");

    build_faces(cells, cell_leaves, first, results.faces, results.incidences, xf, chosen.options, progress, mesh,
                stats);
    timer.done("faces");

    UntangleSettings untangling;
    untangling.stored = chosen.options.stored_precision;
    untangling.progress = [&progress](double f) {
        progress.report(0.5 + 0.45 * f);  // the exact check is about half of a clean run's time
        return true;
    };
    untangle_mesh(mesh, safe_positions(cell_leaves, first, mesh.points.size(), xf), xf, untangling, stats);
    drop_unused_vertices(mesh);
    stats.vertices = mesh.points.size();
    timer.done("untangle");
    progress.report(1.0);
    return mesh;
}

/// The whole pipeline. For grids the automatic settings look at the noise
/// estimate; procedural fields (FieldKind::analytic) have exact crossings
/// and normals.
template <class TreeT, class OracleFor>
Mesh extract_tree(const TreeT& tree, const Signing& signing, const LatticeTransform& xf,
                  const ExtractOptions& options, FieldKind kind, const OracleFor& with_oracle,
                  ExtractStats& stats) {
    const Progress progress(options);
    StageTimer timer(stats);
    const Region region(options.region, *xf.transform);
    const std::vector<openvdb::Coord> leaves = candidate_blocks(
        tree, double(sizeof(CellLeaf) + CellLeaf::SIZE * sizeof(std::int64_t)), options, region.cell_bounds());
    if (leaves.size() >= (std::size_t(1) << (63 - kLeafShift)))
        throw resource_error("the volume has too many leaf nodes to mesh in one piece; mesh it in parts");
    timer.done("candidates");
    progress.report(0.0);  // cancellation points between the set-up stages

    const NoiseEstimate noise = kind == FieldKind::analytic ? NoiseEstimate{} : estimate_noise(tree, signing, leaves);
    const ChosenParameters chosen = choose_parameters(options, noise, kind);
    record_parameters(chosen, kind, stats);
    timer.done("noise estimate");
    progress.report(0.0);

    std::unique_ptr<TreeT> smoothed;
    if (chosen.smooth_field) {
        const ProgressSpan smoothing(progress, 0.0, 0.0);
        smoothed = smooth_field(tree, signing, &smoothing);
        timer.done("smooth field");
    }
    const TreeT& field = smoothed ? *smoothed : tree;
    Mesh mesh = with_oracle(chosen.options.normals, [&](const auto& oracle) {
        return mesh_cells(field, signing, oracle, xf, region, leaves, chosen, progress, timer, stats);
    });
    timer.finish();
    return mesh;
}


template <class GridT>
Mesh extract_grid(const GridT& grid, const ExtractOptions& options, ExtractStats* stats_out) {
    validate(options);
    const LatticeTransform xf = check_transform(grid.transform(), grid.getName());
    const InteriorChoice interior = choose_interior(grid, options);
    const Signing signing = signing_for(interior, options);
    ExtractStats stats;
    Mesh mesh = extract_tree(grid.tree(), signing, xf, options, field_kind(signing, xf.cubic), GridOracles{}, stats);
    report_input(grid, interior, options, mesh, stats);
    if (stats_out) *stats_out = std::move(stats);
    return mesh;
}

}  // namespace
}  // namespace pqdc::detail

namespace pqdc {

Mesh extract(const openvdb::FloatGrid& grid, const ExtractOptions& options, ExtractStats* stats) {
    return detail::extract_grid(grid, options, stats);
}

Mesh extract(const openvdb::DoubleGrid& grid, const ExtractOptions& options, ExtractStats* stats) {
    return detail::extract_grid(grid, options, stats);
}

Mesh extract(const openvdb::GridBase& grid, const ExtractOptions& options, ExtractStats* stats) {
    if (const auto* f = dynamic_cast<const openvdb::FloatGrid*>(&grid)) return extract(*f, options, stats);
    if (const auto* d = dynamic_cast<const openvdb::DoubleGrid*>(&grid)) return extract(*d, options, stats);
    throw input_error("grid '" + grid.getName() + "' holds " + grid.valueType() +
                      " values; pqdc meshes scalar float or double grids (convert it, or pick another grid with --grid)");
}

Mesh extract(const ScalarField& field, const ProceduralSampling& sampling, const ExtractOptions& options,
             ExtractStats* stats) {
    validate(options);
    const openvdb::FloatGrid::Ptr grid = sample_field(field, sampling);
    const detail::LatticeTransform xf = detail::check_transform(grid->transform(), "procedural");
    const detail::Signing signing;  // sampled values are f itself: inside negative, surface at 0
    const detail::ExactOracle oracle{field, grid->transform()};
    ExtractStats s;
    Mesh mesh = detail::extract_tree(grid->tree(), signing, xf, options, detail::FieldKind::analytic,
                                     [&](GridNormals, const auto& body) { return body(oracle); }, s);
    s.interior = "below";
    s.interior_reason = "procedural field: inside negative";
    if (stats) *stats = std::move(s);
    return mesh;
}

}  // namespace pqdc
