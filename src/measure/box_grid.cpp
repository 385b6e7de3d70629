#include "measure/box_grid.hpp"

#include <tbb/parallel_reduce.h>

namespace pqdc::detail {

bool BoxGrid::choose_cell(const std::vector<Box>& boxes) {
    // The bounds (exact min/max, so any split order gives the same), and the
    // median of every 8th box's extent: the cell size only changes speed.
    struct Bounds {
        openvdb::Vec3d lo{std::numeric_limits<double>::max()}, hi{-std::numeric_limits<double>::max()};
    };
    const Bounds all = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, boxes.size(), 1 << 14), Bounds{},
        [&](const tbb::blocked_range<std::size_t>& r, Bounds b) {
            for (std::size_t i = r.begin(); i != r.end(); ++i) {
                b.lo = openvdb::math::minComponent(b.lo, openvdb::Vec3d(boxes[i].lo));
                b.hi = openvdb::math::maxComponent(b.hi, openvdb::Vec3d(boxes[i].hi));
            }
            return b;
        },
        [](const Bounds& a, const Bounds& b) {
            return Bounds{openvdb::math::minComponent(a.lo, b.lo), openvdb::math::maxComponent(a.hi, b.hi)};
        });
    std::vector<double> extents;
    extents.reserve(boxes.size() / 8 + 1);
    for (std::size_t i = 0; i < boxes.size(); i += 8) {
        const openvdb::Vec3d e = openvdb::Vec3d(boxes[i].hi) - openvdb::Vec3d(boxes[i].lo);
        extents.push_back(std::max({e[0], e[1], e[2]}));
    }
    if (extents.empty()) return false;
    auto median = extents.begin() + std::ptrdiff_t(extents.size() / 2);
    std::nth_element(extents.begin(), median, extents.end());
    const double cell = 2.0 * *median;
    if (!(cell > 0.0) || !std::isfinite(cell)) return false;
    origin_ = all.lo;
    inverse_cell_ = 1.0 / cell;
    for (int k = 0; k < 3; ++k) {
        const double n = std::floor((all.hi[k] - all.lo[k]) * inverse_cell_) + 1.0;
        if (!(n <= double(std::int64_t(1) << kAxisBits))) return false;
        dims_[k] = std::int64_t(n);
    }
    return true;
}

void BoxGrid::register_boxes(const std::vector<Box>& boxes, const std::vector<std::size_t>& offset) {
    keys_.resize(offset.back());
    ids_.resize(offset.back());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, boxes.size(), 4096), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            const auto lo = cell_of(openvdb::Vec3d(boxes[i].lo)), hi = cell_of(openvdb::Vec3d(boxes[i].hi));
            std::size_t e = offset[i];
            for (std::int64_t x = lo[0]; x <= hi[0]; ++x)
                for (std::int64_t y = lo[1]; y <= hi[1]; ++y)
                    for (std::int64_t z = lo[2]; z <= hi[2]; ++z, ++e) {
                        keys_[e] = key_of({x, y, z});
                        ids_[e] = std::uint32_t(i);
                    }
        }
    });
}

