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
#pragma once

#include "scale/brick_source.hpp"
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
    struct CoordHash {
        std::size_t operator()(const openvdb::Coord& c) const {
            return std::size_t(std::uint64_t(std::uint32_t(c.x())) * 73856093u ^
                               std::uint64_t(std::uint32_t(c.y())) * 19349663u ^
                               std::uint64_t(std::uint32_t(c.z())) * 83492791u);
        }
    };
    /// One thread's copies. Accessors of one thread share it; each read
    /// checks it afresh (`last`), so one accessor emptying it cannot leave
    /// another reading a leaf that is gone.
    struct Cache {
        std::unique_ptr<TreeT> tree;
        std::unique_ptr<openvdb::tree::ValueAccessor<const TreeT>> acc;
        std::unordered_set<openvdb::Coord, CoordHash> fetched;
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

    explicit SourceValues(const detail::BrickSource<TreeT>& source) : source_(source) {}
    ConstAccessor getConstAccessor() const {
        Cache& cache = caches_.local();
        if (!cache.tree) {
            cache.tree = std::make_unique<TreeT>(source_.background());
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
            cache.fetched.clear();
        }
        // Copies keep their file references: reading one loads the copy only.
        source_.copy_box(openvdb::CoordBBox(leaf, leaf + openvdb::Coord(int(TreeT::LeafNodeType::DIM) - 1)),
                         *cache.tree);
        cache.fetched.insert(leaf);
        if (++copies_ % kLeavesPerRelease == 0) detail::release_mapped_volume_pages();
    }

    const detail::BrickSource<TreeT>& source_;
    mutable tbb::enumerable_thread_specific<Cache> caches_;
    mutable std::atomic<std::uint64_t> copies_{0};
};

}  // namespace pqdc::adaptive_detail
