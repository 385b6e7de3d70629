#include "bricks/bricks.hpp"

#include "lattice/smooth_field.hpp"
#include "pqdc/distributed.hpp"
#include "pqdc/exceptions.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace pqdc::detail {
namespace {

constexpr int kNodeVoxels = 128;   // a level-1 internal node of the 5-4-3 tree
constexpr int kNodesPerAxis = 32;  // level-1 nodes along each axis of a root child
constexpr int kLeafVoxels = 8;

int align_up(int v, int to) { return (v + to - 1) / to * to; }

}  // namespace

openvdb::Coord brick_extent(int brick_size) {
    if (brick_size < 128 || brick_size > 4096 || (brick_size & (brick_size - 1)))
        throw std::logic_error("internal error: brick size " + std::to_string(brick_size) + " was not validated");
    int nodes = 1;  // level-1 nodes in the brick: (brick_size / 128)^3
    for (int s = brick_size / kNodeVoxels; s > 1; s /= 2) nodes *= 8;
    const int nz = std::min(kNodesPerAxis, nodes);
    const int ny = std::min(kNodesPerAxis, nodes / nz);
    const int nx = nodes / (nz * ny);
    return openvdb::Coord(nx * kNodeVoxels, ny * kNodeVoxels, nz * kNodeVoxels);
}

std::vector<BrickRun> split_into_bricks(const std::vector<openvdb::Coord>& leaves, int brick_size) {
    const openvdb::Coord extent = brick_extent(brick_size);
    std::vector<BrickRun> runs;
    for (std::size_t i = 0; i < leaves.size(); ++i) {
        const openvdb::Coord lo = brick_origin(leaves[i], extent);
        if (runs.empty() || runs.back().box.min() != lo) {
            BrickRun r;
            r.box = openvdb::CoordBBox(lo, lo + extent - openvdb::Coord(1));
            r.begin = i;
            runs.push_back(r);
        }
        runs.back().end = i + 1;
    }
    std::vector<openvdb::Coord> seen;
    seen.reserve(runs.size());
    for (const BrickRun& r : runs) seen.push_back(r.box.min());
    std::sort(seen.begin(), seen.end());
    if (std::adjacent_find(seen.begin(), seen.end()) != seen.end())
        throw std::logic_error("internal error: a brick's candidate leaves are not one run of the list");
    return runs;
}

std::pair<std::size_t, std::size_t> rank_bricks(const std::vector<BrickRun>& bricks, int rank, int ranks) {
    const std::size_t total = bricks.empty() ? 0 : bricks.back().end - bricks.front().begin;
    // The first brick whose leaves start at or after r / ranks of the total
    // (in doubles: exact below 2^53, and every rank computes the same cut).
    auto first_of = [&](int r) {
        const double cut = double(total) * double(r);
        std::size_t k = 0;
        while (k < bricks.size() && double(bricks[k].begin - bricks.front().begin) * double(ranks) < cut) ++k;
        return k;
    };
    return {first_of(rank), rank + 1 == ranks ? bricks.size() : first_of(rank + 1)};
}

bool tree_order_less(const openvdb::Coord& a, const openvdb::Coord& b) {
    // Root child (4096^3; the root's map compares origins x, y, z), level-1
    // node in it (128^3), leaf in that (8^3): each x-major.
    constexpr int kShifts[3] = {12, 7, 3};
    for (int level = 0; level < 3; ++level) {
        const int s = kShifts[level];
        for (int axis = 0; axis < 3; ++axis) {
            // Arithmetic shift floors negative coordinates, as the node origins do.
            const int ka = level == 0 ? (a[axis] >> s) : (a[axis] >> s) & ((1 << (kShifts[level - 1] - s)) - 1);
            const int kb = level == 0 ? (b[axis] >> s) : (b[axis] >> s) & ((1 << (kShifts[level - 1] - s)) - 1);
            if (ka != kb) return ka < kb;
        }
    }
    return false;
}

int brick_halo(int cells_reach, bool smoothing) {
    // The points the cells stage reads lie within the leaves next to the brick.
    const int cells = align_up(cells_reach, kLeafVoxels);
    // Smoothing those leaves reads two more points around each: the next leaves.
    return smoothing ? cells + align_up(kSmoothReach, kLeafVoxels) : cells;
}

void check_rank_group(const RankGroup& group) {
    if (group.size() < 1 || group.rank() < 0 || group.rank() >= group.size())
        throw option_error("the rank group says it is rank " + std::to_string(group.rank()) + " of " +
                           std::to_string(group.size()) + "; ranks run from 0 to size - 1");
}

}  // namespace pqdc::detail
