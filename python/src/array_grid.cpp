#include "array_grid.hpp"

#include <pqdc/exceptions.hpp>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <sstream>
#include <type_traits>
#include <vector>

namespace pqdc::python {
namespace {

constexpr int kDim = 8;  // OpenVDB leaf edge (FloatTree and DoubleTree)

float half_to_float(std::uint16_t h) {
    const std::uint32_t sign = std::uint32_t(h & 0x8000u) << 16;
    const int exponent = (h >> 10) & 0x1f;
    std::uint32_t mantissa = h & 0x3ffu, bits;
    if (exponent == 0x1f) {
        bits = sign | 0x7f800000u | (mantissa << 13);  // inf / NaN
    } else if (exponent != 0) {
        bits = sign | (std::uint32_t(exponent + 112) << 23) | (mantissa << 13);
    } else if (mantissa == 0) {
        bits = sign;
    } else {  // subnormal: normalize
        int e = -1;
        do { ++e; mantissa <<= 1; } while (!(mantissa & 0x400u));
        bits = sign | (std::uint32_t(112 - e) << 23) | ((mantissa & 0x3ffu) << 13);
    }
    float f;
    std::memcpy(&f, &bits, sizeof f);
    return f;
}

/// numpy float16, converted on load.
struct Half {
    std::uint16_t bits;
};

template <class V, class T>
V convert(T t) {
    if constexpr (std::is_same_v<T, Half>) return V(half_to_float(t.bits));
    else return V(t);
}

/// Finite values of a region, as stored in the grid (value type V).
struct Range {
    double lo = std::numeric_limits<double>::infinity();
    double hi = -std::numeric_limits<double>::infinity();
    bool empty() const { return lo > hi; }
    void add(const Range& r) {
        lo = std::min(lo, r.lo);
        hi = std::max(hi, r.hi);
    }
};

using Box = std::array<std::int64_t, 6>;  // x0, x1, y0, y1, z0, z1 (half-open)

template <class T, class V>
class Converter {
public:
    Converter(const ArrayView& a, const ConversionOptions& o)
        : a_(a), o_(o), sign_(o.interior == Interior::above_isovalue ? -1.0 : 1.0) {
        for (int i = 0; i < 3; ++i) nb_[i] = (a.shape[i] + kDim - 1) / kDim;
    }

    std::int64_t blocks() const { return nb_[0] * nb_[1] * nb_[2]; }
    std::int64_t block_index(std::int64_t bx, std::int64_t by, std::int64_t bz) const {
        return (bx * nb_[1] + by) * nb_[2] + bz;
    }

    /// Same predicate as the extractor's sign test (value - isovalue, signed).
    bool inside(double v) const { return sign_ * (v - o_.isovalue) < 0; }
    bool straddles(const Range& r) const { return !r.empty() && inside(r.lo) != inside(r.hi); }

    V value(std::int64_t x, std::int64_t y, std::int64_t z) const {
        return load(a_.data + x * a_.strides[0] + y * a_.strides[1] + z * a_.strides[2]);
    }

    /// Values of the region (comparisons skip NaN; infinities count, which
    /// only makes more blocks dense, never fewer).
    Range range(const Box& b) const {
        V lo = std::numeric_limits<V>::infinity(), hi = -lo;
        const std::int64_t sz = a_.strides[2];
        for (std::int64_t x = b[0]; x < b[1]; ++x)
            for (std::int64_t y = b[2]; y < b[3]; ++y) {
                const char* row = a_.data + x * a_.strides[0] + y * a_.strides[1];
                for (std::int64_t z = b[4]; z < b[5]; ++z) {
                    const V v = load(row + z * sz);
                    lo = v < lo ? v : lo;
                    hi = v > hi ? v : hi;
                }
            }
        Range r;
        if (lo <= hi) {
            r.lo = double(lo);
            r.hi = double(hi);
        }
        return r;
    }

    static V load(const char* p) {
        T t;  // memcpy: numpy arrays need not be aligned
        std::memcpy(&t, p, sizeof t);
        return convert<V>(t);
    }

    Box block_box(std::int64_t bx, std::int64_t by, std::int64_t bz, std::int64_t apron) const {
        const std::int64_t b[3] = {bx, by, bz};
        Box box;
        for (int i = 0; i < 3; ++i) {
            box[2 * i] = std::max<std::int64_t>(0, b[i] * kDim - apron);
            box[2 * i + 1] = std::min(a_.shape[i], (b[i] + 1) * kDim + apron);
        }
        return box;
    }

