// Adaptive mode brick by brick (issue 14, out of core): the two things the
// adaptive driver needs from the voxel values as a whole, read one brick
// (plus halo) at a time through the uniform driver's BrickValues, so the
// input held in memory is the topology, one brick and surface-sized data.
//
//   lower_levels_by_bricks   stage "hermite" and the octree's levels up to
//                            brick_levels() (adaptive/brick_levels.hpp):
//                            each brick's candidate blocks and the ring of
//                            blocks around it through build_finest_level on
//                            the brick's tree (smoothed first on noisy
//                            grids), merged into the levels above, cut to
//                            the brick; the bricks' nodes then put in code
//                            order. The nodes the in-core run builds, less
//                            those below a merged leaf, which no later stage
//                            reads: the finest level is never held whole.
// The later stages read the values leaf by leaf (bricks/source_values.hpp).
#pragma once

#include "adaptive/brick_levels.hpp"
#include "adaptive/finest_level.hpp"
#include "adaptive/level_parts.hpp"
#include "adaptive/simplify.hpp"
#include "pqdc/distributed.hpp"
#include "scale/brick_values.hpp"
#include "bricks/bricks.hpp"

#include <algorithm>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace pqdc::adaptive_detail {

/// BrickValues' stage interface (run, leaves, reach, record_bytes, options)
/// over build_finest_level and build_parent_level: each brick's nodes of
/// levels 0..brick_levels() are appended to `levels`, in brick order;
/// take() puts them in code order and links them.
template <class GridT, class Oracle>
class LowerLevelsStage {
public:
    using TreeT = typename GridT::TreeType;

    /// `exact_field`: the procedural field the merges probe, or null to
    /// probe each brick's values (which equal the grid's where they are read).
    LowerLevelsStage(const std::vector<openvdb::Coord>& blocks, int brick_size, const detail::Signing& signing,
                     const Oracle& oracle, const AdaptiveOptions& options, const detail::Region& region,
                     const Octree& frame, const PinnedCells& pinned, const FieldSource* exact_field,
                     FinestCounters& finest, MergeCounters& merges, const detail::ProgressSpan& span)
        : blocks_(blocks), extent_(detail::brick_extent(brick_size)), signing_(signing), oracle_(oracle),
          options_(options), region_(region), frame_(frame), pinned_(pinned), exact_field_(exact_field),
          finest_(finest), merges_(merges), span_(span), sorted_(blocks) {
        std::sort(sorted_.begin(), sorted_.end());
        levels_.resize(std::size_t(brick_levels(frame)) + 1);
    }

    const std::vector<openvdb::Coord>& leaves() const { return blocks_; }
    int reach() const { return kBrickLevelsReach; }
    const ExtractOptions& options() const { return options_.base; }

    /// The levels of blocks [begin, end) (one brick), read from `values`
    /// (the brick's tree with kBrickLevelsReach of halo).
    void run(const TreeT& values, std::size_t begin, std::size_t end, const detail::Progress&, double from,
             double to) {
        // A grid around the brick's tree, not owning it (the stages read through a grid's accessor).
        const typename GridT::Ptr grid =
            GridT::create(typename GridT::TreePtrType(const_cast<TreeT*>(&values), [](TreeT*) {}));
        const openvdb::Coord lo = detail::brick_origin(blocks_[begin], extent_);
        const openvdb::CoordBBox brick(lo, lo + extent_ - openvdb::Coord(1));
        std::vector<openvdb::Coord> blocks(blocks_.begin() + std::ptrdiff_t(begin), blocks_.begin() + std::ptrdiff_t(end));
        const std::vector<openvdb::Coord> ring = ring_blocks(sorted_, brick);
        blocks.insert(blocks.end(), ring.begin(), ring.end());

        constexpr double share = detail::BrickValues<TreeT>::kCellsProgress;
        const detail::ProgressSpan span = span_.part(from / share, to / share);
        const int top = brick_levels(frame_);
        Octree local;
        local.top = frame_.top;
        local.offset = frame_.offset;
        local.levels.resize(std::size_t(top) + 1);
        build_finest_level(*grid, std::move(blocks), signing_, oracle_, options_.base, region_, local, finest_,
                           span.part(0.0, 0.7), brick);
        const GridField<GridT> brick_field(*grid, signing_);
        const FieldSource& field = exact_field_ ? *exact_field_ : brick_field;
        for (int level = 0; level < top; ++level)
            local.levels[std::size_t(level) + 1] =
                build_parent_level(*grid, field, local, level, signing_, options_, pinned_, region_, merges_,
                                   span.part(0.7 + 0.3 * level / top, 0.7 + 0.3 * (level + 1) / top), &brick);
        last_nodes_ = append_brick_nodes(local, top, brick, levels_);
    }

    /// The whole pipeline's bytes for the last brick's nodes (BrickValues sums
    /// them against the memory limit, as build_finest_level does in core).
    std::uint64_t record_bytes(std::size_t, std::size_t) const {
        return std::uint64_t(double(last_nodes_) * kBytesPerSurfaceCell);
    }

