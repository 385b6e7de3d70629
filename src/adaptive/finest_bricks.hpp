// Adaptive mode brick by brick (issue 14, out of core): the two things the
// adaptive driver needs from the voxel values as a whole, read one brick
// (plus halo) at a time through the uniform driver's BrickValues, so the
// input held in memory is the topology, one brick and surface-sized data.
//
//   finest_level_by_bricks   stage "hermite": each brick's candidate blocks
//                            through build_finest_level on the brick's tree
//                            (smoothed first on noisy grids), the bricks'
//                            cells then put in code order: the level the
//                            in-core run builds (which is in code order, one
//                            entry per cell, each computed from the values
//                            within two points of its block).
//   smoothed_near_surface    on noisy grids, the smoothed values the later
//                            stages probe: every leaf within one root cell
//                            (plus a leaf) of a root cell holding surface.
// Without smoothing the later stages read the grid itself: with a
// delay-loaded grid the accessors load only the leaves they touch, near the
// surface.
#pragma once

#include "adaptive/finest_level.hpp"
#include "adaptive/finest_parts.hpp"
#include "pqdc/distributed.hpp"
#include "scale/brick_values.hpp"

#include <tbb/parallel_sort.h>

#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

namespace pqdc::adaptive_detail {

/// BrickValues' stage interface (run, leaves, reach, record_bytes, options)
/// over build_finest_level: each brick's cells are appended to one level,
/// in brick order; take() puts them in code order.
template <class GridT, class Oracle>
class FinestBrickStage {
public:
    using TreeT = typename GridT::TreeType;

    FinestBrickStage(const std::vector<openvdb::Coord>& blocks, const detail::Signing& signing, const Oracle& oracle,
                     const ExtractOptions& options, const detail::Region& region, const Octree& frame,
                     FinestCounters& counters, const detail::ProgressSpan& span)
        : blocks_(blocks), signing_(signing), oracle_(oracle), options_(options), region_(region), frame_(frame),
          counters_(counters), span_(span) {}

    const std::vector<openvdb::Coord>& leaves() const { return blocks_; }
    /// Points beyond a block whose values a block's cells read: BlockScratch::wide's margin.
    int reach() const { return 2; }
    const ExtractOptions& options() const { return options_; }

    /// The cells of blocks [begin, end), read from `values` (a brick's tree).
    void run(const TreeT& values, std::size_t begin, std::size_t end, const detail::Progress&, double from,
             double to) {
        // A grid around the brick's tree, not owning it (build_finest_level reads through a grid's accessor).
        const typename GridT::Ptr grid =
            GridT::create(typename GridT::TreePtrType(const_cast<TreeT*>(&values), [](TreeT*) {}));
        Octree brick;
        brick.top = frame_.top;
        brick.offset = frame_.offset;
        brick.levels.resize(1);
        constexpr double share = detail::BrickValues<TreeT>::kCellsProgress;
        build_finest_level(*grid, std::vector<openvdb::Coord>(blocks_.begin() + std::ptrdiff_t(begin),
                                                              blocks_.begin() + std::ptrdiff_t(end)),
                           signing_, oracle_, options_, region_, brick, counters_,
                           span_.part(from / share, to / share));
        Level& l = brick.levels[0];
        last_cells_ = l.size();
        all_.code.insert(all_.code.end(), l.code.begin(), l.code.end());
        all_.flags.insert(all_.flags.end(), l.flags.begin(), l.flags.end());
        all_.quadrics.insert(all_.quadrics.end(), l.quadrics.begin(), l.quadrics.end());
        all_.vertex.insert(all_.vertex.end(), l.vertex.begin(), l.vertex.end());
    }

    /// The whole pipeline's bytes for the last brick's cells (BrickValues sums
    /// them against the memory limit, as build_finest_level does in core).
    std::uint64_t record_bytes(std::size_t, std::size_t) const {
        return std::uint64_t(double(last_cells_) * kBytesPerSurfaceCell);
    }

    /// The cells appended so far, in brick order (a distributed run's exchange).
    Level& cells() { return all_; }