namespace {

constexpr int kRadixDigitBits = 11;

/// One stable pass of the radix sort on the digit at bit `at`, in parallel
/// over fixed blocks of entries: per-block histograms, one exclusive prefix
/// in (digit, block) order, then each block scatters its entries in order.
/// The blocks do not depend on the thread count, so neither does the result.
template <class Key>
void radix_pass(const UninitializedVector<Key>& keys, const UninitializedVector<std::uint32_t>& ids,
                UninitializedVector<Key>& keys_out, UninitializedVector<std::uint32_t>& ids_out, int at) {
    constexpr std::size_t kBuckets = std::size_t(1) << kRadixDigitBits, kBlock = std::size_t(1) << 16;
    const std::size_t n = keys.size(), blocks = (n + kBlock - 1) / kBlock;
    auto digit = [&](Key k) { return std::size_t((k >> at) & (kBuckets - 1)); };
    std::vector<std::size_t> start(blocks * kBuckets, 0);  // [block][digit]
    tbb::parallel_for(std::size_t(0), blocks, [&](std::size_t b) {
        std::size_t* count = start.data() + b * kBuckets;
        for (std::size_t e = b * kBlock, end = std::min(n, e + kBlock); e < end; ++e) ++count[digit(keys[e])];
    });
    std::size_t sum = 0;
    for (std::size_t d = 0; d < kBuckets; ++d)
        for (std::size_t b = 0; b < blocks; ++b) {
            const std::size_t c = start[b * kBuckets + d];
            start[b * kBuckets + d] = sum;
            sum += c;
        }
    tbb::parallel_for(std::size_t(0), blocks, [&](std::size_t b) {
        std::size_t* next = start.data() + b * kBuckets;
        for (std::size_t e = b * kBlock, end = std::min(n, e + kBlock); e < end; ++e) {
            const std::size_t to = next[digit(keys[e])]++;
            keys_out[to] = keys[e];
            ids_out[to] = ids[e];
        }
    });
}

}  // namespace

/// LSD radix sort of (key, id) by key. Stable, so ids stay ascending within
/// a cell; only the bits the lattice uses are sorted on.
void BoxGrid::sort_entries(const std::function<void()>& checkpoint) {
    UninitializedVector<Key>& keys = sort_keys_;
    UninitializedVector<std::uint32_t>& ids = sort_ids_;
    keys.resize(keys_.size());
    ids.resize(ids_.size());
    for (int axis = 2; axis >= 0; --axis) {
        int bits = 0;
        while ((std::int64_t(1) << bits) < dims_[axis]) ++bits;
        for (int shift = 0; shift < bits; shift += kRadixDigitBits) {
            radix_pass(keys_, ids_, keys, ids, (2 - axis) * kAxisBits + shift);
            keys_.swap(keys);
            ids_.swap(ids);
            checkpoint();
        }
    }
}

/// Chunks of whole cells; false when the cells are too crowded for pairwise
/// tests to beat a tree.
bool BoxGrid::split_chunks() {
    chunk_begin_.assign(1, 0);
    std::size_t pairs = 0, boxes_seen = 0;
    for (std::size_t cell = 0; cell < keys_.size();) {
        std::size_t end = cell + 1;
        while (end < keys_.size() && keys_[end] == keys_[cell]) ++end;
        const std::size_t m = end - cell;
        pairs += m * (m - 1) / 2;
        boxes_seen += m;
        if (end - chunk_begin_.back() >= kChunkEntries && end < keys_.size()) chunk_begin_.push_back(end);
        cell = end;
    }
    chunk_begin_.push_back(keys_.size());
    return pairs <= kPairBudgetPerBox * std::max<std::size_t>(boxes_seen, 1);
}

bool BoxGrid::build(const std::vector<Box>& boxes, const std::function<void()>& checkpoint) {
    if (boxes.size() >= std::numeric_limits<std::uint32_t>::max() || !choose_cell(boxes)) return false;
    checkpoint();
    {
        std::vector<std::size_t>& offset = offset_;
        offset.assign(boxes.size() + 1, 0);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, boxes.size(), 1 << 14), [&](const tbb::blocked_range<std::size_t>& r) {
            for (std::size_t i = r.begin(); i != r.end(); ++i) offset[i + 1] = cells_of(boxes[i]);
        });
        if (std::any_of(offset.begin(), offset.end(), [](std::size_t n) { return n > kMaxCellsPerBox; })) return false;
        std::partial_sum(offset.begin(), offset.end(), offset.begin());
        if (offset.back() > kMaxEntriesPerBox * boxes.size()) return false;
        checkpoint();
        register_boxes(boxes, offset);
    }
    checkpoint();
    sort_entries(checkpoint);
    checkpoint();
    return split_chunks();
}

}  // namespace pqdc::detail
