// Stages "cells", "faces" and the untangle stage's first check of a
// streamed run (issue 14, phase 2: meshing brick by brick without holding
// the mesh). Each brick is meshed with a halo of one leaf on every side
// (its candidate leaves run again by a second CellStage whose counters are
// dropped), so that:
//  - its faces, owned by its own cells, find the lower neighbours' vertices
//    (numbered already: lower neighbours come earlier) with the positions
//    the in-core run split their quads by;
//  - every triangle that can meet one of its own is there (within 2 + 2D
//    cells, D < 1.5 the vertices' largest offset from their cells' centers),
//    so the exact check of the brick finds every offending pair with an own
//    triangle, and no other brick's check is needed for it.
// Own vertices and faces go to the scratch files; the offending pairs'
// corners (the seeds) and the largest offset go, through the exchange
// (scale/stream_numbering.hpp), to the untangle stage (scale/
// stream_untangle.hpp). Each rank of a distributed run (or concurrent run
// of one process) meshes its own contiguous run of bricks in its own
// numbering; a face at its first bricks may use the rank before's
// vertices, which it records as foreign corners for the exchange. The cells are computed once more for the
// halo (about a third more on 256-voxel bricks), in exchange for no
// records kept between bricks.
#pragma once

#include "lattice/auto_parameters.hpp"
#include "lattice/region.hpp"
#include "lattice/resources.hpp"
#include "lattice/transform.hpp"
#include "lattice/untangle.hpp"
#include "pqdc/stats.hpp"
#include "scale/brick_values.hpp"
#include "bricks/bricks.hpp"
#include "bricks/mapped_pages.hpp"
#include "scale/stream_scratch.hpp"
#include "measure/mesh_internal.hpp"
#include "uniform/cells.hpp"
#include "uniform/faces.hpp"
#include "uniform/quad_star_check.hpp"
#include "uniform/safe_positions.hpp"

#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <functional>
#include <cmath>
#include <limits>
#include <string>
#include <unordered_map>
#include <vector>

namespace pqdc::detail {

/// Memory per vertex of a brick's local mesh at its peak, with its two
/// triangles and the first check's arrays: points, safe positions, cells,
/// float copies, scratch records and the check's offsets and incidences
/// add up to about 250 bytes; rounded up.
constexpr double kLocalVertexBytes = 320.0;

/// What a streamed run counts, per rank until the exchange sums them.
struct StreamCounts {
    CellCounters cells;
    std::uint64_t boundary_crossings = 0, quads = 0;
    std::uint64_t pairs = 0, degenerate = 0;  ///< what the in-core stage's first check counts
    double max_offset = 0;  ///< largest vertex offset from its cell's center (max norm, index space)

