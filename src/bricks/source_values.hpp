// The voxel values a run by bricks probes after the bricks (adaptive mode:
// the upper octree levels and the polygons probe the field near the
// surface; streamed runs: the vertex normals of each piece), read leaf by leaf from the BrickSource into a small cache per
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
// Smoothing a leaf costs far more than copying one (it was 41% of an
// adaptive run on a noisy volume with caches of 1024 leaves, which every
// stage and every rebuild refilled), so the caller may give smoothed caches
// more room: cache_leaves_for().
#pragma once

#include "lattice/interior.hpp"
#include "lattice/smooth_field.hpp"
#include "bricks/brick_source.hpp"
#include "bricks/coord_hash.hpp"
#include "bricks/mapped_pages.hpp"

#include <tbb/enumerable_thread_specific.h>

#include <openvdb/openvdb.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <unordered_set>

namespace pqdc::detail {

/// What the later stages need of a grid (getConstAccessor) over a
/// BrickSource, which must outlive it.
template <class TreeT>
class SourceValues {
public:
    using ValueType = typename TreeT::ValueType;
    /// Leaves a thread's cache holds before it is emptied when reading raw
    /// values: about 2 MiB of float values.
    static constexpr std::size_t kLeaves = 1024;
    /// Bytes a smoothed leaf holds with its share of raw leaves, about: the
    /// raw cache holds the smoothed leaves' surroundings, a few leaves each.
    static constexpr std::size_t kSmoothedLeafBytes = 4 * TreeT::LeafNodeType::SIZE * sizeof(ValueType);

    /// The per-thread capacity for `threads` threads sharing `budget` bytes:
    /// kLeaves for raw values; for smoothed values as many as fit, at least kLeaves.
    static std::size_t cache_leaves_for(bool smoothing, std::size_t budget, int threads) {
        if (!smoothing) return kLeaves;
        return std::max(kLeaves, budget / std::size_t(std::max(threads, 1)) / kSmoothedLeafBytes);
    }
    /// Leaves copied (by all threads) between hand-backs of the mapped pages: at most 64 MiB of them.
    static constexpr std::uint64_t kLeavesPerRelease = 1024;

private:
    /// One thread's copies. Accessors of one thread share it; each read
    /// checks it afresh (`recent`), so one accessor emptying it cannot leave
    /// another reading a leaf that is gone.
    struct Cache {
        std::unique_ptr<TreeT> tree;
        std::unique_ptr<TreeT> raw;  ///< smoothing only: the raw leaves around the smoothed ones
        std::unique_ptr<openvdb::tree::ValueAccessor<const TreeT>> acc;
        std::unordered_set<openvdb::Coord, CoordHash> fetched;
        /// The last leaves read, known to be in `fetched`, and their copies
        /// (null: a tile or the background): stencils that straddle leaves
        /// alternate between a few. Coord::max() is no leaf's origin.
        struct Recent {
            openvdb::Coord origin = openvdb::Coord::max();
            const typename TreeT::LeafNodeType* leaf = nullptr;
        };
        std::array<Recent, 4> recent;
        unsigned next_recent = 0;
        const Recent* find_recent(const openvdb::Coord& origin) const {
            for (const Recent& r : recent)
                if (r.origin == origin) return &r;
            return nullptr;
        }
    };

public:
    /// getValue as a tree accessor has it (what topology_safe and
    /// openvdb::tools::BoxSampler call). Use it on the thread that made it.
    class ConstAccessor {
    public:
        using ValueType = typename TreeT::ValueType;
        ConstAccessor(const SourceValues& values, Cache& cache) : values_(&values), cache_(&cache) {}
        ValueType getValue(const openvdb::Coord& p) const {
            const auto* leaf = leaf_copy(p & ~int(kDim - 1));
            return leaf ? leaf->getValue(p) : cache_->acc->getValue(p);
        }

