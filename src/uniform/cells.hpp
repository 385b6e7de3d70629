// Uniform stage "cells": fetch, classify and place vertices, one pass per
// candidate leaf so that its values are fetched once. The in-core driver
// runs it over every candidate leaf of the whole tree; the brick driver
// (scale/brick_values.hpp) over each brick's run of leaves with a tree that
// holds only that brick and its halo. Both call the same per-leaf code.
#pragma once

#include "lattice/auto_parameters.hpp"
#include "lattice/crossings.hpp"
#include "lattice/region.hpp"
#include "lattice/resources.hpp"
#include "lattice/transform.hpp"
#include "lattice/value_block.hpp"
#include "pqdc/stats.hpp"
#include "uniform/cell_tree.hpp"
#include "uniform/classify.hpp"
#include "uniform/place_vertices.hpp"
#include "uniform/region_cells.hpp"

#include <tbb/enumerable_thread_specific.h>

#include <algorithm>
#include <memory>
#include <optional>
#include <vector>

namespace pqdc::detail {

/// What the cells stage leaves per candidate leaf (indexed like the candidate list).
/// Memory of one leaf's cell records (a CellLeaf and its buffer of records).
constexpr std::uint64_t kCellRecordBytes = sizeof(CellLeaf) + CellLeaf::SIZE * sizeof(CellValue);

struct LeafResults {
    std::vector<std::unique_ptr<CellLeaf>> cells;
    std::vector<std::vector<openvdb::Vec3d>> points;
    std::vector<std::uint32_t> faces, incidences;

    explicit LeafResults(std::size_t n) : cells(n), points(n), faces(n, 0), incidences(n, 0) {}

    /// Memory of one candidate's entries, before run() fills them.
    static constexpr std::uint64_t kEntryBytes = sizeof(std::unique_ptr<CellLeaf>) +
                                                 sizeof(std::vector<openvdb::Vec3d>) + 2 * sizeof(std::uint32_t);
};

/// The cells stage's counters, named like the ExtractStats fields they add to.
struct CellCounters {
    std::uint64_t active_cells = 0, degenerate_normals = 0, clamped_vertices = 0, fallback_vertices = 0,
                  multi_vertex_cells = 0, non_finite_values = 0;

    CellCounters& operator+=(const CellCounters& o) {
        active_cells += o.active_cells;
        degenerate_normals += o.degenerate_normals;
        clamped_vertices += o.clamped_vertices;
        fallback_vertices += o.fallback_vertices;
        multi_vertex_cells += o.multi_vertex_cells;
        non_finite_values += o.non_finite_values;
        return *this;
    }
    void add_to(ExtractStats& stats) const {
        stats.active_cells += active_cells;
        stats.degenerate_normals += degenerate_normals;
        stats.clamped_vertices += clamped_vertices;
        stats.fallback_vertices += fallback_vertices;
        stats.multi_vertex_cells += multi_vertex_cells;
        stats.non_finite_values += non_finite_values;
    }
};

template <class TreeT, class Oracle>
class CellStage {
public:
    CellStage(const Signing& signing, const Oracle& oracle, const LatticeTransform& xf, const Region& region,
              const std::vector<openvdb::Coord>& leaves, const ChosenParameters& chosen, LeafResults& out)
        : signing_(signing), oracle_(oracle), xf_(xf), region_(region), leaves_(leaves), chosen_(chosen),
          margin_(hermite_margin(Oracle::kMargin, chosen.filter)), out_(out) {}

    /// The candidate leaves [begin, end) (indices into the candidate list),
    /// reading values from `field`, which must hold the source's values
    /// within reach() of those leaves. Progress goes from `from` to `to`.
    void run(const TreeT& field, std::size_t begin, std::size_t end, const Progress& progress, double from,
             double to) {
        start_run();
        parallel_chunks(end - begin, progress, from, to, [&](std::size_t i) { leaf(begin + i, scratch(field)); });
    }

    /// run() over the candidate leaves `indices` (a streamed run's halo
    /// leaves, scale/stream_cells.hpp), without progress.
    void run_list(const TreeT& field, const std::vector<std::size_t>& indices) {
        start_run();
        tbb::parallel_for(std::size_t(0), indices.size(), [&](std::size_t i) { leaf(indices[i], scratch(field)); });
    }

