// Seeded 3D simplex noise with certified value and gradient bounds: the
// figure3 field's fractal noise.
//
// Simplex noise: Gustavson's formulation of Perlin's 3D simplex noise, with
// two deliberate differences from his reference code:
//  * kernel (r^2 - |d|^2)^4 with r^2 = 0.5 instead of 0.6. Every point of a
//    simplex is at squared distance >= 0.5 from every lattice vertex that is
//    not one of its corners (equality on the simplex faces; checked in the
//    tests), so with 0.5 only the four corners contribute and the noise is
//    C^1. With 0.6 it has small jumps at simplex faces, which would
//    make any Lipschitz bound false and break the sampler's culling.
//  * a seeded permutation (own PRNG, so the same seed gives the same noise on
//    every platform and standard library) and a seeded per-octave offset.
//
// Bounds used by figure3 (see kNoiseValueBound / kNoiseGradientBound). With
// d_i = x - v_i (v_i the unskewed simplex corners), s_i = |d_i|^2,
// t_i = r^2 - s_i and |g_i| = sqrt(2) (cube-edge gradients):
//   N(x)      = S * sum_i t_i^4 (g_i . d_i)                 (t_i > 0 terms)
//   grad N(x) = S * sum_i [ t_i^4 g_i - 8 t_i^3 (g_i . d_i) d_i ]
// Splitting g_i into parts along and across d_i, the i-th gradient term has
// length <= |g_i| * phi(s_i), phi(s) = max(t^4, |t^3 (t - 8 s)|), which is
// t^4 for s <= r^2/5 and t^3 (9 s - r^2) above. Likewise the value term is
// <= |g_i| * t_i^4 sqrt(s_i). Hence
//   |N|      <= S sqrt(2) * sup_x sum_i t_i^4 sqrt(s_i)
//   |grad N| <= S sqrt(2) * sup_x sum_i phi(s_i)
// Both suprema run over one simplex (all simplices are congruent up to a
// coordinate permutation). They are bounded rigorously by evaluating the sum
// on a grid over the simplex's bounding box and adding its Lipschitz constant
// (4 * 0.2429 for phi, 4 * 0.0625 = 4 r^8 for the value kernel, from d/dx of
// one term) times the grid's covering radius; with a 0.0025 grid:
//   sup sum phi            <= 0.072479 + 0.002103 = 0.074583  -> 0.0746
//   sup sum t^4 sqrt(s)    <= 0.009289 + 0.000541 = 0.009830  -> 0.00984
// (tests/test_procedural.cpp re-proves both by branch and bound.) S is chosen
// so that |N| <= 1 holds with certainty; the gradient bound then is
// S * sqrt(2) * 0.0746 ~= 7.58 per lattice unit. Sampling finds |N| up to
// 0.93 and |grad N| up to 6.5, so both bounds are within 15% of the truth.
#pragma once

#include <openvdb/openvdb.h>

#include <array>
#include <cmath>
#include <cstdint>

namespace pqdc::procedural_detail {

using openvdb::Vec3d;

// ------------------------------------------------------------ PRNG

/// SplitMix64 (Steele, Lea, Flood 2014): tiny, well mixed, fully specified,
/// so the noise for a seed is identical on every platform.
class SplitMix64 {
public:
    explicit SplitMix64(std::uint64_t seed) : state_(seed) {}
    std::uint64_t next()
    {
        std::uint64_t z = (state_ += 0x9E3779B97F4A7C15ull);
        z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
        z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
        return z ^ (z >> 31);
    }
    /// Uniform in [0, n) without modulo bias (rejection).
    std::uint32_t below(std::uint32_t n)
    {
        const std::uint64_t limit = std::numeric_limits<std::uint64_t>::max() -
                                    std::numeric_limits<std::uint64_t>::max() % n;
        std::uint64_t r;
        do {
            r = next();
        } while (r >= limit);
        return static_cast<std::uint32_t>(r % n);
    }
    /// Uniform in [0, 1) with 53 random bits.
    double unit() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }

private:
    std::uint64_t state_;
};

// ------------------------------------------------------------ simplex noise

constexpr double kF3 = 1.0 / 3.0;  // skew factor (sqrt(4)-1)/3
constexpr double kG3 = 1.0 / 6.0;  // unskew factor (1-1/sqrt(4))/3
constexpr double kKernelR2 = 0.5;  // see file comment: 0.5 keeps the noise C^1
constexpr double kSqrt2 = 1.4142135623730951;
constexpr double kSupValueKernel = 0.00984;    // sup_x sum_i t_i^4 sqrt(s_i), certified
constexpr double kSupGradientKernel = 0.0746;  // sup_x sum_i phi(s_i), certified
/// Output scale: makes kSqrt2 * kSupValueKernel * kNoiseScale == 1.
constexpr double kNoiseScale = 1.0 / (kSqrt2 * kSupValueKernel);
/// |simplex(x)| <= kNoiseValueBound for every x.
constexpr double kNoiseValueBound = 1.0;
/// |grad simplex(x)| <= kNoiseGradientBound (per lattice unit) for every x.
constexpr double kNoiseGradientBound = kNoiseScale * kSqrt2 * kSupGradientKernel;
/// Beyond this many lattice units a double has no fractional bits left to
/// speak of; the noise is defined as 0 there instead of overflowing the index.
constexpr double kMaxLatticeCoordinate = 1e15;