    /// Every brick's cells in code order (codes are unique: one cell each).
    Level take() {
        const std::size_t n = all_.size();
        std::vector<std::pair<std::uint64_t, std::size_t>> order(n);
        for (std::size_t i = 0; i < n; ++i) order[i] = {all_.code[i], i};
        tbb::parallel_sort(order.begin(), order.end());
        // One array at a time: memory holds the level and one permuted array.
        auto permute = [&](auto& v) {
            std::remove_reference_t<decltype(v)> sorted(n);
            tbb::parallel_for(std::size_t(0), n, [&](std::size_t k) { sorted[k] = v[order[k].second]; });
            v.swap(sorted);
        };
        permute(all_.code);
        permute(all_.flags);
        permute(all_.quadrics);
        permute(all_.vertex);
        return std::move(all_);
    }

private:
    const std::vector<openvdb::Coord>& blocks_;
    const detail::Signing& signing_;
    const Oracle& oracle_;
    const ExtractOptions& options_;
    const detail::Region& region_;
    const Octree& frame_;
    FinestCounters& counters_;
    detail::ProgressSpan span_;
    Level all_;
    std::size_t last_cells_ = 0;
};

/// Stage "hermite" brick by brick: the finest level (code order) of the
/// candidate blocks `blocks` (tree order), bricks of `values`' size;
/// `smooth`: of the smoothed field, as the in-core run meshes it. With a
/// `group`, each rank builds its run of bricks (detail::rank_bricks) and
/// sends the cells to rank 0, which returns the whole level and counts
/// every rank's cells; the other ranks return an empty level.
template <class GridT, class Oracle>
Level finest_level_by_bricks(const detail::BrickValues<typename GridT::TreeType>& values,
                             const std::vector<openvdb::Coord>& blocks, bool smooth, const detail::Signing& signing,
                             const Oracle& oracle, const ExtractOptions& options, const detail::Region& region,
                             const Octree& frame, FinestCounters& counters, const detail::Progress& progress,
                             const detail::ProgressSpan& span, RankGroup* group = nullptr) {
    FinestBrickStage<GridT, Oracle> stage(blocks, signing, oracle, options, region, frame, counters, span);
    const std::vector<detail::BrickRun> bricks = detail::split_into_bricks(blocks, values.brick_size());
    const auto [first, last] =
        group ? detail::rank_bricks(bricks, group->rank(), group->size()) : std::pair<std::size_t, std::size_t>(0, bricks.size());
    values.run_bricks(stage, bricks, first, last, smooth, progress);
    if (group) {
        // Rank 0 keeps its own cells where they are and sends nothing.
        std::string part;
        if (group->rank() != 0) part = encode_finest_part(stage.cells(), counters);
        std::vector<std::string> parts = group->gather_at_root(std::move(part));
        if (group->rank() != 0) return Level{};
        if (parts.size() != std::size_t(group->size()))
            throw std::logic_error("internal error: the rank group gathered " + std::to_string(parts.size()) +
                                   " parts from " + std::to_string(group->size()) + " ranks");
        for (std::size_t k = 1; k < parts.size(); ++k) {
            decode_finest_part(parts[k], stage.cells(), counters);
            std::string().swap(parts[k]);
        }
    }
    return stage.take();
}

/// The boxes (voxels) the octree and polygon stages may read the field in:
/// each root cell holding a finest cell, grown by one root cell (the empty
/// roots beside it, whose centres and edges polygons probe) and one leaf
/// (trilinear samples and gradient stencils past a box's last point).
inline std::vector<openvdb::CoordBBox> probed_boxes(const Octree& tree, const Level& finest) {
    const int shift = 3 * tree.top, root = 1 << tree.top;
    std::vector<openvdb::CoordBBox> boxes;
    for (std::size_t i = 0; i < finest.size(); ++i) {
        const std::uint64_t code = finest.code[i] >> shift;
        if (i > 0 && (finest.code[i - 1] >> shift) == code) continue;  // code order: a root's cells are one run
        const openvdb::Coord lo = tree.origin(tree.top, code);
        openvdb::CoordBBox box(lo, lo + openvdb::Coord(root - 1));
        box.expand(root + 8);
        // Whole leaves (roots of fewer than 8 voxels): a brick's smoothing halo is counted from leaf faces.
        boxes.emplace_back(box.min() & ~7, box.max() | 7);
    }
    return boxes;
}

/// The smoothed field (smooth_field of the whole tree) at every point of
/// probed_boxes, each brick of `values`' size that meets them smoothed on
/// its own copy with a smoothing halo; elsewhere the tree holds background.
template <class TreeT>
std::unique_ptr<TreeT> smoothed_near_surface(const detail::BrickValues<TreeT>& values, const detail::Signing& signing,
                                             const std::vector<openvdb::CoordBBox>& boxes) {
    const openvdb::Coord extent = detail::brick_extent(values.brick_size());
    // Each brick's parts of the boxes (a std::map: bricks in coordinate order, deterministic).
    std::map<openvdb::Coord, std::vector<openvdb::CoordBBox>> parts;
    for (const openvdb::CoordBBox& box : boxes) {
        const openvdb::Coord lo(box.min().x() & ~(extent.x() - 1), box.min().y() & ~(extent.y() - 1),
                                box.min().z() & ~(extent.z() - 1));
        for (int x = lo.x(); x <= box.max().x(); x += extent.x())
            for (int y = lo.y(); y <= box.max().y(); y += extent.y())
                for (int z = lo.z(); z <= box.max().z(); z += extent.z()) {
                    openvdb::CoordBBox part(openvdb::Coord(x, y, z), openvdb::Coord(x, y, z) + extent.offsetBy(-1));
                    part.intersect(box);
                    parts[openvdb::Coord(x, y, z)].push_back(part);
                }
    }
    auto out = std::make_unique<TreeT>(values.background());
    const int halo = detail::brick_halo(0, true);
    for (const auto& [brick, pieces] : parts) {
        openvdb::CoordBBox read;
        for (const openvdb::CoordBBox& p : pieces) read.expand(p);
        read.expand(halo);
        TreeT raw(values.background());
        values.source().copy_box(read, raw);
        const std::unique_ptr<TreeT> smoothed = detail::smooth_field(raw, signing);
        // The pieces are leaf-aligned and at least a halo inside `read`: their leaves' smoothed values are exact.
        for (const openvdb::CoordBBox& p : pieces) detail::copy_tree_box(*smoothed, p, *out);
        detail::release_mapped_volume_pages();
    }
    return out;
}

}  // namespace pqdc::adaptive_detail
