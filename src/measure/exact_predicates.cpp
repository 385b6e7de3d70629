// The filter and the exact fallback of the orientation predicates. This file
// is compiled with -ffp-contract=off (src/CMakeLists.txt): a fused
// multiply-add would change the rounding the error bounds assume.
#include "measure/exact_predicates.hpp"

#include <boost/multiprecision/cpp_int.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>

namespace pqdc {
namespace detail {

namespace {

using boost::multiprecision::cpp_int;

constexpr double kEpsilon = 0x1.0p-53;  // Shewchuk's epsilon: half an ulp of 1
constexpr double kOrient2dBound = (3.0 + 16.0 * kEpsilon) * kEpsilon;
constexpr double kOrient3dBound = (7.0 + 56.0 * kEpsilon) * kEpsilon;

/// Shewchuk's bounds assume no overflow and no underflow. A difference of
/// magnitude 0 or in [2^-300, 2^300] keeps every product of up to three
/// differences, and every sum or difference of such products (a multiple of
/// the smallest operand's ulp when not zero), within the normal range.
/// Exact zeros are fine: a floating-point difference is 0 only when the
/// operands are equal, and zero products are exact.
bool safe(double d) {
    const double m = std::abs(d);
    return m == 0.0 || (m >= 0x1.0p-300 && m <= 0x1.0p300);
}

/// x = mantissa * 2^exponent exactly, |mantissa| < 2^53.
struct Dyadic {
    std::int64_t mantissa = 0;
    int exponent = 0;
};

Dyadic split(double x) {
    Dyadic d;
    if (x == 0.0) return d;
    int e = 0;
    const double f = std::frexp(x, &e);  // x = f * 2^e, 0.5 <= |f| < 1
    d.mantissa = static_cast<std::int64_t>(std::ldexp(f, 53));
    d.exponent = e - 53;
    return d;
}

/// The values as integers, all scaled by the same power of two (2^-E for E
/// the smallest exponent), so every sign of a polynomial that is
/// homogeneous in them is preserved.
template <std::size_t N>
std::array<cpp_int, N> to_integers(const std::array<double, N>& values) {
    std::array<Dyadic, N> parts;
    int lowest = std::numeric_limits<int>::max();
    for (std::size_t i = 0; i < N; ++i) {
        parts[i] = split(values[i]);
        if (parts[i].mantissa != 0) lowest = std::min(lowest, parts[i].exponent);
    }
    std::array<cpp_int, N> out;
    for (std::size_t i = 0; i < N; ++i) {
        out[i] = parts[i].mantissa;
        if (parts[i].mantissa != 0) out[i] <<= unsigned(parts[i].exponent - lowest);
    }
    return out;
}

}  // namespace

int orient2d_exact(double ax, double ay, double bx, double by, double cx, double cy) {
    const auto v = to_integers<6>({ax, ay, bx, by, cx, cy});
    const cpp_int acx = v[0] - v[4], acy = v[1] - v[5], bcx = v[2] - v[4], bcy = v[3] - v[5];
    const cpp_int det = acx * bcy - acy * bcx;
    return det.sign();
}

int orient3d_exact(const openvdb::Vec3d& a, const openvdb::Vec3d& b, const openvdb::Vec3d& c, const openvdb::Vec3d& d) {
    const auto v = to_integers<12>({a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2], d[0], d[1], d[2]});
    const cpp_int adx = v[0] - v[9], ady = v[1] - v[10], adz = v[2] - v[11];
    const cpp_int bdx = v[3] - v[9], bdy = v[4] - v[10], bdz = v[5] - v[11];
    const cpp_int cdx = v[6] - v[9], cdy = v[7] - v[10], cdz = v[8] - v[11];
    const cpp_int det = adz * (bdx * cdy - cdx * bdy) + bdz * (cdx * ady - adx * cdy) + cdz * (adx * bdy - bdx * ady);
    return det.sign();
}

int orient2d(double ax, double ay, double bx, double by, double cx, double cy) {
    const double acx = ax - cx, bcx = bx - cx, acy = ay - cy, bcy = by - cy;
    if (safe(acx) && safe(bcx) && safe(acy) && safe(bcy)) {
        const double left = acx * bcy, right = acy * bcx;
        const double det = left - right;
        const double bound = kOrient2dBound * (std::abs(left) + std::abs(right));
        if (det > bound) return 1;
        if (-det > bound) return -1;
        if (left == 0.0 && right == 0.0) return 0;  // both products exact zeros
    }
    return orient2d_exact(ax, ay, bx, by, cx, cy);
}

int orient3d(const openvdb::Vec3d& a, const openvdb::Vec3d& b, const openvdb::Vec3d& c, const openvdb::Vec3d& d) {
    const double adx = a[0] - d[0], bdx = b[0] - d[0], cdx = c[0] - d[0];
    const double ady = a[1] - d[1], bdy = b[1] - d[1], cdy = c[1] - d[1];
    const double adz = a[2] - d[2], bdz = b[2] - d[2], cdz = c[2] - d[2];
    if (safe(adx) && safe(bdx) && safe(cdx) && safe(ady) && safe(bdy) && safe(cdy) && safe(adz) && safe(bdz) &&
        safe(cdz)) {
        // Shewchuk's orient3d stage A, in his order of operations.
        const double bdxcdy = bdx * cdy, cdxbdy = cdx * bdy;
        const double cdxady = cdx * ady, adxcdy = adx * cdy;
        const double adxbdy = adx * bdy, bdxady = bdx * ady;
        const double det = adz * (bdxcdy - cdxbdy) + bdz * (cdxady - adxcdy) + cdz * (adxbdy - bdxady);
        const double permanent = (std::abs(bdxcdy) + std::abs(cdxbdy)) * std::abs(adz) +
                                 (std::abs(cdxady) + std::abs(adxcdy)) * std::abs(bdz) +
                                 (std::abs(adxbdy) + std::abs(bdxady)) * std::abs(cdz);
        const double bound = kOrient3dBound * permanent;
        if (det > bound) return 1;
        if (-det > bound) return -1;
        if (permanent == 0.0) return 0;  // every product an exact zero
    }
    return orient3d_exact(a, b, c, d);
}

}  // namespace detail
}  // namespace pqdc