constexpr double kGradients[12][3] = {
    {1, 1, 0}, {-1, 1, 0}, {1, -1, 0}, {-1, -1, 0}, {1, 0, 1}, {-1, 0, 1},
    {1, 0, -1}, {-1, 0, -1}, {0, 1, 1}, {0, -1, 1}, {0, 1, -1}, {0, -1, -1},
};

class SimplexNoise {
public:
    explicit SimplexNoise(SplitMix64& rng)
    {
        std::array<std::uint8_t, 256> p{};
        for (int i = 0; i < 256; ++i) p[i] = static_cast<std::uint8_t>(i);
        for (std::uint32_t i = 255; i > 0; --i) std::swap(p[i], p[rng.below(i + 1)]);
        for (int i = 0; i < 512; ++i) {
            perm_[i] = p[i & 255];
            gradient_index_[i] = static_cast<std::uint8_t>(p[i & 255] % 12);
        }
    }

    /// Noise value in [-1, 1]; when `gradient` is non-null also its exact gradient.
    double evaluate(const Vec3d& x, Vec3d* gradient) const
    {
        const double skew = (x[0] + x[1] + x[2]) * kF3;
        const double sx = x[0] + skew, sy = x[1] + skew, sz = x[2] + skew;
        if (!(std::fabs(sx) < kMaxLatticeCoordinate && std::fabs(sy) < kMaxLatticeCoordinate &&
              std::fabs(sz) < kMaxLatticeCoordinate)) {
            if (gradient) *gradient = Vec3d(0.0);
            return std::isnan(sx + sy + sz) ? std::numeric_limits<double>::quiet_NaN() : 0.0;
        }
        const double fi = floor_in_range(sx), fj = floor_in_range(sy), fk = floor_in_range(sz);
        const double unskew = (fi + fj + fk) * kG3;
        const Vec3d d0(x[0] - (fi - unskew), x[1] - (fj - unskew), x[2] - (fk - unskew));

        // The simplex holding x: walk from the cell's low corner along the
        // axes in decreasing order of the in-cell coordinates (branch-free;
        // ties may go either way since the noise is continuous across faces).
        const int x_ge_y = d0[0] >= d0[1], x_ge_z = d0[0] >= d0[2], y_ge_z = d0[1] >= d0[2];
        const int i1 = x_ge_y & x_ge_z, j1 = (1 - x_ge_y) & y_ge_z, k1 = (1 - x_ge_z) & (1 - y_ge_z);
        const int i2 = x_ge_y | x_ge_z, j2 = (1 - x_ge_y) | y_ge_z, k2 = (1 - x_ge_z) | (1 - y_ge_z);

        // Two's complement wrap of the (in range) lattice index to [0, 256).
        const unsigned ii = static_cast<unsigned>(static_cast<std::uint64_t>(static_cast<std::int64_t>(fi)) & 255u);
        const unsigned jj = static_cast<unsigned>(static_cast<std::uint64_t>(static_cast<std::int64_t>(fj)) & 255u);
        const unsigned kk = static_cast<unsigned>(static_cast<std::uint64_t>(static_cast<std::int64_t>(fk)) & 255u);

        double sum = 0.0;
        Vec3d grad(0.0);
        auto corner = [&](int oi, int oj, int ok, double shift) __attribute__((always_inline)) {
            const Vec3d d(d0[0] - oi + shift, d0[1] - oj + shift, d0[2] - ok + shift);
            // Clamping instead of skipping keeps this branch-free; a zero
            // kernel adds exactly zero.
            const double t = std::max(kKernelR2 - d.lengthSqr(), 0.0);
            const double* g = kGradients[gradient_index_[ii + oi + perm_[jj + oj + perm_[kk + ok]]]];
            const double gd = g[0] * d[0] + g[1] * d[1] + g[2] * d[2];
            const double t2 = t * t;
            const double t4 = t2 * t2;
            sum += t4 * gd;
            if (gradient) {
                const double radial = -8.0 * t2 * t * gd;
                grad += Vec3d(t4 * g[0] + radial * d[0], t4 * g[1] + radial * d[1], t4 * g[2] + radial * d[2]);
            }
        };
        corner(0, 0, 0, 0.0);
        corner(i1, j1, k1, kG3);
        corner(i2, j2, k2, 2.0 * kG3);
        corner(1, 1, 1, 3.0 * kG3);
        if (gradient) *gradient = grad * kNoiseScale;
        return sum * kNoiseScale;
    }

private:
    /// floor() for |x| < kMaxLatticeCoordinate, without a libm call on
    /// targets lacking a rounding instruction (it is on the hot path).
    static double floor_in_range(double x)
    {
        const double t = static_cast<double>(static_cast<std::int64_t>(x));
        return t > x ? t - 1.0 : t;
    }

    std::array<std::uint8_t, 512> perm_{};
    std::array<std::uint8_t, 512> gradient_index_{};
};


}  // namespace pqdc::procedural_detail