    /// The nodes appended so far, in brick order (a distributed run's exchange).
    std::vector<Level>& levels() { return levels_; }

    /// Moves every brick's nodes, in code order and linked, into
    /// tree.levels[0..] (codes are unique: the bricks' boxes are disjoint);
    /// returns the highest level.
    int take_into(Octree& tree) {
        sort_and_link(levels_);
        for (std::size_t level = 0; level < levels_.size(); ++level) tree.levels[level] = std::move(levels_[level]);
        return int(levels_.size()) - 1;
    }

private:
    const std::vector<openvdb::Coord>& blocks_;
    const openvdb::Coord extent_;
    const detail::Signing& signing_;
    const Oracle& oracle_;
    const AdaptiveOptions& options_;
    const detail::Region& region_;
    const Octree& frame_;
    const PinnedCells& pinned_;
    const FieldSource* exact_field_;
    FinestCounters& finest_;
    MergeCounters& merges_;
    detail::ProgressSpan span_;
    std::vector<openvdb::Coord> sorted_;  ///< the candidate blocks in Coord order (ring lookups)
    std::vector<Level> levels_;
    std::size_t last_nodes_ = 0;
};

/// Stage "hermite" and the octree's levels up to brick_levels(frame), brick
/// by brick, into tree.levels[0..brick_levels] (code order, linked), of the
/// candidate blocks `blocks` (tree order), bricks of `values`' size;
/// `smooth`: of the smoothed field, as the in-core run meshes it. Returns
/// the highest level built. With a `group`, each rank builds its run of
/// bricks (detail::rank_bricks) and sends the nodes to rank 0, which gets
/// the whole levels and every rank's counts; the other ranks get empty levels.
template <class GridT, class Oracle>
int lower_levels_by_bricks(const detail::BrickValues<typename GridT::TreeType>& values,
                           const std::vector<openvdb::Coord>& blocks, bool smooth, const detail::Signing& signing,
                           const Oracle& oracle, const AdaptiveOptions& options, const detail::Region& region,
                           const PinnedCells& pinned, const FieldSource* exact_field, Octree& tree,
                           FinestCounters& finest, MergeCounters& merges, const detail::Progress& progress,
                           const detail::ProgressSpan& span, RankGroup* group = nullptr) {
    LowerLevelsStage<GridT, Oracle> stage(blocks, values.brick_size(), signing, oracle, options, region, tree, pinned,
                                          exact_field, finest, merges, span);
    const std::vector<detail::BrickRun> bricks = detail::split_into_bricks(blocks, values.brick_size());
    const auto [first, last] =
        group ? detail::rank_bricks(bricks, group->rank(), group->size()) : std::pair<std::size_t, std::size_t>(0, bricks.size());
    values.run_bricks(stage, bricks, first, last, smooth, progress);
    if (group) {
        // Rank 0 keeps its own nodes where they are and sends nothing.
        std::string part;
        if (group->rank() != 0) part = encode_levels_part(stage.levels(), finest, merges);
        std::vector<std::string> parts = group->gather_at_root(std::move(part));
        if (group->rank() == 0) {
            if (parts.size() != std::size_t(group->size()))
                throw std::logic_error("internal error: the rank group gathered " + std::to_string(parts.size()) +
                                       " parts from " + std::to_string(group->size()) + " ranks");
            for (std::size_t k = 1; k < parts.size(); ++k) {
                decode_levels_part(parts[k], stage.levels(), finest, merges);
                std::string().swap(parts[k]);
            }
        }
    }
    return stage.take_into(tree);
}

/// lower_levels_by_bricks in core: the same levels, each brick read straight
/// from `grid`'s tree (no copies), bricks of `brick_size`. Throws
/// resource_error when the kept nodes' estimate exceeds the memory limit.
template <class GridT, class Oracle>
int lower_levels_in_core(const GridT& grid, const std::vector<openvdb::Coord>& blocks, int brick_size,
                         const detail::Signing& signing, const Oracle& oracle, const AdaptiveOptions& options,
                         const detail::Region& region, const PinnedCells& pinned, const FieldSource* exact_field,
                         Octree& tree, FinestCounters& finest, MergeCounters& merges,
                         const detail::ProgressSpan& span) {
    LowerLevelsStage<GridT, Oracle> stage(blocks, brick_size, signing, oracle, options, region, tree, pinned,
                                          exact_field, finest, merges, span);
    const std::vector<detail::BrickRun> bricks = detail::split_into_bricks(blocks, brick_size);
    constexpr double share = detail::BrickValues<typename GridT::TreeType>::kCellsProgress;
    const detail::Progress progress(options.base);
    const double n = double(bricks.size());
    std::uint64_t records = 0;
    for (std::size_t k = 0; k < bricks.size(); ++k) {
        stage.run(grid.tree(), bricks[k].begin, bricks[k].end, progress, share * double(k) / n,
                  share * double(k + 1) / n);
        records += stage.record_bytes(bricks[k].begin, bricks[k].end);
        detail::check_memory(double(records), options.base, "adaptive octree");
    }
    return stage.take_into(tree);
}

}  // namespace pqdc::adaptive_detail