    StreamCounts& operator+=(const StreamCounts& o) {
        cells += o.cells;
        boundary_crossings += o.boundary_crossings;
        quads += o.quads;
        pairs += o.pairs;
        degenerate += o.degenerate;
        max_offset = std::max(max_offset, o.max_offset);
        return *this;
    }
    /// The stages' counters as the in-core stages count them (not the untangle stage's).
    void add_to(ExtractStats& stats, bool triangles) const {
        cells.add_to(stats);
        stats.boundary_crossings += boundary_crossings;
        stats.crossing_edges += quads + boundary_crossings;
        stats.quads += triangles ? 0 : quads;
        stats.triangles += triangles ? 2 * quads : 0;
    }
};

/// What the first pass of one rank hands the exchange (scale/stream_numbering.hpp).
struct StreamedCells {
    std::size_t leaf_begin = 0, leaf_end = 0;   ///< this rank's candidate leaves
    std::vector<std::uint32_t> leaf_vertices;   ///< vertices per own leaf
    /// Corners of offending triangles, as (candidate leaf, vertex within it).
    std::vector<std::pair<std::size_t, std::uint32_t>> seeds;
    StreamCounts counts;
};

namespace stream_detail {

/// A brick's own leaves and its halo leaves, meshed together with local numbering.
struct LocalMesh {
    std::vector<std::size_t> index;   ///< local leaf -> candidate index, increasing
    std::vector<CellLeaf*> leaves;    ///< local leaf -> its cells (null: none)
    std::vector<std::uint64_t> first; ///< local leaf -> first local vertex; one more entry at the end
    std::size_t own_begin = 0, own_end = 0;  ///< the own leaves among the local ones
    CellTree cells{CellValue(0)};
    Mesh mesh;
    std::uint64_t own_faces_begin = 0, own_faces_end = 0;  ///< quads (lattice edges) owned by own leaves
};

/// The candidate leaves within one leaf of brick k's box, not its own, increasing.
inline std::vector<std::size_t> halo_leaves(const std::vector<BrickRun>& bricks, std::size_t k,
                                            const std::unordered_map<openvdb::Coord, std::size_t, CoordHash>& at,
                                            const std::vector<openvdb::Coord>& leaves) {
    openvdb::CoordBBox grown = bricks[k].box;
    grown.expand(int(CellLeaf::DIM));
    const openvdb::Coord extent = bricks[k].box.dim();
    std::vector<std::size_t> out;
    for (int dx = -1; dx <= 1; ++dx)
        for (int dy = -1; dy <= 1; ++dy)
            for (int dz = -1; dz <= 1; ++dz) {
                if (!dx && !dy && !dz) continue;
                const auto it = at.find(bricks[k].box.min() + openvdb::Coord(dx * extent.x(), dy * extent.y(), dz * extent.z()));
                if (it == at.end()) continue;
                const BrickRun& b = bricks[it->second];
                for (std::size_t i = b.begin; i < b.end; ++i)
                    if (grown.isInside(leaves[i])) out.push_back(i);
            }
    std::sort(out.begin(), out.end());
    return out;
}

/// Moves the cells the stages left for `own` and `halo` leaves into one
/// local tree with local vertex numbering, and builds its faces.
inline void assemble(LeafResults& results, std::size_t begin, std::size_t end, const std::vector<std::size_t>& halo,
                     const LatticeTransform& xf, const ExtractOptions& options, LocalMesh& local) {
    const auto split = std::lower_bound(halo.begin(), halo.end(), begin);
    local.index.assign(halo.begin(), split);
    local.own_begin = local.index.size();
    for (std::size_t i = begin; i < end; ++i) local.index.push_back(i);
    local.own_end = local.index.size();
    local.index.insert(local.index.end(), split, halo.end());
    const std::size_t n = local.index.size();
    local.leaves.assign(n, nullptr);
    local.first.assign(n + 1, 0);
    std::vector<std::uint32_t> faces(n, 0);
    openvdb::tree::ValueAccessor<CellTree, false> acc(local.cells);
    for (std::size_t j = 0; j < n; ++j) {
        const std::size_t i = local.index[j];
        local.first[j + 1] = local.first[j] + results.points[i].size();
        faces[j] = results.faces[i];
        if (!results.cells[i]) continue;
        results.cells[i]->setTransientData(openvdb::Index32(j));
        local.leaves[j] = results.cells[i].get();
        acc.addLeaf(results.cells[i].release());
    }
    local.mesh.points.resize(local.first[n]);
    for (std::size_t j = 0; j < n; ++j) {
        std::vector<openvdb::Vec3d>& p = results.points[local.index[j]];
        std::copy(p.begin(), p.end(), local.mesh.points.begin() + std::ptrdiff_t(local.first[j]));
        std::vector<openvdb::Vec3d>().swap(p);
        results.faces[local.index[j]] = results.incidences[local.index[j]] = 0;
    }
    for (std::size_t j = 0; j < local.own_begin; ++j) local.own_faces_begin += faces[j];
    local.own_faces_end = local.own_faces_begin;
    for (std::size_t j = local.own_begin; j < local.own_end; ++j) local.own_faces_end += faces[j];
    ExtractOptions quiet = options;
    quiet.progress = nullptr;
    const Progress none(quiet);
    ExtractStats ignored;
    build_faces(local.cells, local.leaves, local.first, faces, xf, quiet, none, local.mesh, ignored);
    // Halo cells at the halo's far side miss neighbours that their leaves'
    // counts included: those faces stay unwritten (all indices 0). Own
    // faces are all there (their lower neighbours are in the halo).
    auto drop_unwritten = [&](auto& list, std::uint64_t per_quad) {
        std::uint64_t kept = 0, before_own = 0;
        for (std::uint64_t f = 0; f < list.size(); ++f) {
            bool written = false;
            for (int c = 0; c < int(list[f].numElements()); ++c) written = written || list[f][c] != 0;
            if (f == per_quad * local.own_faces_begin) before_own = kept;
            if (written) list[kept++] = list[f];
        }
        if (per_quad * local.own_faces_begin == list.size()) before_own = kept;
        list.resize(kept);
        const std::uint64_t own = local.own_faces_end - local.own_faces_begin;
        local.own_faces_begin = before_own / per_quad;
        local.own_faces_end = local.own_faces_begin + own;
    };
    if (options.faces == FaceType::triangles) drop_unwritten(local.mesh.triangles, 2);
    else drop_unwritten(local.mesh.quads, 1);
}


/// Open crossings (no face: a neighbour cell is missing) counted at own
/// cells, as build_faces counts them in core. Skipped when every incidence
/// of an own cell belongs to one of the local faces.
inline std::uint64_t own_open_crossings(const LocalMesh& local, std::uint64_t own_incidences) {
    const std::uint64_t lo = local.first[local.own_begin], hi = local.first[local.own_end];
    auto own = [&](unsigned v) { return v >= lo && v < hi; };
    std::uint64_t in_faces = 0;
    if (!local.mesh.quads.empty()) {
        for (const auto& q : local.mesh.quads) in_faces += own(q[0]) + own(q[1]) + own(q[2]) + own(q[3]);
    } else {
        for (std::size_t t = 0; t + 1 < local.mesh.triangles.size(); t += 2) {
            const auto& a = local.mesh.triangles[t];
            const auto& b = local.mesh.triangles[t + 1];
            in_faces += own(a[0]) + own(a[1]) + own(a[2]);
            for (int c = 0; c < 3; ++c)  // b's corner off the shared diagonal
                if (b[c] != a[0] && b[c] != a[1] && b[c] != a[2]) in_faces += own(b[c]);
        }
    }
    if (in_faces == own_incidences) return 0;
    return tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(local.own_begin, local.own_end), std::uint64_t(0),
        [&](const tbb::blocked_range<std::size_t>& r, std::uint64_t n) {
            for (std::size_t j = r.begin(); j != r.end(); ++j)
                if (local.leaves[j]) n += count_open_crossings(local.cells, *local.leaves[j]);
            return n;
        },
        std::plus<std::uint64_t>());
}

/// The untangle stage's first check on the local mesh: the corners of
/// offending triangles with an own triangle go to `seeds` as (candidate
/// leaf, vertex within it); pairs are counted by the later brick of the two.
inline void find_seeds(const LocalMesh& local, const VertexCells& cells, const LatticeTransform& xf,
                       VertexPrecision stored, std::vector<std::pair<std::size_t, std::uint32_t>>& seeds,
                       StreamCounts& out) {
    const std::vector<std::uint8_t> patches = cell_patches(cells);
    const LatticeVertices lattice{nullptr, &patches, &xf, &cells};
    QuadStarCheck check(local.mesh, lattice);
    const SelfIntersections found =
        stored == VertexPrecision::float32
            ? check.whole(points_as_stored(local.mesh.points, stored), SelfIntersectionOptions{})
            : check.whole(local.mesh.points, SelfIntersectionOptions{});
    const std::uint64_t own_lo = 2 * local.own_faces_begin, own_hi = 2 * local.own_faces_end;
    auto is_own = [&](std::size_t t) { return t >= own_lo && t < own_hi; };
    auto seed = [&](std::size_t t) {
        for (unsigned v : split_triangle(local.mesh, t)) {
            const auto j = std::size_t(std::upper_bound(local.first.begin(), local.first.end(), v) - local.first.begin()) - 1;
            seeds.emplace_back(local.index[j], std::uint32_t(v - local.first[j]));
        }
    };
    for (const auto& [a, b] : found.pairs) {
        if (!is_own(a) && !is_own(b)) continue;
        seed(a);
        seed(b);
        out.pairs += std::max(a, b) < own_hi;
    }
    for (std::size_t t : found.degenerate_triangles)
        if (is_own(t)) {
            seed(t);
            ++out.degenerate;
        }
}

/// The own vertices' scratch records; the largest offset from a cell's
/// center into `max_offset`, non-finite positions into `non_finite`.
inline std::vector<ScratchVertex> own_vertices(const LocalMesh& local, const VertexCells& cells,
                                               const LatticeTransform& xf,
                                               double& max_offset, std::vector<std::uint64_t>& non_finite) {
    const std::uint64_t lo = local.first[local.own_begin], hi = local.first[local.own_end];
    std::vector<ScratchVertex> vs(hi - lo);
    const double offset = tbb::parallel_reduce(
        tbb::blocked_range<std::uint64_t>(lo, hi, 1 << 12), 0.0,
        [&](const tbb::blocked_range<std::uint64_t>& r, double m) {
            for (std::uint64_t v = r.begin(); v != r.end(); ++v) {
                ScratchVertex& s = vs[v - lo];
                s.position = local.mesh.points[v];
                s.cell = cells.cell(v);
                s.config = cells.config(v);
                s.joined = cells.joined(v);
                s.patch = std::uint8_t(cells.patch(v));
                const openvdb::Vec3d o = xf.transform->worldToIndex(s.position) - (s.cell.asVec3d() + openvdb::Vec3d(0.5));
                const double d = std::max({std::abs(o.x()), std::abs(o.y()), std::abs(o.z())});
                m = std::isfinite(d) ? std::max(m, d) : m;
            }
            return m;
        },
        [](double a, double b) { return std::max(a, b); });
    max_offset = std::max(max_offset, offset);
    for (std::uint64_t v = lo; v < hi; ++v)
        if (!std::isfinite(local.mesh.points[v].lengthSqr())) non_finite.push_back(v);
    return vs;
}

/// The own faces' indices, flattened, in this rank's numbering
/// (`rank_first`: per candidate leaf, set for this rank's leaves so far);
/// corners in leaves before `leaf_begin` (an earlier rank's) go to `foreign`.
inline std::vector<std::uint32_t> own_face_indices(const LocalMesh& local, const std::vector<std::uint64_t>& rank_first,
                                                   std::size_t leaf_begin, const VertexCells& cells,
                                                   std::vector<ForeignCorner>& foreign) {
    constexpr std::uint32_t kForeign = ~std::uint32_t(0);  // never a vertex: counts stay below 2^32
    std::vector<std::uint32_t> numbers(local.first[local.own_end]);
    for (std::size_t j = 0; j < local.own_end; ++j) {
        const std::size_t leaf = local.index[j];
        for (std::uint64_t v = local.first[j]; v < local.first[j + 1]; ++v)
            numbers[v] = leaf < leaf_begin ? kForeign : std::uint32_t(rank_first[leaf] + (v - local.first[j]));
    }
    std::vector<std::uint32_t> out;
    auto put = [&](unsigned v) {
        if (numbers[v] == kForeign) {
            const auto j = std::size_t(std::upper_bound(local.first.begin(), local.first.end(), v) - local.first.begin()) - 1;
            foreign.push_back({out.size(), std::uint64_t(local.index[j]) << 32 | (v - local.first[j]), cells.cell(v)});
        }
        out.push_back(numbers[v] == kForeign ? 0 : numbers[v]);  // a placeholder for the foreign
    };
    if (!local.mesh.triangles.empty() || local.mesh.quads.empty()) {
        out.reserve(6 * (local.own_faces_end - local.own_faces_begin));
        for (std::uint64_t t = 2 * local.own_faces_begin; t < 2 * local.own_faces_end; ++t)
            for (int c = 0; c < 3; ++c) put(local.mesh.triangles[t][c]);
    } else {
        out.reserve(4 * (local.own_faces_end - local.own_faces_begin));
        for (std::uint64_t q = local.own_faces_begin; q < local.own_faces_end; ++q)
            for (int c = 0; c < 4; ++c) put(local.mesh.quads[q][c]);
    }
    return out;
}

}  // namespace stream_detail

