// Minimal 3-vector and symmetric 3x3 matrix value types used by the quadric
// library. Kept free of OpenVDB/Eigen so quadric.hpp stays a light, header-only
// building block that compiles in microseconds and vectorizes well.
#pragma once

#include <cmath>
#include <cstddef>

namespace pqdc {

template <class T>
struct vec3 {
    T x{}, y{}, z{};

    constexpr vec3() = default;
    constexpr vec3(T x_, T y_, T z_) : x(x_), y(y_), z(z_) {}
    template <class U>
    constexpr explicit vec3(const vec3<U>& o) : x(T(o.x)), y(T(o.y)), z(T(o.z)) {}

    constexpr T& operator[](std::size_t i) { return i == 0 ? x : (i == 1 ? y : z); }
    constexpr T operator[](std::size_t i) const { return i == 0 ? x : (i == 1 ? y : z); }

    constexpr vec3& operator+=(const vec3& o) { x += o.x; y += o.y; z += o.z; return *this; }
    constexpr vec3& operator-=(const vec3& o) { x -= o.x; y -= o.y; z -= o.z; return *this; }
    constexpr vec3& operator*=(T s) { x *= s; y *= s; z *= s; return *this; }
    constexpr vec3& operator/=(T s) { x /= s; y /= s; z /= s; return *this; }
};

template <class T> constexpr vec3<T> operator+(vec3<T> a, const vec3<T>& b) { return a += b; }
template <class T> constexpr vec3<T> operator-(vec3<T> a, const vec3<T>& b) { return a -= b; }
template <class T> constexpr vec3<T> operator-(const vec3<T>& a) { return {-a.x, -a.y, -a.z}; }
template <class T> constexpr vec3<T> operator*(vec3<T> a, T s) { return a *= s; }
template <class T> constexpr vec3<T> operator*(T s, vec3<T> a) { return a *= s; }
template <class T> constexpr vec3<T> operator/(vec3<T> a, T s) { return a /= s; }
template <class T> constexpr bool operator==(const vec3<T>& a, const vec3<T>& b) {
    return a.x == b.x && a.y == b.y && a.z == b.z;
}
template <class T> constexpr bool operator!=(const vec3<T>& a, const vec3<T>& b) { return !(a == b); }

template <class T> constexpr T dot(const vec3<T>& a, const vec3<T>& b) {
    return a.x * b.x + a.y * b.y + a.z * b.z;
}
template <class T> constexpr vec3<T> cross(const vec3<T>& a, const vec3<T>& b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
template <class T> inline T length(const vec3<T>& a) { return std::sqrt(dot(a, a)); }
template <class T> constexpr T length_sqr(const vec3<T>& a) { return dot(a, a); }
template <class T> inline T distance(const vec3<T>& a, const vec3<T>& b) { return length(a - b); }
template <class T> inline bool is_finite(const vec3<T>& a) {
    return std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(a.z);
}

/// Symmetric 3x3 matrix stored as its 6 unique entries (row-major upper triangle).
template <class T>
struct sym3 {
    T a00{}, a01{}, a02{}, a11{}, a12{}, a22{};

    static constexpr sym3 zero() { return {}; }
    static constexpr sym3 identity(T s = T(1)) { return {s, 0, 0, s, 0, s}; }
    static constexpr sym3 outer(const vec3<T>& n) {
        return {n.x * n.x, n.x * n.y, n.x * n.z, n.y * n.y, n.y * n.z, n.z * n.z};
    }
    /// From a full (possibly non-symmetric) matrix given by rows: keeps the symmetric part.
    static constexpr sym3 from_rows(const vec3<T>& r0, const vec3<T>& r1, const vec3<T>& r2) {
        return {r0.x, (r0.y + r1.x) / 2, (r0.z + r2.x) / 2, r1.y, (r1.z + r2.y) / 2, r2.z};
    }
    template <class U>
    constexpr explicit operator sym3<U>() const {
        return {U(a00), U(a01), U(a02), U(a11), U(a12), U(a22)};
    }

    constexpr T operator()(int r, int c) const {
        const int i = r < c ? r : c, j = r < c ? c : r;
        if (i == 0) return j == 0 ? a00 : (j == 1 ? a01 : a02);
        if (i == 1) return j == 1 ? a11 : a12;
        return a22;
    }
    constexpr T trace() const { return a00 + a11 + a22; }
    constexpr T determinant() const {
        return a00 * (a11 * a22 - a12 * a12) - a01 * (a01 * a22 - a12 * a02) +
               a02 * (a01 * a12 - a11 * a02);
    }

    constexpr sym3& operator+=(const sym3& o) {
        a00 += o.a00; a01 += o.a01; a02 += o.a02; a11 += o.a11; a12 += o.a12; a22 += o.a22;
        return *this;
    }
    constexpr sym3& operator-=(const sym3& o) {
        a00 -= o.a00; a01 -= o.a01; a02 -= o.a02; a11 -= o.a11; a12 -= o.a12; a22 -= o.a22;
        return *this;
    }
    constexpr sym3& operator*=(T s) {
        a00 *= s; a01 *= s; a02 *= s; a11 *= s; a12 *= s; a22 *= s;
        return *this;
    }
};

template <class T> constexpr sym3<T> operator+(sym3<T> a, const sym3<T>& b) { return a += b; }
template <class T> constexpr sym3<T> operator-(sym3<T> a, const sym3<T>& b) { return a -= b; }
template <class T> constexpr sym3<T> operator*(sym3<T> a, T s) { return a *= s; }
template <class T> constexpr sym3<T> operator*(T s, sym3<T> a) { return a *= s; }
template <class T> constexpr vec3<T> operator*(const sym3<T>& m, const vec3<T>& v) {
    return {m.a00 * v.x + m.a01 * v.y + m.a02 * v.z,
            m.a01 * v.x + m.a11 * v.y + m.a12 * v.z,
            m.a02 * v.x + m.a12 * v.y + m.a22 * v.z};
}
/// Tr[A B] for symmetric A, B.
template <class T> constexpr T trace_of_product(const sym3<T>& a, const sym3<T>& b) {
    return a.a00 * b.a00 + a.a11 * b.a11 + a.a22 * b.a22 +
           T(2) * (a.a01 * b.a01 + a.a02 * b.a02 + a.a12 * b.a12);
}
/// [a]x S [a]x^T (cross-product matrix sandwich), symmetric for symmetric S.
template <class T> constexpr sym3<T> cross_sandwich(const vec3<T>& a, const sym3<T>& s) {
    // With r_i the rows of [a]x, M_ij = r_i^T S r_j.
    const vec3<T> r0{T(0), -a.z, a.y};
    const vec3<T> r1{a.z, T(0), -a.x};
    const vec3<T> r2{-a.y, a.x, T(0)};
    const vec3<T> s0 = s * r0, s1 = s * r1, s2 = s * r2;
    return {dot(r0, s0), dot(r0, s1), dot(r0, s2), dot(r1, s1), dot(r1, s2), dot(r2, s2)};
}

}  // namespace pqdc
