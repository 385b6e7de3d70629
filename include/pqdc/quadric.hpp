// Error quadrics and probabilistic error quadrics.
//
// A quadric is the quadratic error function  Q(x) = x^T A x - 2 b^T x + c  with
// symmetric A. Quadrics add (the error of a sum of objects is the sum of their
// quadrics), so they are a small value type with `+`.
//
// Probabilistic quadrics (Trettner & Kobbelt, "Fast and Robust QEF Minimization
// using Probabilistic Quadrics", EG 2020) are the expected quadric when the
// input (plane point/normal, triangle corners) is Gaussian-distributed; A is
// positive definite for any positive covariance, so A^-1 b is a robust
// minimizer without SVD. Equation numbers below refer to that paper.
//
// Coordinates: quadrics accumulate large terms (c grows with |x|^2). Build and
// sum them relative to a nearby origin (e.g. a cell corner) and move them with
// relative_to(); in single precision, quadrics built in world coordinates far
// from the origin lose the minimizer entirely.
#pragma once

#include "pqdc/vec3.hpp"

#include <cmath>
#include <limits>
#include <optional>
#include <type_traits>

namespace pqdc {

/// Which terms a factory computes. `a_b` skips c (enough for the minimizer,
/// cheaper); such a quadric has c == 0 and its values are meaningless, only
/// its minimizer is.
enum class quadric_terms { a_b, a_b_c };

/// Cross-interference matrix Ci[A, B] (eq. 12): second-order covariance terms.
template <class T>
constexpr sym3<T> cross_interference(const sym3<T>& a, const sym3<T>& b) {
    return {
        a.a11 * b.a22 - T(2) * a.a12 * b.a12 + a.a22 * b.a11,
        -a.a01 * b.a22 + a.a02 * b.a12 + a.a12 * b.a02 - a.a22 * b.a01,
        a.a01 * b.a12 - a.a02 * b.a11 - a.a11 * b.a02 + a.a12 * b.a01,
        a.a00 * b.a22 - T(2) * a.a02 * b.a02 + a.a22 * b.a00,
        -a.a00 * b.a12 + a.a01 * b.a02 + a.a02 * b.a01 - a.a12 * b.a00,
        a.a00 * b.a11 - T(2) * a.a01 * b.a01 + a.a11 * b.a00,
    };
}

template <class T>
struct quadric {
    using scalar = T;
    sym3<T> A{};
    vec3<T> b{};
    T c = T(0);

    // ---------------------------------------------------------------- factories

    /// Squared distance to point p: |x - p|^2. A sum of n point quadrics is
    /// minimized by the mass point of the points.
    static constexpr quadric point(const vec3<T>& p) {
        return {sym3<T>::identity(), p, dot(p, p)};
    }

    /// Classical plane quadric <x - q, n>^2 (eq. 4). n need not be unit length;
    /// the error then scales with |n|^2. Rank 1: minimize with the pseudo-inverse.
    template <quadric_terms Terms = quadric_terms::a_b_c>
    static constexpr quadric plane(const vec3<T>& q, const vec3<T>& n) {
        const T d = dot(n, q);
        return {sym3<T>::outer(n), n * d, Terms == quadric_terms::a_b_c ? d * d : T(0)};
    }

    /// Probabilistic plane quadric with isotropic noise (eqs. 6-8 with
    /// Sigma_q = sigma_q^2 I, Sigma_n = sigma_n^2 I). sigma_q (a length) and
    /// sigma_n (dimensionless, relative to a unit normal) are standard
    /// deviations. sigma_q does not move the minimizer, it only adds to c.
    template <quadric_terms Terms = quadric_terms::a_b_c>
    static constexpr quadric probabilistic_plane(const vec3<T>& q, const vec3<T>& n, T sigma_q,
                                                 T sigma_n) {
        const T vn = sigma_n * sigma_n;
        const T d = dot(n, q);
        sym3<T> A = sym3<T>::outer(n);
        A.a00 += vn;
        A.a11 += vn;
        A.a22 += vn;
        T c = T(0);
        if constexpr (Terms == quadric_terms::a_b_c) {
            const T vq = sigma_q * sigma_q;
            c = d * d + vn * dot(q, q) + vq * dot(n, n) + T(3) * vn * vq;
        }
        // One aggregate return: GCC 12 otherwise builds a_b results through
        // the stack (store-forwarding stalls, 2-3x slower; bench_table1).
        return {A, n * d + q * vn, c};
    }

    /// Probabilistic plane quadric with general covariances (eqs. 6-8).
    template <quadric_terms Terms = quadric_terms::a_b_c>
    static constexpr quadric probabilistic_plane(const vec3<T>& q, const vec3<T>& n,
                                                 const sym3<T>& Sigma_q, const sym3<T>& Sigma_n) {
        const sym3<T> A = sym3<T>::outer(n) + Sigma_n;
        const vec3<T> b = A * q;
        T c = T(0);
        if constexpr (Terms == quadric_terms::a_b_c)
            c = dot(q, b) + dot(n, Sigma_q * n) + trace_of_product(Sigma_n, Sigma_q);
        return {A, b, c};
    }