/// The first pass over rank `rank`'s share (of `ranks`) of the bricks of
/// `values`: cells and faces brick by brick into `scratch`, in this rank's
/// numbering, and what the exchange and the untangle stage need.
template <class TreeT, class Oracle>
StreamedCells stream_cells(const BrickValues<TreeT>& values, const Signing& signing, const Oracle& oracle,
                           const LatticeTransform& xf, const Region& region, const std::vector<openvdb::Coord>& leaves,
                           const ChosenParameters& chosen, int rank, int ranks, const Progress& progress, double from,
                           double to, StreamScratch& scratch) {
    using namespace stream_detail;
    LeafResults results(leaves.size());
    CellStage<TreeT, Oracle> own(signing, oracle, xf, region, leaves, chosen, results);
    CellStage<TreeT, Oracle> halo_stage(signing, oracle, xf, region, leaves, chosen, results);  // its counters dropped
    const std::vector<BrickRun> bricks = split_into_bricks(leaves, values.brick_size());
    std::unordered_map<openvdb::Coord, std::size_t, CoordHash> brick_at;
    for (std::size_t k = 0; k < bricks.size(); ++k) brick_at[bricks[k].box.min()] = k;
    const int halo = brick_halo(own.reach(), chosen.smooth_field) + int(CellLeaf::DIM);
    const auto [first_brick, last_brick] = rank_bricks(bricks, rank, ranks);

    StreamedCells out;
    out.leaf_begin = first_brick < last_brick ? bricks[first_brick].begin : 0;
    out.leaf_end = first_brick < last_brick ? bricks[last_brick - 1].end : 0;
    out.leaf_vertices.assign(out.leaf_end - out.leaf_begin, 0);
    std::vector<std::uint64_t> rank_first(leaves.size(), 0);  // set as leaves are meshed as own
    std::uint64_t next_vertex = 0;
    for (std::size_t k = first_brick; k < last_brick; ++k) {
        const BrickRun& brick = bricks[k];
        const std::vector<std::size_t> around = halo_leaves(bricks, k, brick_at, leaves);
        {
            const std::unique_ptr<TreeT> tree = values.values_around(brick.box, halo, chosen.smooth_field);
            const double at = from + (to - from) * double(k - first_brick) / double(last_brick - first_brick);
            own.run(*tree, brick.begin, brick.end, progress, at, at);
            halo_stage.run_list(*tree, around);
        }
        release_mapped_volume_pages();
        std::uint64_t own_incidences = 0;
        for (std::size_t i = brick.begin; i < brick.end; ++i) own_incidences += results.incidences[i];
        LocalMesh local;
        assemble(results, brick.begin, brick.end, around, xf, chosen.options, local);
        // Bricks differ: the first over the limit is named, raising the limit to its figure may not do.
        const std::string brick_name = "mesh of brick " + std::to_string(k + 1) + " of " + std::to_string(bricks.size()) +
                                       " (with its halo; others may need more; smaller bricks need less: "
                                       "BrickOptions::brick_size)";
        check_memory(double(local.mesh.points.size()) * kLocalVertexBytes + double(local.index.size()) * kCellRecordBytes,
                     chosen.options, brick_name.c_str());
        for (std::size_t j = local.own_begin; j < local.own_end; ++j) {
            rank_first[local.index[j]] = next_vertex + (local.first[j] - local.first[local.own_begin]);
            out.leaf_vertices[local.index[j] - out.leaf_begin] = std::uint32_t(local.first[j + 1] - local.first[j]);
        }
        out.counts.quads += local.own_faces_end - local.own_faces_begin;
        out.counts.boundary_crossings += own_open_crossings(local, own_incidences);

        const std::size_t nv = local.mesh.points.size();
        const VertexCells cells(local.leaves, local.first, nv);
        find_seeds(local, cells, xf, chosen.options.stored_precision, out.seeds, out.counts);
        std::vector<std::uint64_t> non_finite;
        const std::vector<ScratchVertex> vs = own_vertices(local, cells, xf, out.counts.max_offset, non_finite);
        for (std::uint64_t v : non_finite)  // straight to safety, as in core
            out.seeds.emplace_back(brick.begin, std::uint32_t(v - local.first[local.own_begin]));
        next_vertex += vs.size();
        if (next_vertex >= (std::uint64_t(1) << 32))
            throw resource_error("the mesh would have " + std::to_string(next_vertex) +
                                 " vertices, more than 32-bit face indices can address; mesh the volume in parts");
        std::vector<ForeignCorner> foreign;
        std::vector<std::uint32_t> faces = own_face_indices(local, rank_first, out.leaf_begin, cells, foreign);
        scratch.add_brick(vs, faces, std::move(foreign));
        progress.report(from + (to - from) * double(k + 1 - first_brick) / double(last_brick - first_brick));
    }
    out.counts.cells = own.counters();
    return out;
}

}  // namespace pqdc::detail
