// Stage "fetch": dense value blocks copied out of the sparse tree, with the
// inside/active/NaN bit rows that classification works on (both extractors).
#pragma once

#include "lattice/interior.hpp"

#include <openvdb/openvdb.h>

#include <cassert>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#include <cmath>
#include <cstdint>
#include <type_traits>
#include <vector>

namespace pqdc::detail {

/// Values of a tree over an axis-aligned box of lattice points, signed so that
/// inside is negative (value - isovalue, or isovalue - value for densities),
/// with each point's active state. Inactive points keep their stored value
/// (background or tile value), which is meaningful: outside a level set's
/// band it has the right sign, in a fog volume it is empty space. NaN stays
/// NaN so cells touching it can be left out.
struct DenseBlock {
    openvdb::Coord min;  ///< index-space lattice point stored at local (0,0,0)
    int dim = 0;         ///< edge length of the cube of points
    std::vector<double> value;
    /// Bit rows along z (bit z of row [x][y]): point inside, active, NaN.
    /// Classification works on 16 points at a time from these.
    static constexpr int kMaxDim = 16;
    std::uint16_t inside_row[kMaxDim][kMaxDim];
    std::uint16_t active_row[kMaxDim][kMaxDim];
    std::uint16_t nan_row[kMaxDim][kMaxDim];
    /// No NaN or infinity anywhere in the block: gradients need no checks.
    bool all_finite = false;

