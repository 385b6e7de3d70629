// Broad phase for meshes of similar-sized triangles (every mesh pqdc
// extracts): the overlapping pairs of axis-aligned boxes through a uniform
// grid, each pair once. Cheaper than a box tree by an order of magnitude on
// such meshes: no serial build, no traversal, and the boxes of one grid cell
// sit next to each other in memory.
//
// Each box is registered in every cell it touches; a pair is reported only
// by the cell holding the lowest corner of the two boxes' overlap, which
// both boxes are registered in, so every overlapping pair is met exactly once.
// The cell size is twice the median box extent. A box may touch up to 16^3
// cells: adaptive meshes have a few triangles of merged leaves 8-64 voxels
// wide among finest-level ones (with at most 4^3, figure3's adaptive mesh
// went to the tree, 3x slower). When the boxes do not suit a grid (huge
// boxes, more than 8 cells per box on average, crowded cells, an extent of
// zero, a lattice beyond 2^21 cells per axis) `build` returns false and the
// caller uses the tree.
#pragma once

#include "geometry/float_rounding.hpp"
#include "measure/default_init.hpp"

#include <openvdb/openvdb.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <functional>
#include <limits>
#include <numeric>
#include <vector>

namespace pqdc::detail {

/// Bounds in float, rounded outwards: half the memory of double bounds
/// (the largest array of the self-intersection check), and the box still
/// contains its triangle, so no overlapping pair is missed; the exact test
/// decides the few extra ones.
struct Box {
    openvdb::Vec3f lo, hi;
};

/// The largest float at most x (-inf below the float range).
inline float float_at_or_below(double x) {
    constexpr double kMax = double(std::numeric_limits<float>::max());
    if (!(x >= -kMax)) return -std::numeric_limits<float>::infinity();
    if (x >= kMax) return std::numeric_limits<float>::max();
    float f = detail::nearest_float(x);
    if (double(f) > x) {  // one float step down: the next representable value
        if (f == 0.0f) return -std::numeric_limits<float>::denorm_min();
        std::uint32_t bits;
        std::memcpy(&bits, &f, sizeof f);
        bits = f > 0.0f ? bits - 1 : bits + 1;
        std::memcpy(&f, &bits, sizeof f);
    }
    return f;
}

/// The bounding box of a triangle, rounded outwards to float.
inline Box bounding_box(const openvdb::Vec3d& a, const openvdb::Vec3d& b, const openvdb::Vec3d& c) {
    Box box;
    for (int k = 0; k < 3; ++k) {
        box.lo[k] = float_at_or_below(std::min({a[k], b[k], c[k]}));
        box.hi[k] = -float_at_or_below(-std::max({a[k], b[k], c[k]}));
    }
    return box;
}

inline bool boxes_overlap(const Box& a, const Box& b) {
    for (int k = 0; k < 3; ++k)
        if (a.hi[k] < b.lo[k] || b.hi[k] < a.lo[k]) return false;
    return true;
}

inline bool boxes_overlap(const Box& a, const openvdb::Vec3d& lo, const openvdb::Vec3d& hi) {
    for (int k = 0; k < 3; ++k)
        if (double(a.hi[k]) < lo[k] || hi[k] < double(a.lo[k])) return false;
    return true;
}

class BoxGrid {
public:
    /// Every box takes part. False: use another broad phase. `checkpoint`
    /// runs between the steps (a cancellation point; it may throw). A grid
    /// built again keeps its arrays' memory (the parts of one check).
    bool build(const std::vector<Box>& boxes, const std::function<void()>& checkpoint);

    /// Calls visit(chunk, a, b, load(a), load(b)) for every overlapping pair
    /// a < b reported by the chunks [first, last), from TBB tasks; chunk in
    /// [0, chunk_count()) is the same for any thread count, so per-chunk
    /// results joined in chunk order are deterministic. load(id) is called
    /// once per box and grid cell, not once per pair (a box overlaps about
    /// five others per cell, and memory traffic is most of the cost).
    template <class Load, class Visit>
    void for_each_pair(const std::vector<Box>& boxes, std::size_t first, std::size_t last, const Load& load,
                       Visit&& visit) const;
    std::size_t chunk_count() const { return chunk_begin_.size() ? chunk_begin_.size() - 1 : 0; }

private:
    using Key = std::uint64_t;
    static constexpr int kAxisBits = 21;
    static constexpr std::size_t kMaxCellsPerBox = 4096, kMaxEntriesPerBox = 8, kPairBudgetPerBox = 256;
    static constexpr std::size_t kChunkEntries = 1 << 14;

