// Stage "candidates": the 8^3 blocks of lattice cells that may hold a cell
// with an active corner, for both extractors.
#pragma once

#include "lattice/resources.hpp"

#include <openvdb/openvdb.h>

#include <cstdint>
#include <memory>
#include <vector>

namespace pqdc::detail {

/// Origins, in tree order, of the blocks that may hold a cell with an active
/// corner: the block of every source leaf and its seven lower neighbours (a
/// cell's corners lie at or above its minimum corner), and likewise along the
/// boundary shell of active tiles, whose interior is one constant and holds no
/// crossing. The cells themselves are classified later from the values.
/// Only blocks holding a cell whose minimum corner lies in `clip` (the
/// region's cell bounds) are kept, and only they count towards memory.
/// Throws resource_error (check_memory) when `bytes_per_block` times the
/// possible blocks exceeds the options' memory limit.
template <class TreeT>
std::vector<openvdb::Coord> candidate_blocks(const TreeT& src, double bytes_per_block, const ExtractOptions& options,
                                             const openvdb::CoordBBox& clip = openvdb::CoordBBox::inf()) {
    constexpr int L = int(TreeT::LeafNodeType::DIM);
    const bool clipped = clip != openvdb::CoordBBox::inf();
    // A source leaf seeds its own block and its lower neighbours: it matters
    // when it reaches the clip box widened by one block upwards.
    openvdb::CoordBBox seed_clip = clip;
    if (clipped) seed_clip.max() = seed_clip.max().offsetBy(L);
    auto block_in_clip = [&](const openvdb::Coord& origin) {
        return !clipped || clip.hasOverlap(openvdb::CoordBBox(origin, origin.offsetBy(L - 1)));
    };
    auto leaf_in_clip = [&](const openvdb::Coord& origin) {
        return !clipped || seed_clip.hasOverlap(openvdb::CoordBBox(origin, origin.offsetBy(L - 1)));
    };
    // Topology only (64-byte leaves).
    openvdb::MaskTree blocks(false);
    auto touch_with_lower = [&](const openvdb::Coord& origin) {
        for (int n = 0; n < 8; ++n)
            blocks.touchLeaf(origin - openvdb::Coord(n & 1 ? L : 0, n & 2 ? L : 0, n & 4 ? L : 0));
    };
    std::uint64_t seeds = 0;
    if (!clipped) seeds = src.leafCount();
    else
        for (auto it = src.cbeginLeaf(); it; ++it) seeds += leaf_in_clip(it->origin());
    std::vector<openvdb::CoordBBox> tiles;
    auto tile_it = src.cbeginValueOn();
    tile_it.setMaxDepth(TreeT::ValueOnCIter::LEAF_DEPTH - 1);  // tiles only: never visit the voxels
    for (auto& it = tile_it; it; ++it) {
        if (it.isVoxelValue()) continue;
        openvdb::CoordBBox box;
        it.getBoundingBox(box);
        if (clipped) {
            if (!seed_clip.hasOverlap(box)) continue;
            // Only the part near the clip box seeds blocks (its shell elsewhere is outside).
            openvdb::CoordBBox near = seed_clip;
            near.expand(L);
            box.intersect(near);
        }
        tiles.push_back(box);
        const std::uint64_t side = std::uint64_t(box.dim().x() / L) + 1;
        seeds += 6 * side * side;
    }
    // Touching lower neighbours at most doubles the blocks of a band or shell.
    check_memory(double(seeds) * 2 * bytes_per_block, options, "cell classification");
    for (auto it = src.cbeginLeaf(); it; ++it)
        if (leaf_in_clip(it->origin())) touch_with_lower(it->origin());
    for (const auto& box : tiles) {
        const openvdb::Coord lo = box.min(), hi = box.max();
        for (int a = 0; a < 3; ++a) {
            const int b = (a + 1) % 3, c = (a + 2) % 3;
            for (int side : {lo[a], hi[a]})
                for (int i = lo[b]; i <= hi[b]; i += L)
                    for (int j = lo[c]; j <= hi[c]; j += L) {
                        openvdb::Coord p;
                        p[a] = side;
                        p[b] = i;
                        p[c] = j;
                        touch_with_lower(p & ~(L - 1));
                    }
        }
    }
    std::vector<openvdb::Coord> origins;
    origins.reserve(blocks.leafCount());
    for (auto it = blocks.cbeginLeaf(); it; ++it)
        if (block_in_clip(it->origin())) origins.push_back(it->origin());
    return origins;
}

}  // namespace pqdc::detail
