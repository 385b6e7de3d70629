// Exact orientation predicates on double coordinates (internal).
//
// Each returns the sign (+1, 0, -1) of a determinant of coordinate
// differences, exactly, for any finite doubles: first evaluated in floating
// point and accepted when its magnitude exceeds Shewchuk's proven forward
// error bound ("Adaptive Precision Floating-Point Arithmetic and Fast Robust
// Geometric Predicates", 1997, the stage-A bounds of orient2d/orient3d),
// else recomputed exactly: in Shewchuk's floating-point expansions where
// no product can leave the normal range, in integers otherwise (every double
// is an integer times a power of two). Shared by the self-intersection
// finder (src/measure) and decimation (src/decimate).
//
// The filters are inline: they run tens of millions of times per
// self-intersection check. Every file that includes this header is compiled
// with -ffp-contract=off (src/CMakeLists.txt): a fused multiply-add would
// change the rounding the error bounds assume.
#pragma once

#include <openvdb/Types.h>

#include <cmath>
#include <cstddef>

namespace pqdc {
namespace detail {

/// The signs computed in exact arithmetic only (no filter): the fallback,
/// and the reference in tests.
int orient3d_exact(const openvdb::Vec3d& a, const openvdb::Vec3d& b, const openvdb::Vec3d& c, const openvdb::Vec3d& d);
int orient2d_exact(double ax, double ay, double bx, double by, double cx, double cy);

namespace filter {
constexpr double kEpsilon = 0x1.0p-53;  // Shewchuk's epsilon: half an ulp of 1
constexpr double kOrient2dBound = (3.0 + 16.0 * kEpsilon) * kEpsilon;
constexpr double kOrient3dBound = (7.0 + 56.0 * kEpsilon) * kEpsilon;

/// Every value is 0 or of magnitude in [lo, hi] (NaN is not). Checked for
/// all of them without a branch per value.
template <std::size_t N>
inline bool magnitudes_within(const double (&d)[N], double lo, double hi) {
    bool bad = false;
    for (std::size_t i = 0; i < N; ++i) {
        const double m = std::abs(d[i]);
        const bool above = !(m <= hi);  // NaN counts as out of range
        bad |= above | ((m < lo) & (m != 0.0));
    }
    return !bad;
}

/// Shewchuk's bounds assume no overflow and no underflow. A difference of
/// magnitude 0 or in [2^-300, 2^300] keeps every product of up to three
/// differences, and every sum or difference of such products (a multiple of
/// the smallest operand's ulp when not zero), within the normal range.
/// Exact zeros are fine: a floating-point difference is 0 only when the
/// operands are equal, and zero products are exact. (A NaN difference goes
/// to the exact fallback, which answers 0 for non-finite input.)
template <std::size_t N>
inline bool all_safe(const double (&d)[N]) {
    return magnitudes_within(d, 0x1.0p-300, 0x1.0p300);
}

}  // namespace filter

/// Sign of det [a - c; b - c]: positive when a, b, c are counter-clockwise.
inline int orient2d(double ax, double ay, double bx, double by, double cx, double cy) {
    const double acx = ax - cx, bcx = bx - cx, acy = ay - cy, bcy = by - cy;
    const double differences[4] = {acx, bcx, acy, bcy};
    if (filter::all_safe(differences)) {
        const double left = acx * bcy, right = acy * bcx;
        const double det = left - right;
        const double bound = filter::kOrient2dBound * (std::abs(left) + std::abs(right));
        if (det > bound) return 1;
        if (-det > bound) return -1;
        if (left == 0.0 && right == 0.0) return 0;  // both products exact zeros
    }
    return orient2d_exact(ax, ay, bx, by, cx, cy);
}

/// orient3d's floating-point stage only: its sign when the error bound
/// proves it, else 2 (undecided). For cheap early exits.
inline int orient3d_if_certain(const openvdb::Vec3d& a, const openvdb::Vec3d& b, const openvdb::Vec3d& c,
                               const openvdb::Vec3d& d) {
    const double adx = a[0] - d[0], bdx = b[0] - d[0], cdx = c[0] - d[0];
    const double ady = a[1] - d[1], bdy = b[1] - d[1], cdy = c[1] - d[1];
    const double adz = a[2] - d[2], bdz = b[2] - d[2], cdz = c[2] - d[2];
    const double differences[9] = {adx, bdx, cdx, ady, bdy, cdy, adz, bdz, cdz};
    if (filter::all_safe(differences)) {
        // Shewchuk's orient3d stage A, in his order of operations.
        const double bdxcdy = bdx * cdy, cdxbdy = cdx * bdy;
        const double cdxady = cdx * ady, adxcdy = adx * cdy;
        const double adxbdy = adx * bdy, bdxady = bdx * ady;
        const double det = adz * (bdxcdy - cdxbdy) + bdz * (cdxady - adxcdy) + cdz * (adxbdy - bdxady);
        const double permanent = (std::abs(bdxcdy) + std::abs(cdxbdy)) * std::abs(adz) +
                                 (std::abs(cdxady) + std::abs(adxcdy)) * std::abs(bdz) +
                                 (std::abs(adxbdy) + std::abs(bdxady)) * std::abs(cdz);
        const double bound = filter::kOrient3dBound * permanent;
        if (det > bound) return 1;
        if (-det > bound) return -1;
        if (permanent == 0.0) return 0;  // every product an exact zero
    }
    return 2;
}

/// Sign of det [a - d; b - d; c - d] (rows): positive when d lies below the
/// plane through a, b, c, "below" being the side from which a, b, c appear
/// clockwise.
inline int orient3d(const openvdb::Vec3d& a, const openvdb::Vec3d& b, const openvdb::Vec3d& c, const openvdb::Vec3d& d) {
    const int sign = orient3d_if_certain(a, b, c, d);
    return sign != 2 ? sign : orient3d_exact(a, b, c, d);
}

}  // namespace detail
}  // namespace pqdc
