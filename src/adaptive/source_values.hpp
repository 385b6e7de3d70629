// The voxel values a run by bricks probes after the bricks (adaptive mode:
// the upper octree levels and the polygons probe the field near the
// surface), read leaf by leaf from the BrickSource into a small cache per
// thread. Probing a delay-loaded grid through its own accessors loads every
// leaf touched for good: on the 2048^3 sphere store that held 0.85 GiB at
// the end of the run. Here the memory is bounded by the threads' caches and
// the values are the same. The file pages the copies map (64 KiB of
// fault-around per leaf) are handed back every kLeavesPerRelease leaves, as
// the bricks hand theirs back after each brick; a concurrent read faults its
// page back in, the same bytes.
//
// On noisy grids (smooth_field) each leaf is smoothed as it is copied: its
// smoothed values read the raw values within kSmoothReach (2) of it, copied
// too (a second cache per thread, at most 27 raw leaves per smoothed leaf,
// emptied with the first), so they are smooth_field's values of
// the whole grid, where a copy of every leaf near the surface was held before.
#pragma once

#include "lattice/interior.hpp"
#include "lattice/smooth_field.hpp"
#include "scale/brick_source.hpp"
#include "scale/coord_hash.hpp"
#include "scale/mapped_pages.hpp"

#include <tbb/enumerable_thread_specific.h>

#include <openvdb/openvdb.h>

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <unordered_set>

namespace pqdc::adaptive_detail {

/// What the adaptive stages need of a grid (getConstAccessor) over a
/// BrickSource, which must outlive it.
template <class TreeT>
class SourceValues {
public:
    using ValueType = typename TreeT::ValueType;
    /// Leaves a thread's cache holds before it is emptied: about 2 MiB of float values.
    static constexpr std::size_t kLeaves = 1024;
    /// Leaves copied (by all threads) between hand-backs of the mapped pages: at most 64 MiB of them.
    static constexpr std::uint64_t kLeavesPerRelease = 1024;

private:
    /// One thread's copies. Accessors of one thread share it; each read
    /// checks it afresh (`last`), so one accessor emptying it cannot leave
    /// another reading a leaf that is gone.
    struct Cache {
        std::unique_ptr<TreeT> tree;
        std::unique_ptr<TreeT> raw;  ///< smoothing only: the raw leaves around the smoothed ones
        std::unique_ptr<openvdb::tree::ValueAccessor<const TreeT>> acc;
        std::unordered_set<openvdb::Coord, detail::CoordHash> fetched;
        openvdb::Coord last = openvdb::Coord::max();  // no leaf's origin (not 8-aligned)
    };

public:
    /// getValue as a tree accessor has it (what topology_safe and
    /// openvdb::tools::BoxSampler call). Use it on the thread that made it.
    class ConstAccessor {
    public:
        using ValueType = typename TreeT::ValueType;
        ConstAccessor(const SourceValues& values, Cache& cache) : values_(&values), cache_(&cache) {}
        ValueType getValue(const openvdb::Coord& p) const {
            const openvdb::Coord leaf = p & ~int(TreeT::LeafNodeType::DIM - 1);
            if (leaf != cache_->last) {
                values_->fetch(leaf, *cache_);
                cache_->last = leaf;
            }
            return cache_->acc->getValue(p);
        }

    private:
        const SourceValues* values_;
        Cache* cache_;
    };

    /// `smoothing`: the signing of smooth_field, to read its values (null: the raw values).
    explicit SourceValues(const detail::BrickSource<TreeT>& source, const detail::Signing* smoothing = nullptr)
        : source_(source), smoothing_(smoothing) {}
    ConstAccessor getConstAccessor() const {
        Cache& cache = caches_.local();
        if (!cache.tree) {
            cache.tree = std::make_unique<TreeT>(source_.background());
            if (smoothing_) cache.raw = std::make_unique<TreeT>(source_.background());
            cache.acc = std::make_unique<openvdb::tree::ValueAccessor<const TreeT>>(*cache.tree);
        }
        return ConstAccessor(*this, cache);
    }

private:
    void fetch(const openvdb::Coord& leaf, Cache& cache) const {
        if (cache.fetched.count(leaf)) return;
        if (cache.fetched.size() >= kLeaves) {
            cache.acc->clear();
            cache.tree->clear();
            if (cache.raw) cache.raw->clear();
            cache.fetched.clear();
        }
        // Copies keep their file references: reading one loads the copy only.
        const openvdb::CoordBBox box(leaf, leaf + openvdb::Coord(int(TreeT::LeafNodeType::DIM) - 1));
        if (!smoothing_) {
            source_.copy_box(box, *cache.tree);
        } else {
            openvdb::CoordBBox around = box;
            around.expand(detail::kSmoothReach);
            source_.copy_box(around, *cache.raw);
            if (const auto* raw_leaf = cache.raw->probeConstLeaf(leaf)) {
                auto smoothed = std::make_unique<typename TreeT::LeafNodeType>(*raw_leaf);
                detail::smooth_leaf(*cache.raw, *smoothed, *smoothing_);
                cache.tree->addLeaf(smoothed.release());
            } else {
                detail::copy_tree_box(*cache.raw, box, *cache.tree);  // a tile or background: smoothing keeps it
            }
        }
        cache.fetched.insert(leaf);
        if (++copies_ % kLeavesPerRelease == 0) detail::release_mapped_volume_pages();
    }

    const detail::BrickSource<TreeT>& source_;
    const detail::Signing* smoothing_;
    mutable tbb::enumerable_thread_specific<Cache> caches_;
    mutable std::atomic<std::uint64_t> copies_{0};
};

}  // namespace pqdc::adaptive_detail
