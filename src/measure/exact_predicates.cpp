// The exact fallback of the orientation predicates (the filters are inline
// in the header).
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

}  // namespace detail
}  // namespace pqdc
