// A brick store read brick file by brick file (issue 14): the BrickSource
// for stores whose topology alone does not fit in memory. Nothing is
// assembled: the candidate list is each brick file's candidates merged in
// tree order, a brick's values (with its halo) are copied out of the few
// files its box overlaps, and the files' parsed topology is kept in a cache
// bounded in bytes (scale/store_index.hpp), so memory holds the index, the
// candidate list and the bricks in flight.
//
// Why the candidates merge: candidate_blocks is a union over source leaves
// and active tiles (each touches its block and lower neighbours), so the
// union over brick files of each file's candidates is the whole volume's;
// the root's tiles, which no brick file holds, come from the shell.
#pragma once

#include "lattice/candidates.hpp"
#include "lattice/resources.hpp"
#include "pqdc/exceptions.hpp"
#include "scale/brick_source.hpp"
#include "scale/bricks.hpp"
#include "scale/mapped_pages.hpp"
#include "scale/rank_exchange.hpp"
#include "scale/store_index.hpp"

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <vector>

namespace pqdc::detail {

template <class TreeT>
class StoreBrickSource : public BrickSource<TreeT> {
public:
    using typename BrickSource<TreeT>::ValueT;
    using GridT = openvdb::Grid<TreeT>;

    /// `shell`: the store's grid without voxels (its root's tiles);
    /// `cache_bytes`: how much parsed brick-file topology may be held at once.
    StoreBrickSource(const StoreIndex& index, const TreeT& shell, std::uint64_t cache_bytes)
        : index_(index), shell_(shell), files_(index, cache_bytes) {}

    ValueT background() const override { return shell_.background(); }

    /// Rank r of `group` reads the r-th share of the brick files; the
    /// shares' lists are then all-gathered and merged on every rank.
    std::vector<openvdb::Coord> candidate_blocks(double bytes_per_block, const ExtractOptions& options,
                                                 const openvdb::CoordBBox& clip, RankGroup& group) const override {
        const std::size_t n = index_.bricks().size(), ranks = std::size_t(group.size()), r = std::size_t(group.rank());
        std::vector<openvdb::Coord> mine =
            files_candidates(n * r / ranks, n * (r + 1) / ranks, r == 0, bytes_per_block, options, clip);
        if (ranks == 1) return mine;
        std::vector<openvdb::Coord> all = all_gather_values(group, mine, "the brick files' candidate blocks");
        std::vector<openvdb::Coord>().swap(mine);
        check_memory(double(all.size()) * bytes_per_block, options, "cell classification");
        return merged(std::move(all));
    }

    bool is_value_on(const openvdb::Coord& p) const override {
        const std::size_t k = index_.holding(p);
        if (k == index_.bricks().size()) return shell_.isValueOn(p);
        const openvdb::GridBase::Ptr grid = files_.open(k);
        return tree_of(*grid, k).isValueOn(p);  // the tree's lookup reads masks only
    }

    void copy_box(const openvdb::CoordBBox& box, TreeT& into) const override {
        copy_tree_box(shell_, box, into);  // the root's tiles
        for (const std::size_t k : index_.overlapping(box)) {
            const openvdb::GridBase::Ptr grid = files_.open(k);
            const TreeT& tree = tree_of(*grid, k);
            openvdb::CoordBBox part = box;
            part.intersect(index_.bricks()[k].box);
            copy_tree_box(tree, part, into);
            // The copies read their buffers against the file's grid, which the
            // cache may drop once `grid` goes: read them now, in parallel (as
            // the cells stage would have).
            std::vector<typename TreeT::LeafNodeType*> copies;
            for_each_leaf_in(tree, part, [&](const openvdb::Coord& origin) {
                if (auto* leaf = into.probeLeaf(origin)) copies.push_back(leaf);
            });
            tbb::parallel_for(std::size_t(0), copies.size(), [&](std::size_t i) { copies[i]->buffer().data(); });
        }
    }

    /// Brick files opened so far (for the run's statistics and tests).
    std::uint64_t files_opened() const { return files_.opened(); }

private:
    /// The candidates of brick files [first, last) (and of the shell's root
    /// tiles with `with_shell`), merged.
    std::vector<openvdb::Coord> files_candidates(std::size_t first, std::size_t last, bool with_shell,
                                                 double bytes_per_block, const ExtractOptions& options,
                                                 const openvdb::CoordBBox& clip) const {
        std::vector<std::vector<openvdb::Coord>> parts(last - first + 1);
        if (with_shell) parts.back() = detail::candidate_blocks(shell_, bytes_per_block, options, clip);
        // A file's leaves seed blocks at most one leaf below them.
        openvdb::CoordBBox reach = clip;
        if (clip != openvdb::CoordBBox::inf()) reach.max() = reach.max().offsetBy(int(TreeT::LeafNodeType::DIM));
        // In chunks of two files per thread, handing the files' mapped pages
        // back between them: parsing a file's topology faults most of its pages
        // in (chunks of 32 held 600 MB of a dense store's pages).
        const std::size_t chunk = 2 * std::size_t(tbb::this_task_arena::max_concurrency());
        for (std::size_t start = first; start < last; start += chunk) {
            tbb::parallel_for(start, std::min(last, start + chunk), [&](std::size_t k) {
                if (!index_.bricks()[k].box.hasOverlap(reach)) return;
                const openvdb::GridBase::Ptr grid = files_.open(k);
                parts[k - first] = detail::candidate_blocks(tree_of(*grid, k), bytes_per_block, options, clip);
            });
            release_mapped_volume_pages();
        }
        std::size_t total = 0;
        for (const auto& p : parts) total += p.size();
        check_memory(double(total) * bytes_per_block, options, "cell classification");
        std::vector<openvdb::Coord> blocks;
        blocks.reserve(total);
        for (auto& p : parts) {
            blocks.insert(blocks.end(), p.begin(), p.end());
            std::vector<openvdb::Coord>().swap(p);
        }
        return merged(std::move(blocks));
    }

    /// `blocks` in tree order, each once (a file's lower-neighbour blocks
    /// may be another file's too).
    static std::vector<openvdb::Coord> merged(std::vector<openvdb::Coord> blocks) {
        tbb::parallel_sort(blocks.begin(), blocks.end(), tree_order_less);
        blocks.erase(std::unique(blocks.begin(), blocks.end()), blocks.end());
        return blocks;
    }

    const TreeT& tree_of(const openvdb::GridBase& grid, std::size_t k) const {
        const auto* typed = dynamic_cast<const GridT*>(&grid);
        if (!typed)
            throw input_error("brick store '" + index_.dir() + "': '" + index_.bricks()[k].file +
                              "' holds another value type than the store's grid.vdb; split the volume again with "
                              "pqdc-bricks split");
        return typed->tree();
    }

    /// f(origin) for every leaf of `tree` that overlaps `box`, skipping the
    /// internal nodes outside it.
    template <class F>
    static void for_each_leaf_in(const TreeT& tree, const openvdb::CoordBBox& box, const F& f) {
        for (auto n2 = tree.root().cbeginChildOn(); n2; ++n2) {
            if (!n2->getNodeBoundingBox().hasOverlap(box)) continue;
            for (auto n1 = n2->cbeginChildOn(); n1; ++n1) {
                if (!n1->getNodeBoundingBox().hasOverlap(box)) continue;
                for (auto leaf = n1->cbeginChildOn(); leaf; ++leaf)
                    if (leaf->getNodeBoundingBox().hasOverlap(box)) f(leaf->origin());
            }
        }
    }

    const StoreIndex& index_;
    const TreeT& shell_;
    BrickFileCache files_;
};

}  // namespace pqdc::detail