    /// Runs body(bx, by, bz) over every block, one slab of x blocks at a time
    /// with a progress report (cancellation point) after each slab.
    template <class Body>
    void for_blocks(double from, double to, const Body& body) const {
        for (std::int64_t bx = 0; bx < nb_[0]; ++bx) {
            tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, nb_[1] * nb_[2]),
                              [&](const tbb::blocked_range<std::int64_t>& r) {
                                  for (std::int64_t i = r.begin(); i != r.end(); ++i)
                                      body(bx, i / nb_[2], i % nb_[2]);
                              });
            if (o_.progress && !o_.progress(from + (to - from) * double(bx + 1) / double(nb_[0])))
                throw cancelled_error("array conversion cancelled by the caller");
        }
    }

    /// Whether the block needs its voxels, and (else) the value of its tile.
    enum class Kind : std::uint8_t { nothing, tile, dense };

    /// Every block's range, streaming whole z rows (the array's usual
    /// contiguous axis) through one row of block accumulators per (x, y) slab.
    void core_ranges(std::vector<Range>& core) const {
        core.assign(std::size_t(blocks()), Range{});
        for (std::int64_t bx = 0; bx < nb_[0]; ++bx) {
            tbb::parallel_for(std::int64_t(0), nb_[1], [&](std::int64_t by) {
                const V inf = std::numeric_limits<V>::infinity();
                std::vector<V> lo(std::size_t(nb_[2]), inf), hi(std::size_t(nb_[2]), -inf);
                const Box b = block_box(bx, by, 0, 0);
                for (std::int64_t x = b[0]; x < b[1]; ++x)
                    for (std::int64_t y = b[2]; y < b[3]; ++y) accumulate_row(x, y, lo.data(), hi.data());
                for (std::int64_t bz = 0; bz < nb_[2]; ++bz)
                    if (lo[std::size_t(bz)] <= hi[std::size_t(bz)])
                        core[std::size_t(block_index(bx, by, bz))] = {double(lo[std::size_t(bz)]), double(hi[std::size_t(bz)])};
            });
            if (o_.progress && !o_.progress(0.3 * double(bx + 1) / double(nb_[0])))
                throw cancelled_error("array conversion cancelled by the caller");
        }
    }

    void accumulate_row(std::int64_t x, std::int64_t y, V* lo, V* hi) const {
        const char* row = a_.data + x * a_.strides[0] + y * a_.strides[1];
        const std::int64_t sz = a_.strides[2], n = a_.shape[2];
        for (std::int64_t z0 = 0, bz = 0; z0 < n; z0 += kDim, ++bz) {
            const std::int64_t z1 = std::min(n, z0 + kDim);
            V l = lo[bz], h = hi[bz];
            for (std::int64_t z = z0; z < z1; ++z) {
                const V v = load(row + z * sz);
                l = v < l ? v : l;  // NaN compares false: skipped
                h = v > h ? v : h;
            }
            lo[bz] = l;
            hi[bz] = h;
        }
    }

    std::vector<Kind> classify(std::vector<Range>& core) const {
        core_ranges(core);
        std::vector<Kind> kind(core.size(), Kind::nothing);
        tbb::parallel_for(std::int64_t(0), blocks(), [&](std::int64_t i) {
            const std::int64_t x = i / (nb_[1] * nb_[2]), y = (i / nb_[2]) % nb_[1], z = i % nb_[2];
            kind[std::size_t(i)] = classify_block(core, x, y, z);
        });
        return kind;
    }

    Kind classify_block(const std::vector<Range>& core, std::int64_t x, std::int64_t y, std::int64_t z) const {
        const Range& own = core[std::size_t(block_index(x, y, z))];
        if (!o_.sparse) return Kind::dense;
        if (straddles(own)) return Kind::dense;
        Range near = own;  // the 26 neighbours' cores cover the apron (apron < kDim)
        for (std::int64_t dx = -1; dx <= 1; ++dx)
            for (std::int64_t dy = -1; dy <= 1; ++dy)
                for (std::int64_t dz = -1; dz <= 1; ++dz) {
                    const std::int64_t nx = x + dx, ny = y + dy, nz = z + dz;
                    if (nx < 0 || ny < 0 || nz < 0 || nx >= nb_[0] || ny >= nb_[1] || nz >= nb_[2]) continue;
                    near.add(core[std::size_t(block_index(nx, ny, nz))]);
                }
        if (straddles(near) && apron_straddles(core, x, y, z)) return Kind::dense;
        return own.empty() ? Kind::nothing : Kind::tile;
    }

