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

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>

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

/// orient2d for points known to lie in one box, with Shewchuk's stage-A
/// bound taken once for the box (a semi-static filter): every computed
/// coordinate difference is at most W, the box's larger side (rounding is
/// monotone), so |left| + |right| <= 2 fl(W^2) and one bound serves every
/// sign. Where it does not decide, and for widths that could underflow or
/// overflow, the adaptive orient2d. For the stars of the self-intersection
/// checks, whose dozens of signs all involve a few nearby points.
class BoxOrient2d {
public:
    /// Coordinates i and j of the points; `width`: the larger of the box's
    /// sides along them, as computed (hi - lo) in double.
    BoxOrient2d(int i, int j, double width) : i_(i), j_(j) {
        const bool usable = width >= 0x1.0p-250 && width <= 0x1.0p250;  // false for NaN
        // The factor's slack covers the rounding of this product and, with the
        // width's lower limit, any underflow in the products.
        bound_ = usable ? (width * width) * (filter::kOrient2dBound * (2.0 + 0x1.0p-30))
                        : std::numeric_limits<double>::infinity();
    }
    /// orient2d of p, q, r (in the box).
    int operator()(const openvdb::Vec3d& p, const openvdb::Vec3d& q, const openvdb::Vec3d& r) const {
        const double left = (p[i_] - r[i_]) * (q[j_] - r[j_]), right = (p[j_] - r[j_]) * (q[i_] - r[i_]);
        const double det = left - right;
        if (det > bound_) return 1;
        if (-det > bound_) return -1;
        return orient2d(p[i_], p[j_], q[i_], q[j_], r[i_], r[j_]);
    }
    int i() const { return i_; }
    int j() const { return j_; }

private:
    int i_, j_;
    double bound_;
};

/// The BoxOrient2d on coordinates i, j for c and corner(0) ... corner(n - 1).
template <class Corner>
BoxOrient2d orient_in_box_of(int i, int j, const openvdb::Vec3d& c, std::size_t n, const Corner& corner) {
    double lo_i = c[i], hi_i = c[i], lo_j = c[j], hi_j = c[j];
    for (std::size_t k = 0; k < n; ++k) {
        const openvdb::Vec3d& p = corner(k);
        lo_i = std::min(lo_i, p[i]), hi_i = std::max(hi_i, p[i]);
        lo_j = std::min(lo_j, p[j]), hi_j = std::max(hi_j, p[j]);
    }
    return BoxOrient2d(i, j, std::max(hi_i - lo_i, hi_j - lo_j));
}

/// Whether the closed polygon corner(0) ... corner(n - 1) turns around c
/// exactly once with every edge turning the same way seen from c (each
/// orient(c, corner(k), corner(k + 1)) equal and not 0): a star-shaped
/// polygon around c. Then the winding number (Sunday's crossing rule on the
/// ray from c along +i) counts only the edges that cross c's j-coordinate
/// in one direction, upward when the turn is positive, downward when it is
/// negative: exact coordinate comparisons, no further sign. Returns that
/// turn (1 or -1), or 0 when the polygon is not such a star.
template <class Corner>
int turns_once_around(const BoxOrient2d& orient, const openvdb::Vec3d& c, std::size_t n, const Corner& corner) {
    const int j = orient.j();
    int turn = 0, crossings = 0;
    for (std::size_t k = 0; k < n; ++k) {
        const openvdb::Vec3d& p = corner(k);
        const openvdb::Vec3d& q = corner(k + 1 == n ? 0 : k + 1);
        const int o = orient(c, p, q);
        if (o == 0 || (turn != 0 && o != turn)) return 0;
        turn = o;
        crossings += o > 0 ? (p[j] <= c[j] && c[j] < q[j]) : (q[j] <= c[j] && c[j] < p[j]);
    }
    return crossings == 1 ? turn : 0;
}

}  // namespace detail
}  // namespace pqdc