    const std::vector<openvdb::Coord>& leaves() const { return leaves_; }
    /// Lattice points below a candidate leaf's origin (and above its last
    /// cell corner, origin + 8) whose values run() reads: the fetch block's
    /// one point (lower neighbours' configurations), or the Hermite block's
    /// margin (gradient stencils plus the quadric filter's neighbour cells).
    int reach() const { return std::max(1, margin_); }

    /// The counters of every run so far, plus those absorb()ed.
    CellCounters counters() const {
        CellCounters c = absorbed_;
        for (const Scratch& s : scratch_) {
            c.degenerate_normals += s.cache.degenerate_owned;
            c.clamped_vertices += s.counters.clamped;
            c.fallback_vertices += s.counters.fallback;
            c.multi_vertex_cells += s.counters.multi;
            c.non_finite_values += s.non_finite;
            c.active_cells += s.cells;
        }
        return c;
    }
    /// Counts cells another process ran (scale/distributed_values.hpp).
    void absorb(const CellCounters& other) { absorbed_ += other; }
    /// Adds counters() to `stats`.
    void add_stats(ExtractStats& stats) const { counters().add_to(stats); }

    /// What run() has filled in, per candidate leaf.
    LeafResults& results() { return out_; }

    /// Bytes that the results of candidate leaves [begin, end) hold beyond
    /// the per-candidate entries: cell records and vertices.
    std::uint64_t record_bytes(std::size_t begin, std::size_t end) const {
        std::uint64_t bytes = 0;
        for (std::size_t i = begin; i < end; ++i) {
            if (out_.cells[i]) bytes += kCellRecordBytes;
            bytes += out_.points[i].capacity() * sizeof(openvdb::Vec3d);
        }
        return bytes;
    }
    const ExtractOptions& options() const { return chosen_.options; }

private:
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

    /// Accessors belong to one tree: a new run (a new brick tree) starts afresh.
    void start_run() {
        for (Scratch& s : scratch_) s.acc.reset();
    }
    /// The calling thread's scratch, its accessor on `field`.
    Scratch& scratch(const TreeT& field) {
        Scratch& s = scratch_.local();
        if (!s.acc) s.acc.emplace(field);
        return s;
    }

    void leaf(std::size_t li, Scratch& s) {
        const openvdb::Coord origin = leaves_[li];
        if (!corners_may_cross(*s.acc, origin, signing_)) return;
        // One point below (lower neighbours, gradient stencil), two above
        // (corners, upper neighbours, gradient stencil); with a wider
        // Hermite margin, that block is copied out of the wider one.
        if (margin_ > 1) {
            fetch_block(*s.acc, origin - openvdb::Coord(margin_), kLeafDim + 1 + 2 * margin_, signing_, s.wide);
            copy_sub_block(s.wide, margin_ - 1, kLeafDim + 3, s.block);
        } else {
            fetch_block(*s.acc, origin - openvdb::Coord(1), kLeafDim + 3, signing_, s.block);
        }
        if (block_is_one_sided(s.block)) return;
        classify_leaf(s.block, s.classified);
        s.non_finite += s.classified.non_finite;
        if (!region_.unbounded()) {
            if (!s.in_region) s.in_region.emplace(region_);
            restrict_leaf_cells(s.block, origin, *s.in_region, s.classified);
        }
        if (s.classified.cells.empty()) return;
        const DenseBlock& hermite_block = margin_ > 1 ? s.wide : s.block;
        place_leaf_vertices(oracle_, hermite_block, s.classified, origin, xf_, chosen_.options, chosen_.filter,
                            s.cache, s.own, out_.points[li], s.first_vertex, s.counters);
        auto leaf = std::make_unique<CellLeaf>(origin, CellValue(0), false);
        leaf->setTransientData(openvdb::Index32(li));
        for (std::size_t i = 0; i < s.classified.cells.size(); ++i) {
            const ClassifiedCell& c = s.classified.cells[i];
            leaf->setValueOn(CellLeaf::coordToOffset(origin + c.local), pack_cell(c.config, c.joined, s.first_vertex[i]));
        }
        s.cells += s.classified.cells.size();
        out_.cells[li] = std::move(leaf);
        out_.faces[li] = s.classified.faces;
        out_.incidences[li] = s.classified.incidences;
    }

    const Signing& signing_;
    const Oracle& oracle_;
    const LatticeTransform& xf_;
    const Region& region_;
    const std::vector<openvdb::Coord>& leaves_;
    const ChosenParameters& chosen_;
    const int margin_;
    LeafResults& out_;
    CellCounters absorbed_;
    tbb::enumerable_thread_specific<Scratch> scratch_;
};

}  // namespace pqdc::detail
