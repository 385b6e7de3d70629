// The exact fallback of the orientation predicates (the filters are inline
// in the header): Shewchuk's floating-point expansions where the differences
// keep every product within the normal range, else integers (every double is
// an integer times a power of two). Both are exact; the expansions are much
// faster, and flat CAD sides send many exactly coplanar pairs here.
#include "geometry/exact_predicates.hpp"

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

// Shewchuk's floating-point expansions (a value is the exact sum of
// non-overlapping doubles, smallest first), with the products' error terms
// from fma. Exact barring overflow and underflow, which expansions_fit()
// rules out.
struct Expansion {
    double c[192];
    int n = 0;
};

void two_sum(double a, double b, double& x, double& y) {
    x = a + b;
    const double bv = x - a, av = x - bv;
    y = (a - av) + (b - bv);
}

/// h = e + b (Shewchuk's grow_expansion_zeroelim).
void grow(const Expansion& e, double b, Expansion& h) {
    double q = b;
    h.n = 0;
    for (int i = 0; i < e.n; ++i) {
        double sum, err;
        two_sum(q, e.c[i], sum, err);
        q = sum;
        if (err != 0) h.c[h.n++] = err;
    }
    if (q != 0 || h.n == 0) h.c[h.n++] = q;
}

/// h = e + f, one component of f at a time (sizes here are small).
void add(const Expansion& e, const Expansion& f, Expansion& h) {
    if (f.n == 0) {
        h = e;
        return;
    }
    Expansion t;
    const Expansion* from = &e;
    for (int i = 0; i < f.n; ++i) {
        // Ping-pong so that the last grow writes h.
        Expansion& to = ((f.n - 1 - i) % 2 == 0) ? h : t;
        grow(*from, f.c[i], to);
        from = &to;
    }
}

/// h = e * b (Shewchuk's scale_expansion_zeroelim, products split by fma).
void scale(const Expansion& e, double b, Expansion& h) {
    h.n = 0;
    if (e.n == 0) return;
    double q = e.c[0] * b;
    double lo = std::fma(e.c[0], b, -q);
    if (lo != 0) h.c[h.n++] = lo;
    for (int i = 1; i < e.n; ++i) {
        const double p = e.c[i] * b, pe = std::fma(e.c[i], b, -p);
        double s1, e1, s2, e2;
        two_sum(q, pe, s1, e1);
        if (e1 != 0) h.c[h.n++] = e1;
        two_sum(p, s1, s2, e2);
        if (e2 != 0) h.c[h.n++] = e2;
        q = s2;
    }
    if (q != 0 || h.n == 0) h.c[h.n++] = q;
}

void mul(const Expansion& e, const Expansion& f, Expansion& h) {
    Expansion acc[2], part;
    int cur = 0;
    for (int i = 0; i < f.n; ++i) {
        scale(e, f.c[i], part);
        add(acc[cur], part, acc[1 - cur]);
        cur = 1 - cur;
    }
    h.n = acc[cur].n;
    std::copy(acc[cur].c, acc[cur].c + acc[cur].n, h.c);
}

Expansion diff(double a, double b) {  // exact a - b
    Expansion e;
    const double x = a - b, bv = a - x, av = x + bv;
    const double y = (a - av) + (bv - b);
    if (y != 0) e.c[e.n++] = y;
    e.c[e.n++] = x;
    return e;
}

Expansion negate(Expansion e) {
    for (int i = 0; i < e.n; ++i) e.c[i] = -e.c[i];
    return e;
}

int sign_of(const Expansion& e) {
    for (int i = e.n - 1; i >= 0; --i)
        if (e.c[i] != 0) return e.c[i] > 0 ? 1 : -1;
    return 0;
}

/// Exact x1 * y1 - x2 * y2 for expansions.
Expansion cross2(const Expansion& x1, const Expansion& y1, const Expansion& x2, const Expansion& y2) {
    Expansion p, q, r;
    mul(x1, y1, p);
    mul(x2, y2, q);
    add(p, negate(q), r);
    return r;
}

/// Differences of magnitude 0 or in [2^-200, 2^200]: every component of
/// products of up to three of them (their error terms reach down to about
/// 2^-760) and of their sums stays a normal double, so the expansions are
/// exact.
template <std::size_t N>
bool expansions_fit(const double (&d)[N]) {
    return filter::magnitudes_within(d, 0x1.0p-200, 0x1.0p200);
}

bool finite(const openvdb::Vec3d& p) { return std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]); }

}  // namespace

int orient2d_exact(double ax, double ay, double bx, double by, double cx, double cy) {
    if (!(std::isfinite(ax) && std::isfinite(ay) && std::isfinite(bx) && std::isfinite(by) && std::isfinite(cx) &&
          std::isfinite(cy)))
        return 0;  // callers reject such points earlier
    const double differences[4] = {ax - cx, ay - cy, bx - cx, by - cy};
    if (expansions_fit(differences)) return sign_of(cross2(diff(ax, cx), diff(by, cy), diff(ay, cy), diff(bx, cx)));
    const auto v = to_integers<6>({ax, ay, bx, by, cx, cy});
    const cpp_int acx = v[0] - v[4], acy = v[1] - v[5], bcx = v[2] - v[4], bcy = v[3] - v[5];
    const cpp_int det = acx * bcy - acy * bcx;
    return det.sign();
}

int orient3d_exact(const openvdb::Vec3d& a, const openvdb::Vec3d& b, const openvdb::Vec3d& c, const openvdb::Vec3d& d) {
    if (!(finite(a) && finite(b) && finite(c) && finite(d))) return 0;  // callers reject such points earlier
    const double differences[9] = {a[0] - d[0], a[1] - d[1], a[2] - d[2], b[0] - d[0], b[1] - d[1],
                                   b[2] - d[2], c[0] - d[0], c[1] - d[1], c[2] - d[2]};
    if (expansions_fit(differences)) {
        const Expansion adx = diff(a[0], d[0]), ady = diff(a[1], d[1]), adz = diff(a[2], d[2]);
        const Expansion bdx = diff(b[0], d[0]), bdy = diff(b[1], d[1]), bdz = diff(b[2], d[2]);
        const Expansion cdx = diff(c[0], d[0]), cdy = diff(c[1], d[1]), cdz = diff(c[2], d[2]);
        Expansion t1, t2, t3, s, r;
        mul(adx, cross2(bdy, cdz, bdz, cdy), t1);
        mul(bdx, cross2(cdy, adz, cdz, ady), t2);
        mul(cdx, cross2(ady, bdz, adz, bdy), t3);
        add(t1, t2, s);
        add(s, t3, r);
        return sign_of(r);
    }
    const auto v = to_integers<12>({a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2], d[0], d[1], d[2]});
    const cpp_int adx = v[0] - v[9], ady = v[1] - v[10], adz = v[2] - v[11];
    const cpp_int bdx = v[3] - v[9], bdy = v[4] - v[10], bdz = v[5] - v[11];
    const cpp_int cdx = v[6] - v[9], cdy = v[7] - v[10], cdz = v[8] - v[11];
    const cpp_int det = adz * (bdx * cdy - cdx * bdy) + bdz * (cdx * ady - adx * cdy) + cdz * (adx * bdy - bdx * ady);
    return det.sign();
}

}  // namespace detail
}  // namespace pqdc
