// A brick store read brick file by brick file (issue 14): the BrickSource
// for stores whose topology alone does not fit in memory. Nothing is
// assembled: the candidate list is each brick file's candidates merged in
// tree order, a brick's values (with its halo) are copied out of the few
// files its box overlaps, and the files' topology is kept, compact, in a
// cache bounded in bytes (bricks/store_files.hpp), so memory holds the index,
// the candidate list and the bricks in flight.
//
// Why the candidates merge: candidate_blocks is a union over source leaves
// and active tiles (each touches its block and lower neighbours), so the
// union over brick files of each file's candidates is the whole volume's;
// the root's tiles, which no brick file holds, come from the shell.
#pragma once

#include "lattice/candidates.hpp"
#include "lattice/resources.hpp"
#include "pqdc/exceptions.hpp"
#include "bricks/brick_source.hpp"
#include "bricks/bricks.hpp"
#include "bricks/mapped_pages.hpp"
#include "ranks/rank_exchange.hpp"
#include "bricks/store_files.hpp"
#include "bricks/store_index.hpp"

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <exception>
#include <vector>

namespace pqdc::detail {

template <class TreeT>
class StoreBrickSource : public BrickSource<TreeT> {
public:
    using typename BrickSource<TreeT>::ValueT;

    /// `shell`: the store's grid without voxels (its root's tiles);
    /// `cache_bytes`: how much parsed brick-file topology may be held at once.
    StoreBrickSource(const StoreIndex& index, const openvdb::Grid<TreeT>& shell, std::uint64_t cache_bytes)
        : index_(index), shell_(shell.tree()), files_(index, shell, cache_bytes) {}

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
        return files_.open(k)->is_value_on(p);
    }

    void copy_box(const openvdb::CoordBBox& box, TreeT& into) const override {
        copy_tree_box(shell_, box, into);  // the root's tiles
        for (const std::size_t k : index_.overlapping(box)) {
            openvdb::CoordBBox part = box;
            part.intersect(index_.bricks()[k].box);
            files_.open(k)->copy(part, into);  // leaves read when the brick's stages read them
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
        // In chunks of about kPagesPerRelease bytes of files, handing their
        // mapped pages back between chunks: parsing a file's topology faults
        // most of its pages in. (Each hand-back walks every mapped file, and
        // the cache keeps thousands mapped: chunks of 4 files took 15 s of a
        // 3070-file store's 112 s.)
        constexpr std::uint64_t kPagesPerRelease = std::uint64_t(256) << 20;
        for (std::size_t start = first; start < last;) {
            std::size_t end = start;
            for (std::uint64_t bytes = 0; end < last && (end == start || bytes < kPagesPerRelease); ++end)
                bytes += index_.bricks()[end].bytes;
            // A failure is kept, not thrown through the loop: TBB would cancel
            // the other files' tasks and with them OpenVDB's nested loops that
            // free trees (Tree::clear), leaking them; and the first failing
            // file by index is the one reported, whatever the thread timing.
            std::vector<std::exception_ptr> failed(end - start);
            tbb::parallel_for(start, end, [&](std::size_t k) {
                try {
                    scan_file(k, bytes_per_block, options, clip, reach, parts[k - first]);
                } catch (...) {
                    failed[k - start] = std::current_exception();
                }
            });
            for (const std::exception_ptr& e : failed)
                if (e) std::rethrow_exception(e);
            release_mapped_volume_pages();
            start = end;
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

    /// The candidates of brick file `k` into `part` (none when the file
    /// cannot reach `reach`).
    void scan_file(std::size_t k, double bytes_per_block, const ExtractOptions& options,
                   const openvdb::CoordBBox& clip, const openvdb::CoordBBox& reach,
                   std::vector<openvdb::Coord>& part) const {
        if (!index_.bricks()[k].box.hasOverlap(reach)) return;
        bool scanned = false;
        const auto brick = files_.open(k, [&](const TreeT& fresh) {
            part = detail::candidate_blocks(fresh, bytes_per_block, options, clip);
            scanned = true;
        });
        if (scanned) return;
        TreeT copy(shell_.background());  // the file was open already (another rank's share)
        brick->copy(index_.bricks()[k].box, copy);
        part = detail::candidate_blocks(copy, bytes_per_block, options, clip);
    }

    /// `blocks` in tree order, each once (a file's lower-neighbour blocks
    /// may be another file's too).
    static std::vector<openvdb::Coord> merged(std::vector<openvdb::Coord> blocks) {
        tbb::parallel_sort(blocks.begin(), blocks.end(), tree_order_less);
        blocks.erase(std::unique(blocks.begin(), blocks.end()), blocks.end());
        return blocks;
    }

    const StoreIndex& index_;
    const TreeT& shell_;
    BrickFiles<TreeT> files_;
};

}  // namespace pqdc::detail