        /// detail::read_block4 (normals/outward_normal.hpp): one look-up per
        /// leaf the 4^3 block meets, not one per voxel.
        friend void read_block4(const ConstAccessor& a, const openvdb::Coord& min, ValueType* out) {
            // Along each axis the block's voxels before the next leaf boundary, and the rest.
            int first[3];
            for (int axis = 0; axis < 3; ++axis) first[axis] = std::min(4, kDim - (min[axis] & (kDim - 1)));
            for (int sx = 0; sx < 4; sx = sx < first[0] ? first[0] : 4) {
                const int ex = sx < first[0] ? first[0] : 4;
                for (int sy = 0; sy < 4; sy = sy < first[1] ? first[1] : 4) {
                    const int ey = sy < first[1] ? first[1] : 4;
                    for (int sz = 0; sz < 4; sz = sz < first[2] ? first[2] : 4) {
                        const int ez = sz < first[2] ? first[2] : 4;
                        const openvdb::Coord corner = min.offsetBy(sx, sy, sz);
                        const auto* leaf = a.leaf_copy(corner & ~int(kDim - 1));
                        if (!leaf) {  // a tile or the background
                            for (int x = sx; x < ex; ++x)
                                for (int y = sy; y < ey; ++y)
                                    for (int z = sz; z < ez; ++z)
                                        out[16 * x + 4 * y + z] = a.cache_->acc->getValue(min.offsetBy(x, y, z));
                            continue;
                        }
                        // The leaf's values in place (data() loads a copy still in the file): x-major, z fastest.
                        const ValueType* values = leaf->buffer().data();
                        const int base = int(TreeT::LeafNodeType::coordToOffset(corner)) - ((sx * kDim + sy) * kDim + sz);
                        for (int x = sx; x < ex; ++x)
                            for (int y = sy; y < ey; ++y)
                                for (int z = sz; z < ez; ++z) out[16 * x + 4 * y + z] = values[base + (x * kDim + y) * kDim + z];
                    }
                }
            }
        }

    private:
        static constexpr int kDim = int(TreeT::LeafNodeType::DIM);

        /// The copy of the leaf at `origin`, fetched if need be; null where
        /// the source has a tile or the background there.
        const typename TreeT::LeafNodeType* leaf_copy(const openvdb::Coord& origin) const {
            if (const auto* r = cache_->find_recent(origin)) return r->leaf;
            values_->fetch(origin, *cache_);  // may empty the cache, and `recent` with it
            auto& slot = cache_->recent[cache_->next_recent++ % cache_->recent.size()];
            slot.origin = origin;
            slot.leaf = cache_->tree->probeConstLeaf(origin);
            return slot.leaf;
        }

        const SourceValues* values_;
        Cache* cache_;
    };

    /// `smoothing`: the signing of smooth_field, to read its values (null: the raw values).
    /// `cache_leaves`: each thread's capacity (cache_leaves_for()).
    explicit SourceValues(const BrickSource<TreeT>& source, const Signing* smoothing = nullptr,
                          std::size_t cache_leaves = kLeaves)
        : source_(source), smoothing_(smoothing), cache_leaves_(cache_leaves) {}
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
        if (cache.fetched.size() >= cache_leaves_) {
            cache.acc->clear();
            cache.tree->clear();
            if (cache.raw) cache.raw->clear();
            cache.fetched.clear();
            cache.recent.fill({});
        }
        // Copies keep their file references: reading one loads the copy only.
        const openvdb::CoordBBox box(leaf, leaf + openvdb::Coord(int(TreeT::LeafNodeType::DIM) - 1));
        if (!smoothing_) {
            source_.copy_box(box, *cache.tree);
        } else {
            openvdb::CoordBBox around = box;
            around.expand(kSmoothReach);
            source_.copy_box(around, *cache.raw);
            if (const auto* raw_leaf = cache.raw->probeConstLeaf(leaf)) {
                auto smoothed = std::make_unique<typename TreeT::LeafNodeType>(*raw_leaf);
                smooth_leaf(*cache.raw, *smoothed, *smoothing_);
                cache.tree->addLeaf(smoothed.release());
            } else {
                copy_tree_box(*cache.raw, box, *cache.tree);  // a tile or background: smoothing keeps it
            }
        }
        cache.fetched.insert(leaf);
        if (++copies_ % kLeavesPerRelease == 0) release_mapped_volume_pages();
    }

    const BrickSource<TreeT>& source_;
    const Signing* smoothing_;
    std::size_t cache_leaves_;
    mutable tbb::enumerable_thread_specific<Cache> caches_;
    mutable std::atomic<std::uint64_t> copies_{0};
};

}  // namespace pqdc::detail