    /// Whether the block plus its apron straddles, reading only the apron
    /// parts of neighbours that can hold the other side (a neighbour whose
    /// whole core lies on the block's side adds nothing).
    bool apron_straddles(const std::vector<Range>& core, std::int64_t x, std::int64_t y, std::int64_t z) const {
        const Range& own = core[std::size_t(block_index(x, y, z))];
        Range seen = own;
        const std::int64_t b[3] = {x, y, z};
        for (int n = 0; n < 27; ++n) {
            const std::int64_t d[3] = {n % 3 - 1, (n / 3) % 3 - 1, n / 9 - 1};
            if (d[0] == 0 && d[1] == 0 && d[2] == 0) continue;
            Box part;
            bool inside_array = true;
            for (int i = 0; i < 3; ++i) {
                const std::int64_t lo = b[i] * kDim;
                part[2 * i] = std::max<std::int64_t>(0, d[i] < 0 ? lo - o_.apron : d[i] == 0 ? lo : lo + kDim);
                part[2 * i + 1] = std::min(a_.shape[i], d[i] < 0 ? lo : d[i] == 0 ? lo + kDim : lo + kDim + o_.apron);
                inside_array &= part[2 * i] < part[2 * i + 1];
            }
            if (!inside_array) continue;
            Range both = own;
            both.add(core[std::size_t(block_index(x + d[0], y + d[1], z + d[2]))]);
            if (!own.empty() && !straddles(both)) continue;
            seen.add(range(part));
            if (straddles(seen)) return true;
        }
        return false;
    }

    template <class LeafT>
    std::unique_ptr<LeafT> make_leaf(std::int64_t bx, std::int64_t by, std::int64_t bz) const {
        const V nan = std::numeric_limits<V>::quiet_NaN();
        auto leaf = std::make_unique<LeafT>(openvdb::Coord(int(bx * kDim), int(by * kDim), int(bz * kDim)), nan, false);
        V* data = leaf->buffer().data();
        const Box b = block_box(bx, by, bz, 0);
        for (std::int64_t x = b[0]; x < b[1]; ++x)
            for (std::int64_t y = b[2]; y < b[3]; ++y)
                for (std::int64_t z = b[4]; z < b[5]; ++z) {
                    const openvdb::Index n = openvdb::Index(((x & 7) << 6) | ((y & 7) << 3) | (z & 7));
                    data[n] = value(x, y, z);
                    leaf->setActiveState(n, true);
                }
        return leaf;
    }

    typename openvdb::Grid<typename openvdb::tree::Tree4<V, 5, 4, 3>::Type>::Ptr build(ConversionStats& st) const {
        using GridT = openvdb::Grid<typename openvdb::tree::Tree4<V, 5, 4, 3>::Type>;
        using LeafT = typename GridT::TreeType::LeafNodeType;
        std::vector<Range> core;
        const std::vector<Kind> kind = classify(core);
        st.blocks = std::uint64_t(blocks());
        for (Kind k : kind) {
            st.dense_leaves += k == Kind::dense;
            st.tiles += k == Kind::tile;
        }
        st.grid_bytes = st.dense_leaves * (sizeof(LeafT) + LeafT::SIZE * sizeof(V));
        if (o_.memory_limit_bytes && st.grid_bytes > o_.memory_limit_bytes) {
            std::ostringstream s;
            s.precision(3);
            s << "converting the array needs about " << double(st.grid_bytes) / 1048576.0 << " MiB for "
              << st.dense_leaves << " dense 8^3 blocks, more than memory_limit (" << o_.memory_limit_bytes
              << " bytes); raise memory_limit or pass a smaller array";
            throw resource_error(s.str());
        }
        std::vector<std::unique_ptr<LeafT>> leaves(kind.size());
        for_blocks(0.3, 1.0, [&](std::int64_t x, std::int64_t y, std::int64_t z) {
            const std::size_t i = std::size_t(block_index(x, y, z));
            if (kind[i] == Kind::dense) leaves[i] = make_leaf<LeafT>(x, y, z);
        });
        auto grid = GridT::create(std::numeric_limits<V>::quiet_NaN());
        grid->setName("array");
        auto& tree = grid->tree();
        for (std::int64_t i = 0; i < blocks(); ++i) {
            const std::int64_t x = i / (nb_[1] * nb_[2]), y = (i / nb_[2]) % nb_[1], z = i % nb_[2];
            const openvdb::Coord origin(int(x * kDim), int(y * kDim), int(z * kDim));
            if (kind[std::size_t(i)] == Kind::dense) {
                tree.addLeaf(leaves[std::size_t(i)].release());
            } else if (kind[std::size_t(i)] == Kind::tile) {
                // Level 1 holds 8^3 tiles; the range's low end is on the block's side.
                tree.addTile(1, origin, V(core[std::size_t(i)].lo), false);
            }
        }
        return grid;
    }

private:
    const ArrayView& a_;
    const ConversionOptions& o_;
    const double sign_;
    std::int64_t nb_[3];
};

