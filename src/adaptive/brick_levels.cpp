#include "adaptive/brick_levels.hpp"

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <type_traits>
#include <utility>

namespace pqdc::adaptive_detail {

std::vector<openvdb::Coord> ring_blocks(const std::vector<openvdb::Coord>& sorted, const openvdb::CoordBBox& brick) {
    std::vector<openvdb::Coord> ring;
    auto look = [&](int x, int y, int z) {
        const openvdb::Coord b(x, y, z);
        if (std::binary_search(sorted.begin(), sorted.end(), b)) ring.push_back(b);
    };
    // Block origins from one block below the brick to one block past it;
    // inside the brick's x-y columns only the two end blocks of z are ring.
    const openvdb::Coord lo = brick.min() - openvdb::Coord(8), hi = brick.max() + openvdb::Coord(1);
    for (int x = lo.x(); x <= hi.x(); x += 8)
        for (int y = lo.y(); y <= hi.y(); y += 8) {
            const bool column_in_brick = x > lo.x() && x < hi.x() && y > lo.y() && y < hi.y();
            if (column_in_brick) {
                look(x, y, lo.z());
                look(x, y, hi.z());
                continue;
            }
            for (int z = lo.z(); z <= hi.z(); z += 8) look(x, y, z);
        }
    return ring;
}

std::size_t append_brick_nodes(const Octree& local, int top, const openvdb::CoordBBox& brick,
                               std::vector<Level>& out) {
    out.resize(std::size_t(top) + 1);
    std::size_t appended = 0;
    std::vector<std::uint8_t> keep, keep_below;
    for (int level = top; level >= 0; --level) {
        const Level& lv = local.levels[level];
        if (level == top) {
            keep.assign(lv.size(), 0);
            for (std::size_t i = 0; i < lv.size(); ++i) keep[i] = brick.isInside(local.origin(level, lv.code[i]));
        }
        // The children of kept internal nodes are kept (they lie in the same brick).
        if (level > 0) {
            keep_below.assign(local.levels[level - 1].size(), 0);
            for (std::size_t i = 0; i < lv.size(); ++i)
                if (keep[i] && !(lv.flags[i] & kLeaf))
                    std::fill_n(keep_below.begin() + lv.first_child[i], popcount8(lv.child_mask[i]), 1);
        }
        Level& o = out[std::size_t(level)];
        for (std::size_t i = 0; i < lv.size(); ++i) {
            if (!keep[i]) continue;
            o.code.push_back(lv.code[i]);
            o.flags.push_back(lv.flags[i]);
            o.vertex.push_back(lv.vertex[i]);
            if (level > 0) {
                o.child_mask.push_back(lv.child_mask[i]);
                o.first_child.push_back(0);
            }
            if (level == top) o.quadrics.push_back(lv.quadrics[i]);
            ++appended;
        }
        keep.swap(keep_below);
    }
    return appended;
}

void sort_and_link(std::vector<Level>& levels) {
    for (Level& lv : levels) {
        const std::size_t n = lv.size();
        if (std::is_sorted(lv.code.begin(), lv.code.end())) continue;
        std::vector<std::pair<std::uint64_t, std::size_t>> order(n);
        for (std::size_t i = 0; i < n; ++i) order[i] = {lv.code[i], i};
        tbb::parallel_sort(order.begin(), order.end());
        // One array at a time: memory holds the level and one permuted array.
        auto permute = [&](auto& v) {
            if (v.empty()) return;
            std::remove_reference_t<decltype(v)> sorted(n);
            tbb::parallel_for(std::size_t(0), n, [&](std::size_t k) { sorted[k] = v[order[k].second]; });
            v.swap(sorted);
        };
        permute(lv.code);
        permute(lv.flags);
        permute(lv.child_mask);
        permute(lv.quadrics);
        permute(lv.vertex);
    }
    for (std::size_t level = 1; level < levels.size(); ++level) {
        const std::vector<std::uint64_t>& below = levels[level - 1].code;
        Level& lv = levels[level];
        lv.first_child.resize(lv.size());
        tbb::parallel_for(std::size_t(0), lv.size(), [&](std::size_t i) {
            lv.first_child[i] =
                std::uint32_t(std::lower_bound(below.begin(), below.end(), lv.code[i] << 3) - below.begin());
        });
    }
}

}  // namespace pqdc::adaptive_detail