    /// Classical triangle quadric (eq. 9): (n^T x - |p,q,r|)^2 with
    /// n = p x q + q x r + r x p (twice the area times the unit normal), so it
    /// is area-weighted: Q(x) = (2 area dist(x, plane))^2.
    template <quadric_terms Terms = quadric_terms::a_b_c>
    static constexpr quadric triangle(const vec3<T>& p, const vec3<T>& q, const vec3<T>& r) {
        const vec3<T> pxq = cross(p, q);
        const vec3<T> n = pxq + cross(q, r) + cross(r, p);
        const T det = dot(pxq, r);
        return {sym3<T>::outer(n), n * det, Terms == quadric_terms::a_b_c ? det * det : T(0)};
    }

    /// Probabilistic triangle quadric, every corner with isotropic positional
    /// noise of standard deviation sigma (a length). Eqs. 11, 13-15 with
    /// Sigma = sigma^2 I, where [e]x Sigma [e]x^T = sigma^2 (|e|^2 I - e e^T)
    /// and Ci = 2 sigma^4 I.
    template <quadric_terms Terms = quadric_terms::a_b_c>
    static constexpr quadric probabilistic_triangle(const vec3<T>& p, const vec3<T>& q,
                                                    const vec3<T>& r, T sigma) {
        const T v = sigma * sigma;
        const T v2 = v * v;
        const vec3<T> pxq = cross(p, q), qxr = cross(q, r), rxp = cross(r, p);
        const vec3<T> n = pxq + qxr + rxp;
        const T det = dot(pxq, r);
        const vec3<T> epq = p - q, eqr = q - r, erp = r - p;

        sym3<T> A = sym3<T>::outer(n);
        const sym3<T> eet = sym3<T>::outer(epq) + sym3<T>::outer(eqr) + sym3<T>::outer(erp);
        const T diag = v * (dot(epq, epq) + dot(eqr, eqr) + dot(erp, erp)) + T(6) * v2;
        A -= eet * v;
        A.a00 += diag;
        A.a11 += diag;
        A.a22 += diag;

        const vec3<T> b = n * det + (cross(q - p, pxq) + cross(r - q, qxr) + cross(p - r, rxp)) * v +
                          (p + q + r) * (T(2) * v2);
        T c = T(0);
        if constexpr (Terms == quadric_terms::a_b_c)
            c = det * det + v * (dot(pxq, pxq) + dot(qxr, qxr) + dot(rxp, rxp)) +
                T(2) * v2 * (dot(p, p) + dot(q, q) + dot(r, r)) + T(6) * v2 * v;
        return {A, b, c};
    }

    /// Probabilistic triangle quadric with a general covariance per corner
    /// (eqs. 11, 12, 14, 15).
    template <quadric_terms Terms = quadric_terms::a_b_c>
    static constexpr quadric probabilistic_triangle(const vec3<T>& p, const vec3<T>& q,
                                                    const vec3<T>& r, const sym3<T>& Sp,
                                                    const sym3<T>& Sq, const sym3<T>& Sr) {
        const vec3<T> pxq = cross(p, q), qxr = cross(q, r), rxp = cross(r, p);
        const vec3<T> n = pxq + qxr + rxp;
        const T det = dot(pxq, r);
        const sym3<T> ci_pq = cross_interference(Sp, Sq);
        const sym3<T> ci_qr = cross_interference(Sq, Sr);
        const sym3<T> ci_rp = cross_interference(Sr, Sp);

        const sym3<T> A = sym3<T>::outer(n) + cross_sandwich(p - q, Sr) + cross_sandwich(q - r, Sp) +
                          cross_sandwich(r - p, Sq) + ci_pq + ci_qr + ci_rp;
        const vec3<T> b = n * det + cross(q - p, Sr * pxq) + cross(r - q, Sp * qxr) +
                          cross(p - r, Sq * rxp) + ci_pq * r + ci_qr * p + ci_rp * q;
        T c = T(0);
        if constexpr (Terms == quadric_terms::a_b_c)
            c = det * det + dot(pxq, Sr * pxq) + dot(qxr, Sp * qxr) + dot(rxp, Sq * rxp) +
                dot(p, ci_qr * p) + dot(q, ci_rp * q) + dot(r, ci_pq * r) + trace_of_product(Sr, ci_pq);
        return {A, b, c};
    }

    // --------------------------------------------------------------- arithmetic