    std::array<std::int64_t, 3> cell_of(const openvdb::Vec3d& p) const {
        std::array<std::int64_t, 3> c;
        for (int k = 0; k < 3; ++k) {
            const double x = std::floor((p[k] - origin_[k]) * inverse_cell_);
            c[k] = std::int64_t(std::min(std::max(x, 0.0), double(dims_[k] - 1)));  // clamped before the cast
        }
        return c;
    }
    static std::array<std::int64_t, 3> cell_of_key(Key k) {
        constexpr Key mask = (Key(1) << kAxisBits) - 1;
        return {std::int64_t(k >> (2 * kAxisBits)), std::int64_t((k >> kAxisBits) & mask), std::int64_t(k & mask)};
    }
    static Key key_of(const std::array<std::int64_t, 3>& c) {
        return (Key(c[0]) << (2 * kAxisBits)) | (Key(c[1]) << kAxisBits) | Key(c[2]);
    }
    std::size_t cells_of(const Box& b) const {
        const auto lo = cell_of(openvdb::Vec3d(b.lo)), hi = cell_of(openvdb::Vec3d(b.hi));
        return std::size_t((hi[0] - lo[0] + 1) * (hi[1] - lo[1] + 1) * (hi[2] - lo[2] + 1));
    }
    bool choose_cell(const std::vector<Box>& boxes);
    void register_boxes(const std::vector<Box>& boxes, const std::vector<std::size_t>& offset);
    void sort_entries(const std::function<void()>& checkpoint);
    bool split_chunks();

    openvdb::Vec3d origin_;
    double inverse_cell_ = 0;
    std::array<std::int64_t, 3> dims_{};
    UninitializedVector<Key> keys_;           ///< per entry, sorted
    UninitializedVector<std::uint32_t> ids_;  ///< per entry: the box; ascending within a cell
    UninitializedVector<Key> sort_keys_;      ///< the radix sort's other buffers
    UninitializedVector<std::uint32_t> sort_ids_;
    std::vector<std::size_t> offset_;         ///< per box + 1: its first entry
    std::vector<std::size_t> chunk_begin_;  ///< entry ranges made of whole cells
};

template <class Load, class Visit>
void BoxGrid::for_each_pair(const std::vector<Box>& boxes, std::size_t first, std::size_t last, const Load& load,
                            Visit&& visit) const {
    using Payload = decltype(load(std::uint32_t(0)));
    // One cell's boxes side by side, one array per bound: the test of one
    // box against the rest of its cell is a branch-free loop (about three in
    // four boxes of a cell miss each other, so a branch per test was
    // mispredicted often), and the overlapping ones are then compacted.
    struct Cell {
        std::vector<float> lo[3], hi[3];
        std::vector<std::uint8_t> overlap;
        std::vector<std::uint32_t> id, hit;
        std::vector<std::array<std::int64_t, 3>> lo_cell;
        std::vector<Payload> payload;
        void resize(std::size_t m) {
            for (int k = 0; k < 3; ++k) {
                lo[k].resize(m);
                hi[k].resize(m);
            }
            overlap.resize(m);
            id.resize(m);
            hit.resize(m);
            lo_cell.resize(m);
            payload.resize(m);
        }
    };
    tbb::parallel_for(tbb::blocked_range<std::size_t>(first, last, 1), [&](const tbb::blocked_range<std::size_t>& r) {
        Cell c;
        for (std::size_t chunk = r.begin(); chunk != r.end(); ++chunk) {
            std::size_t cell = chunk_begin_[chunk];
            while (cell < chunk_begin_[chunk + 1]) {
                std::size_t end = cell + 1;
                while (end < keys_.size() && keys_[end] == keys_[cell]) ++end;
                const std::size_t m = end - cell;
                c.resize(m);
                for (std::size_t i = 0; i < m; ++i) {
                    const std::uint32_t id = ids_[cell + i];
                    const Box& b = boxes[id];
                    for (int k = 0; k < 3; ++k) {
                        c.lo[k][i] = b.lo[k];
                        c.hi[k][i] = b.hi[k];
                    }
                    c.id[i] = id;
                    c.lo_cell[i] = cell_of(openvdb::Vec3d(b.lo));
                    c.payload[i] = load(id);
                }
                const std::array<std::int64_t, 3> here = cell_of_key(keys_[cell]);
                for (std::size_t i = 0; i + 1 < m; ++i) {
                    const float lx = c.lo[0][i], ly = c.lo[1][i], lz = c.lo[2][i];
                    const float hx = c.hi[0][i], hy = c.hi[1][i], hz = c.hi[2][i];
                    for (std::size_t j = i + 1; j < m; ++j)
                        c.overlap[j] = (c.lo[0][j] <= hx) & (lx <= c.hi[0][j]) & (c.lo[1][j] <= hy) &
                                       (ly <= c.hi[1][j]) & (c.lo[2][j] <= hz) & (lz <= c.hi[2][j]);
                    std::size_t hits = 0;
                    for (std::size_t j = i + 1; j < m; ++j) {
                        c.hit[hits] = std::uint32_t(j);
                        hits += c.overlap[j];
                    }
                    const std::array<std::int64_t, 3>& cell_i = c.lo_cell[i];
                    for (std::size_t h = 0; h < hits; ++h) {
                        const std::size_t j = c.hit[h];
                        // The overlap's lowest corner is max(a.lo, b.lo), and cell_of
                        // is monotone: its cell is the larger of the two lo cells.
                        const std::array<std::int64_t, 3>& cell_j = c.lo_cell[j];
                        bool owner = true;
                        for (int k = 0; k < 3; ++k) owner = owner && std::max(cell_i[k], cell_j[k]) == here[k];
                        if (owner) visit(chunk, c.id[i], c.id[j], c.payload[i], c.payload[j]);
                    }
                }
                cell = end;
            }
        }
    });
}

}  // namespace pqdc::detail