template <class T>
openvdb::GridBase::Ptr build(const ArrayView& a, const ConversionOptions& o, ConversionStats& st) {
    // float holds 8- and 16-bit integers and halves exactly; wider types need double.
    if constexpr (sizeof(T) <= 2 || std::is_same_v<T, float>) return Converter<T, float>(a, o).build(st);
    else return Converter<T, double>(a, o).build(st);
}

}  // namespace

openvdb::GridBase::Ptr array_to_grid(const ArrayView& array, const ConversionOptions& options,
                                     ConversionStats* stats) {
    if (options.interior == Interior::automatic)
        throw option_error("array_to_grid: interior must be resolved to below or above the isovalue");
    if (options.apron < 0 || options.apron >= kDim)
        throw option_error("array_to_grid: apron must be in [0, 8) voxels, got " + std::to_string(options.apron));
    for (int i = 0; i < 3; ++i)
        if (array.shape[i] > (std::int64_t(1) << 30))
            throw input_error("the array has " + std::to_string(array.shape[i]) +
                              " voxels along an axis; OpenVDB coordinates reach 2^30");
    const auto t0 = std::chrono::steady_clock::now();
    ConversionStats st;
    openvdb::GridBase::Ptr grid;
    switch (array.type) {
    case ElementType::f16: grid = build<Half>(array, options, st); break;
    case ElementType::f32: grid = build<float>(array, options, st); break;
    case ElementType::f64: grid = build<double>(array, options, st); break;
    case ElementType::i8: grid = build<std::int8_t>(array, options, st); break;
    case ElementType::i16: grid = build<std::int16_t>(array, options, st); break;
    case ElementType::i32: grid = build<std::int32_t>(array, options, st); break;
    case ElementType::i64: grid = build<std::int64_t>(array, options, st); break;
    case ElementType::u8: grid = build<std::uint8_t>(array, options, st); break;
    case ElementType::u16: grid = build<std::uint16_t>(array, options, st); break;
    case ElementType::u32: grid = build<std::uint32_t>(array, options, st); break;
    case ElementType::u64: grid = build<std::uint64_t>(array, options, st); break;
    case ElementType::b8: grid = build<std::uint8_t>(array, options, st); break;
    }
    st.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (stats) *stats = st;
    return grid;
}

openvdb::MaskGrid::Ptr mask_to_grid(const MaskView& m) {
    std::int64_t nb[3];
    for (int i = 0; i < 3; ++i) nb[i] = (m.shape[i] + kDim - 1) / kDim;
    using LeafT = openvdb::MaskTree::LeafNodeType;
    std::vector<std::unique_ptr<LeafT>> leaves(std::size_t(nb[0] * nb[1] * nb[2]));
    tbb::parallel_for(std::int64_t(0), std::int64_t(leaves.size()), [&](std::int64_t i) {
        const std::int64_t b[3] = {i / (nb[1] * nb[2]), (i / nb[2]) % nb[1], i % nb[2]};
        const openvdb::Coord origin(int(b[0] * kDim), int(b[1] * kDim), int(b[2] * kDim));
        std::unique_ptr<LeafT> leaf;
        for (std::int64_t x = b[0] * kDim; x < std::min(m.shape[0], (b[0] + 1) * kDim); ++x)
            for (std::int64_t y = b[1] * kDim; y < std::min(m.shape[1], (b[1] + 1) * kDim); ++y)
                for (std::int64_t z = b[2] * kDim; z < std::min(m.shape[2], (b[2] + 1) * kDim); ++z) {
                    if (!m.data[x * m.strides[0] + y * m.strides[1] + z * m.strides[2]]) continue;
                    if (!leaf) leaf = std::make_unique<LeafT>(origin, false);
                    leaf->setValueOn(openvdb::Index(((x & 7) << 6) | ((y & 7) << 3) | (z & 7)));
                }
        leaves[std::size_t(i)] = std::move(leaf);
    });
    auto grid = openvdb::MaskGrid::create(false);
    grid->setName("mask");
    for (auto& leaf : leaves)
        if (leaf) grid->tree().addLeaf(leaf.release());
    return grid;
}

}  // namespace pqdc::python
