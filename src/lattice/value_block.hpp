// Dense value blocks and Hermite samplers used by the extractors (internal).
#pragma once

#include "pqdc/vec3.hpp"

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

/// Maps raw grid values to signed values (inside negative).
struct Signing {
    double isovalue = 0.0;
    double sign = 1.0;  ///< +1: inside below isovalue; -1: inside above
    double operator()(double raw) const { return sign * (raw - isovalue); }
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

/// Index-space gradient at a block point by central differences, one-sided
/// where a neighbour is not finite. Inactive neighbours are used: a fog
/// volume's inactive zeros are real data, and a level set's crossings lie
/// well inside its band. The point must be at least one away from the block
/// border.
inline vec3<double> block_gradient(const DenseBlock& b, int x, int y, int z) {
    const int d[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    vec3<double> g;
    const double c = b.at(x, y, z);
    for (int a = 0; a < 3; ++a) {
        const int xp = x + d[a][0], yp = y + d[a][1], zp = z + d[a][2];
        const int xm = x - d[a][0], ym = y - d[a][1], zm = z - d[a][2];
        const bool p = std::isfinite(b.at(xp, yp, zp)), m = std::isfinite(b.at(xm, ym, zm));
        double v;
        if (p && m) v = 0.5 * (b.at(xp, yp, zp) - b.at(xm, ym, zm));
        else if (p) v = b.at(xp, yp, zp) - c;
        else if (m) v = c - b.at(xm, ym, zm);
        else v = 0.0;
        g[a] = v;
    }
    return g;
}

/// A crossing on a lattice edge: position along the edge in [0, 1] and the
/// unit normal (index space), or a zero normal when the gradient there is
/// zero or non-finite.
struct Crossing {
    double t = 0.5;
    vec3<double> normal{0, 0, 0};
};

inline vec3<double> normalized_or_zero(const vec3<double>& g) {
    const double len = length(g);
    if (!(len > 0) || !std::isfinite(len)) return {0, 0, 0};
    const vec3<double> n = g / len;
    return is_finite(n) ? n : vec3<double>{0, 0, 0};
}

/// Root of f on [0, 1] given f(0) = f0 and f(1) = f1 of opposite signs:
/// Illinois-modified regula falsi, superlinear and always bracketed. Stops
/// when the bracket is narrower than t_tol or f vanishes.
template <class F>
double root_on_unit_interval(F&& f, double f0, double f1, double t_tol) {
    double a = 0, b = 1, fa = f0, fb = f1;
    int side = 0;
    for (int it = 0; it < 64 && b - a > t_tol; ++it) {
        double t = (a * fb - b * fa) / (fb - fa);
        if (!(t > a && t < b)) t = 0.5 * (a + b);
        const double ft = f(t);
        if (ft == 0) return t;
        if ((ft < 0) == (fa < 0)) {
            a = t;
            fa = ft;
            if (side == -1) fb *= 0.5;
            side = -1;
        } else {
            b = t;
            fb = ft;
            if (side == 1) fa *= 0.5;
            side = 1;
        }
    }
    return 0.5 * (a + b);
}

/// block_gradient for a block without NaN or infinity (same result, no tests).
inline vec3<double> block_gradient_finite(const DenseBlock& b, int x, int y, int z) {
    const int sx = b.dim * b.dim, sy = b.dim, i = b.index(x, y, z);
    const double* v = b.value.data();
    return {0.5 * (v[i + sx] - v[i - sx]), 0.5 * (v[i + sy] - v[i - sy]), 0.5 * (v[i + 1] - v[i - 1])};
}

/// Where the line through (0, s0) and (1, s1) crosses zero, clamped to
/// [0, 1]; 0.5 when s0 == s1 (no sign change: only rounding got us here).
inline double linear_root(double s0, double s1) {
    const double denom = s0 - s1;
    double t = denom != 0.0 ? s0 / denom : 0.5;
    if (!(t >= 0.0)) t = 0.0;
    if (!(t <= 1.0)) t = 1.0;
    return t;
}

/// Linear interpolation of the sampled values; normal from the gradients at
/// both end points interpolated to the crossing.
inline Crossing linear_crossing(const DenseBlock& b, int x, int y, int z, int axis) {
    const int x1 = x + (axis == 0), y1 = y + (axis == 1), z1 = z + (axis == 2);
    const double s0 = b.at(x, y, z), s1 = b.at(x1, y1, z1);
    Crossing c;
    c.t = linear_root(s0, s1);
    const vec3<double> g0 = b.all_finite ? block_gradient_finite(b, x, y, z) : block_gradient(b, x, y, z);
    const vec3<double> g1 = b.all_finite ? block_gradient_finite(b, x1, y1, z1) : block_gradient(b, x1, y1, z1);
    c.normal = normalized_or_zero(g0 * (1.0 - c.t) + g1 * c.t);
    return c;
}

/// GridNormals::sharp. The block must hold two points of margin around both
/// ends of the edge (ENO stencils reach two points out); without NaN or
/// infinity in it, else this is linear_crossing.
inline Crossing sharp_crossing(const DenseBlock& b, int x, int y, int z, int axis) {
    if (!b.all_finite) return linear_crossing(b, x, y, z, axis);
    const int x1 = x + (axis == 0), y1 = y + (axis == 1), z1 = z + (axis == 2);
    const double s0 = b.at(x, y, z), s1 = b.at(x1, y1, z1);
    Crossing c;
    c.t = linear_root(s0, s1);
    // Per axis: of the two one-sided differences, the one whose next second
    // difference is smaller (ENO), where the central one straddles a kink.
    // bend: sum of |second differences| at the point, 0 on a flat face.
    auto eno_gradient = [&b](int px, int py, int pz, double& bend) {
        vec3<double> g;
        bend = 0.0;
        const int p[3] = {px, py, pz};
        for (int a = 0; a < 3; ++a) {
            auto v = [&](int off) {
                int q[3] = {p[0], p[1], p[2]};
                q[a] += off;
                return b.at(q[0], q[1], q[2]);
            };
            const double vm2 = v(-2), vm1 = v(-1), v0 = v(0), vp1 = v(1), vp2 = v(2);
            const double dp = vp1 - v0, dm = v0 - vm1, c0 = std::abs(vp1 - 2 * v0 + vm1);
            bend += c0;
            if (c0 > 1e-6 * (std::abs(dp) + std::abs(dm))) {
                const double cm = std::abs(v0 - 2 * vm1 + vm2), cp = std::abs(vp2 - 2 * vp1 + v0);
                g[a] = cm < cp ? dm : dp;
            } else {
                g[a] = 0.5 * (dp + dm);
            }
        }
        return g;
    };
    double k0 = 0, k1 = 0;
    const vec3<double> g0 = eno_gradient(x, y, z, k0), g1 = eno_gradient(x1, y1, z1, k1);
    // An end whose stencil is linear sits in one face's region: trust it
    // more. The floor (1e-3 of the gradient size) keeps flat regions at the
    // plain interpolation.
    const double eps = 1e-3 * (length(g0) + length(g1)) + 1e-300;
    const double u0 = 1.0 / (k0 + eps), u1 = 1.0 / (k1 + eps);
    const double a0 = g0[axis], a1 = g1[axis];
    double t0 = a0 != 0.0 ? -s0 / a0 : -1.0, t1 = a1 != 0.0 ? 1.0 - s1 / a1 : -1.0;
    if (!(t0 >= 0.0 && t0 <= 1.0)) t0 = c.t;
    if (!(t1 >= 0.0 && t1 <= 1.0)) t1 = c.t;
    c.t = (u0 * t0 + u1 * t1) / (u0 + u1);
    c.normal = normalized_or_zero(g0 * ((1.0 - c.t) * u0) + g1 * (c.t * u1));
    return c;
}

}  // namespace pqdc::detail