    int index(int x, int y, int z) const { return (x * dim + y) * dim + z; }
    double at(int x, int y, int z) const { return value[index(x, y, z)]; }
    bool on(int x, int y, int z) const { return (active_row[x][y] >> z) & 1; }
};

static_assert(openvdb::FloatTree::LeafNodeType::LOG2DIM == 3, "fetch_block assumes 8^3 leaves");

/// Fills `block` with the points [min, min + dim) of the tree behind
/// `accessor`. Copies whole leaf buffers where leaves exist and fills tile or
/// background regions in one go, so a block costs ~27 probes, not dim^3.
/// Two phases: tight conversion loops per leaf row segment, then the inside
/// and NaN bit rows from the stored values, two at a time.
template <class AccessorT>
void fetch_block(const AccessorT& accessor, const openvdb::Coord& min, int dim, const Signing& signing,
                 DenseBlock& block) {
    using LeafT = typename AccessorT::TreeType::LeafNodeType;
    constexpr int L = int(LeafT::DIM);
    block.min = min;
    block.dim = dim;
    const std::size_t n = std::size_t(dim) * dim * dim;
    block.value.resize(n);
    assert(dim <= DenseBlock::kMaxDim);
    for (int x = 0; x < dim; ++x)
        for (int y = 0; y < dim; ++y) block.active_row[x][y] = 0;
    const double sign = signing.sign, iso = signing.isovalue;
    double* const value = block.value.data();
    const openvdb::Coord max = min + openvdb::Coord(dim - 1);
    const openvdb::Coord first = min & ~(L - 1), last = max & ~(L - 1);
    for (int lx = first.x(); lx <= last.x(); lx += L)
        for (int ly = first.y(); ly <= last.y(); ly += L)
            for (int lz = first.z(); lz <= last.z(); lz += L) {
                const openvdb::Coord origin(lx, ly, lz);
                const openvdb::Coord lo = openvdb::Coord::maxComponent(origin, min);
                const openvdb::Coord hi = openvdb::Coord::minComponent(origin + openvdb::Coord(L - 1), max);
                const int nz = hi.z() - lo.z() + 1, bz = lo.z() - min.z();
                const unsigned run = ((1u << nz) - 1) << bz;
                if (const LeafT* leaf = accessor.probeConstLeaf(origin)) {
                    const auto* data = leaf->buffer().data();
                    const auto& mask = leaf->getValueMask();
                    for (int x = lo.x(); x <= hi.x(); ++x) {
                        const std::uint64_t word = mask.template getWord<std::uint64_t>(x & (L - 1));
                        for (int y = lo.y(); y <= hi.y(); ++y) {
                            const int base = ((x & (L - 1)) << 6) | ((y & (L - 1)) << 3);
                            const auto* src = data + base + (lo.z() & (L - 1));
                            const int bx = x - min.x(), by = y - min.y();
                            double* dst = value + block.index(bx, by, bz);
                            if (nz == L)  // the common full row: constant trip count
                                for (int k = 0; k < L; ++k) dst[k] = sign * (double(src[k]) - iso);
                            else
                                for (int k = 0; k < nz; ++k) dst[k] = sign * (double(src[k]) - iso);
                            const unsigned on = unsigned(word >> (base & 63) >> (lo.z() & (L - 1))) & ((1u << nz) - 1);
                            block.active_row[bx][by] |= std::uint16_t(on << bz);
                        }
                    }
                } else {
                    const double v = signing(double(accessor.getValue(lo)));
                    const bool on = accessor.isValueOn(lo);
                    for (int x = lo.x(); x <= hi.x(); ++x)
                        for (int y = lo.y(); y <= hi.y(); ++y) {
                            const int bx = x - min.x(), by = y - min.y();
                            double* dst = value + block.index(bx, by, bz);
                            for (int k = 0; k < nz; ++k) dst[k] = v;
                            if (on) block.active_row[bx][by] |= std::uint16_t(run);
                        }
                }
            }
    unsigned non_finite = 0;
    for (int x = 0; x < dim; ++x)
        for (int y = 0; y < dim; ++y) {
            const double* v = value + block.index(x, y, 0);
            unsigned in = 0, nan = 0;
            int z = 0;
#if defined(__SSE2__)
            const __m128d zero = _mm_setzero_pd();
            __m128d bad = zero;
            for (; z + 2 <= dim; z += 2) {
                const __m128d p = _mm_loadu_pd(v + z);
                in |= unsigned(_mm_movemask_pd(_mm_cmplt_pd(p, zero))) << z;
                nan |= unsigned(_mm_movemask_pd(_mm_cmpunord_pd(p, p))) << z;
                const __m128d d = _mm_sub_pd(p, p);  // NaN for NaN and +-inf
                bad = _mm_or_pd(bad, _mm_cmpunord_pd(d, d));
            }
            non_finite |= unsigned(_mm_movemask_pd(bad));
#endif
            for (; z < dim; ++z) {
                in |= unsigned(v[z] < 0.0) << z;
                nan |= unsigned(v[z] != v[z]) << z;
                non_finite |= unsigned(!std::isfinite(v[z]));
            }
            block.inside_row[x][y] = std::uint16_t(in);
            block.nan_row[x][y] = std::uint16_t(nan);
        }
    block.all_finite = non_finite == 0;
}

/// Fills `block` with the points [from.min + offset, + dim) of `from`, which
/// must hold them: what fetch_block would fill for that box, without reading
/// the tree again. The cell stages need a leaf's points twice, with one
/// point of margin (classification) and with the gradient stencil's wider
/// one; copying the first out of the second costs a tenth of a second fetch.
inline void copy_sub_block(const DenseBlock& from, int offset, int dim, DenseBlock& block) {
    assert(offset >= 0 && offset + dim <= from.dim);
    block.min = from.min + openvdb::Coord(offset);
    block.dim = dim;
    block.value.resize(std::size_t(dim) * dim * dim);
    const std::uint16_t mask = std::uint16_t((1u << dim) - 1);
    bool finite = true;
    for (int x = 0; x < dim; ++x)
        for (int y = 0; y < dim; ++y) {
            const double* src = from.value.data() + from.index(x + offset, y + offset, offset);
            double* dst = block.value.data() + block.index(x, y, 0);
            for (int z = 0; z < dim; ++z) {
                dst[z] = src[z];
                finite &= std::isfinite(src[z]);
            }
            block.inside_row[x][y] = std::uint16_t(from.inside_row[x + offset][y + offset] >> offset) & mask;
            block.active_row[x][y] = std::uint16_t(from.active_row[x + offset][y + offset] >> offset) & mask;
            block.nan_row[x][y] = std::uint16_t(from.nan_row[x + offset][y + offset] >> offset) & mask;
        }
    block.all_finite = from.all_finite || finite;
}

/// False when every lattice point of [origin, origin + 8]^3 (the corners of
/// the leaf's cells) lies on one side and none is NaN: no cell of the leaf is
/// crossed, so its 11^3 value block need not be fetched. Reads only the
/// source values, without converting or storing them.
template <class AccessorT>
inline bool corners_may_cross(const AccessorT& acc, const openvdb::Coord& origin, const Signing& signing) {
    using LeafT = typename AccessorT::TreeType::LeafNodeType;
    constexpr int L = int(LeafT::DIM);
    const double iso = signing.isovalue;
    const bool below = signing.sign > 0;  // inside: raw < iso (else raw > iso)
    unsigned any_in = 0, any_out = 0, nan = 0;
    const float iso_f = float(iso);
    [[maybe_unused]] const bool iso_is_float = double(iso_f) == iso;
    for (int n = 0; n < 8; ++n) {
        const openvdb::Coord o = origin + openvdb::Coord(n & 1 ? L : 0, n & 2 ? L : 0, n & 4 ? L : 0);
        const int xe = n & 1 ? 1 : L, ye = n & 2 ? 1 : L, ze = n & 4 ? 1 : L;
        if (const LeafT* leaf = acc.probeConstLeaf(o)) {
            const auto* d = leaf->buffer().data();
            // Flags accumulated without early exits, so the loops vectorize.
            auto scan = [&](const auto* v, int count) {
#if defined(__SSE2__)
                using ValueT = std::decay_t<decltype(*v)>;
                if constexpr (std::is_same_v<ValueT, float>) {
                    if (iso_is_float) {  // float compares are exact: 4 values per instruction
                        const __m128 t = _mm_set1_ps(iso_f);
                        __m128 in4 = _mm_setzero_ps(), out4 = in4, nan4 = in4;
                        int k = 0;
                        for (; k + 4 <= count; k += 4) {
                            const __m128 p = _mm_loadu_ps(v + k);
                            in4 = _mm_or_ps(in4, below ? _mm_cmplt_ps(p, t) : _mm_cmpgt_ps(p, t));
                            out4 = _mm_or_ps(out4, below ? _mm_cmpnlt_ps(p, t) : _mm_cmpngt_ps(p, t));
                            nan4 = _mm_or_ps(nan4, _mm_cmpunord_ps(p, p));
                        }
                        any_in |= unsigned(_mm_movemask_ps(in4) != 0);
                        any_out |= unsigned(_mm_movemask_ps(out4) != 0);  // includes NaN: decided by nan anyway
                        nan |= unsigned(_mm_movemask_ps(nan4) != 0);
                        for (; k < count; ++k) {
                            const float r = v[k];
                            any_in |= below ? unsigned(r < iso_f) : unsigned(r > iso_f);
                            any_out |= below ? unsigned(!(r < iso_f)) : unsigned(!(r > iso_f));
                            nan |= unsigned(r != r);
                        }
                        return;
                    }
                }
#endif
                unsigned lt = 0, gt = 0, eq = 0, un = 0;
                for (int k = 0; k < count; ++k) {
                    const double r = double(v[k]);
                    lt |= unsigned(r < iso);
                    gt |= unsigned(r > iso);
                    eq |= unsigned(r == iso);
                    un |= unsigned(r != r);
                }
                any_in |= below ? lt : gt;
                any_out |= below ? (gt | eq) : (lt | eq);
                nan |= un;
            };
            if (n == 0) {
                scan(d, int(LeafT::SIZE));  // the whole leaf, contiguous
            } else {
                for (int x = 0; x < xe; ++x)
                    for (int y = 0; y < ye; ++y) scan(d + ((x << 6) | (y << 3)), ze);
            }
        } else {
            const double r = double(acc.getValue(o));
            any_in |= below ? unsigned(r < iso) : unsigned(r > iso);
            any_out |= below ? unsigned(r >= iso) : unsigned(r <= iso);
            nan |= unsigned(r != r);
        }
        if ((any_in && any_out) || nan) return true;
    }
    return false;
}

}  // namespace pqdc::detail