    constexpr quadric& operator+=(const quadric& o) {
        A += o.A;
        b += o.b;
        c += o.c;
        return *this;
    }
    constexpr quadric& operator-=(const quadric& o) {
        A -= o.A;
        b -= o.b;
        c -= o.c;
        return *this;
    }
    constexpr quadric& operator*=(T s) {
        A *= s;
        b *= s;
        c *= s;
        return *this;
    }
    friend constexpr quadric operator+(quadric a, const quadric& o) { return a += o; }
    friend constexpr quadric operator-(quadric a, const quadric& o) { return a -= o; }
    friend constexpr quadric operator*(quadric a, T s) { return a *= s; }
    friend constexpr quadric operator*(T s, quadric a) { return a *= s; }

    template <class U>
    constexpr explicit operator quadric<U>() const {
        return {sym3<U>(A), vec3<U>(b), U(c)};
    }

    /// Q(x) = x^T A x - 2 b^T x + c.
    constexpr T operator()(const vec3<T>& x) const { return dot(x, A * x) - T(2) * dot(b, x) + c; }

    /// The same error function expressed relative to `origin`: the returned R
    /// satisfies R(y) == (*this)(origin + y). Exact in exact arithmetic; the
    /// arithmetic is done in double (long double for double quadrics) so that
    /// moving a quadric across a cell or back to world space stays accurate.
    quadric relative_to(const vec3<T>& origin) const {
        using W = std::conditional_t<(sizeof(T) < sizeof(double)), double, long double>;
        const quadric<W> w = static_cast<quadric<W>>(*this);
        const vec3<W> o(origin);
        const vec3<W> Ao = w.A * o;
        quadric<W> r;
        r.A = w.A;
        r.b = w.b - Ao;
        r.c = w.c - W(2) * dot(w.b, o) + dot(o, Ao);
        return static_cast<quadric<T>>(r);
    }
};

using quadricf = quadric<float>;
using quadricd = quadric<double>;

// ----------------------------------------------------------------- minimizers

/// x = A^-1 b for a positive-definite A (closed-form adjugate inverse).
/// Returns nullopt, never NaN, when A is not numerically positive definite:
/// indefinite (Sylvester's criterion), det(A) <= 64 eps trace(A)^3 (rank
/// deficient, ill-conditioned or tiny), or any input/result is non-finite.
/// The det bound caps the rounding error of the adjugate solve, which grows
/// like cond(A)^2 eps when two eigenvalues are small (flat regions): near
/// the bound |x| loses all but ~3 digits, far from it the error is tiny.
/// Sums of isotropic probabilistic plane quadrics with unit normals have
/// det/trace^3 >= ~sigma_n^4 for any plane layout (equality when all planes
/// are parallel), so they pass for sigma_n >= 0.06 in float and >= 4e-4 in
/// double; smaller sigma_n on flat regions gives nullopt (use double, or
/// minimizer_pseudo_inverse). Classical quadrics generally need
/// minimizer_pseudo_inverse.
template <class T>
std::optional<vec3<T>> minimizer_positive_definite(const quadric<T>& q) {
    const sym3<T>& a = q.A;
    const T c00 = a.a11 * a.a22 - a.a12 * a.a12;
    const T c01 = a.a02 * a.a12 - a.a01 * a.a22;
    const T c02 = a.a01 * a.a12 - a.a02 * a.a11;
    const T c22 = a.a00 * a.a11 - a.a01 * a.a01;
    const T det = a.a00 * c00 + a.a01 * c01 + a.a02 * c02;
    const T tr = a.trace();
    // Sylvester: a00 > 0, c22 > 0 and det > 0 <=> positive definite; a
    // positive det and trace alone also admit saddles such as diag(-1, -1, 3).
    if (!(a.a00 > T(0)) || !(c22 > T(0)) ||
        !(det > T(64) * std::numeric_limits<T>::epsilon() * tr * tr * tr))
        return std::nullopt;
    const T c11 = a.a00 * a.a22 - a.a02 * a.a02;
    const T c12 = a.a01 * a.a02 - a.a00 * a.a12;
    const T inv = T(1) / det;
    // Not const: `return x` must be able to move, or GCC 12 assembles the
    // optional through the stack (store-forwarding stalls, 2x slower).
    vec3<T> x{(c00 * q.b.x + c01 * q.b.y + c02 * q.b.z) * inv,
              (c01 * q.b.x + c11 * q.b.y + c12 * q.b.z) * inv,
              (c02 * q.b.x + c12 * q.b.y + c22 * q.b.z) * inv};
    if (!is_finite(x)) return std::nullopt;
    return x;
}

/// Eigen-decomposition of a symmetric 3x3 matrix by cyclic Jacobi rotations.
/// Deterministic and accurate to double rounding; values[i] belongs to the
/// column vectors[i]. Unsorted.
struct sym3_eigen {
    double values[3];
    vec3<double> vectors[3];
};

inline sym3_eigen eigen_decompose(const sym3<double>& m) {
    double a[3][3] = {{m.a00, m.a01, m.a02}, {m.a01, m.a11, m.a12}, {m.a02, m.a12, m.a22}};
    double v[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    for (int sweep = 0; sweep < 32; ++sweep) {
        const double off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        const double diag = a[0][0] * a[0][0] + a[1][1] * a[1][1] + a[2][2] * a[2][2];
        if (!(off > 1e-30 * diag) || off == 0.0) break;
        for (int p = 0; p < 2; ++p) {
            for (int r = p + 1; r < 3; ++r) {
                if (a[p][r] == 0.0) continue;
                const double theta = (a[r][r] - a[p][p]) / (2.0 * a[p][r]);
                const double t = (theta >= 0 ? 1.0 : -1.0) /
                                 (std::fabs(theta) + std::sqrt(theta * theta + 1.0));
                const double cs = 1.0 / std::sqrt(t * t + 1.0), sn = t * cs;
                for (int k = 0; k < 3; ++k) {  // A <- A J
                    const double akp = a[k][p], akr = a[k][r];
                    a[k][p] = cs * akp - sn * akr;
                    a[k][r] = sn * akp + cs * akr;
                }
                for (int k = 0; k < 3; ++k) {  // A <- J^T A
                    const double apk = a[p][k], ark = a[r][k];
                    a[p][k] = cs * apk - sn * ark;
                    a[r][k] = sn * apk + cs * ark;
                }
                for (int k = 0; k < 3; ++k) {  // V <- V J
                    const double vkp = v[k][p], vkr = v[k][r];
                    v[k][p] = cs * vkp - sn * vkr;
                    v[k][r] = sn * vkp + cs * vkr;
                }
            }
        }
    }
    sym3_eigen e;
    for (int i = 0; i < 3; ++i) {
        e.values[i] = a[i][i];
        e.vectors[i] = {v[0][i], v[1][i], v[2][i]};
    }
    return e;
}

template <class T>
struct pseudo_inverse_result {
    vec3<T> point;  ///< the minimizer closest to the reference point
    int rank = 0;   ///< number of eigen-directions kept (0..3)
};

/// Robust minimizer for rank-deficient quadrics (classical dual contouring,
/// sigma_n = 0): eigen-decompose A and invert only eigenvalues above
/// relative_cutoff * (largest eigenvalue), solving for the offset from
/// `reference`. Directions the quadric does not constrain keep the
/// reference's coordinate, so pass the mass point of the samples. rank 0
/// (A == 0 or non-finite) returns the reference itself.
/// relative_cutoff: dimensionless, in [0, 1); default 0.01. Eigenvalues of A
/// are squared singular values of the stacked normals, so this is the
/// customary DC truncation of singular values below 0.1 of the largest.
template <class T>
pseudo_inverse_result<T> minimizer_pseudo_inverse(const quadric<T>& q, const vec3<T>& reference,
                                                  double relative_cutoff = 0.01) {
    pseudo_inverse_result<T> res{reference, 0};
    const sym3<double> A(q.A);
    const vec3<double> ref(reference);
    // Residual gradient direction relative to the reference: A (x - ref) = b - A ref.
    const vec3<double> rhs = vec3<double>(q.b) - A * ref;
    if (!is_finite(rhs) || !std::isfinite(A.trace())) return res;
    const sym3_eigen e = eigen_decompose(A);
    double lmax = 0;
    for (double l : e.values) lmax = std::fmax(lmax, std::fabs(l));
    if (!(lmax > 0)) return res;
    vec3<double> dx{0, 0, 0};
    for (int i = 0; i < 3; ++i) {
        if (e.values[i] > relative_cutoff * lmax) {
            dx += e.vectors[i] * (dot(e.vectors[i], rhs) / e.values[i]);
            ++res.rank;
        }
    }
    res.point = vec3<T>(ref + dx);
    return res;
}

/// Mass point accumulator: the sigma_n -> infinity limit of a sum of
/// probabilistic plane quadrics, whose minimizer tends to the average of the
/// plane points (the normals stop mattering).
template <class T>
struct mass_point {
    vec3<T> sum{};
    T weight = T(0);

    constexpr void add(const vec3<T>& p, T w = T(1)) {
        sum += p * w;
        weight += w;
    }
    constexpr mass_point& operator+=(const mass_point& o) {
        sum += o.sum;
        weight += o.weight;
        return *this;
    }
    friend constexpr mass_point operator+(mass_point a, const mass_point& o) { return a += o; }
    /// The average; nullopt when nothing was added.
    std::optional<vec3<T>> point() const {
        if (!(weight > T(0))) return std::nullopt;
        return sum / weight;
    }
};

}  // namespace pqdc
