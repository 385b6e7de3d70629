// Hermite samples on lattice edges: where the surface crosses the edge and its
// unit normal there, for grids (linear or sharp stencils) and procedural
// fields (root finding on the exact field). Shared by both extractors.
#pragma once

#include "lattice/value_block.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/procedural.hpp"
#include "pqdc/vec3.hpp"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <cmath>

namespace pqdc::detail {

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
    if (len > 0 && std::isfinite(len)) {
        const vec3<double> n = g / len;
        return is_finite(n) ? n : vec3<double>{0, 0, 0};
    }
    // |g|^2 overflowed (values from about 1e154 on) or underflowed (below
    // about 1e-154): the direction is still there. Scaled by the largest
    // component first, as a field scaled by any factor gives the same normals.
    const double m = std::max({std::abs(g.x), std::abs(g.y), std::abs(g.z)});
    if (!(m > 0) || !std::isfinite(m)) return {0, 0, 0};
    const vec3<double> s = g / m;
    return s / length(s);
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
/// An infinite value lies beyond every finite one (np.log of an image with
/// zeros): the root is the limit, at the finite end.
inline double linear_root(double s0, double s1) {
    const double denom = s0 - s1;
    double t = denom != 0.0 ? s0 / denom : 0.5;
    // inf / inf: the only NaN of values a cell may hold, so the common
    // path pays one comparison (a finite s0 over an infinite denom is 0).
    if (t != t && (std::isinf(s0) || std::isinf(s1))) return std::isinf(s0) == std::isinf(s1) ? 0.5 : 1.0;
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

/// Whether `holds(x, y, z)` for every point of both end points' ENO
/// stencils (two out along each axis) of the edge from (x, y, z) along axis.
template <class Holds>
bool all_eno_stencil_points(int x, int y, int z, int axis, const Holds& holds) {
    for (int end = 0; end < 2; ++end) {
        const int p[3] = {x + (end && axis == 0), y + (end && axis == 1), z + (end && axis == 2)};
        for (int a = 0; a < 3; ++a)
            for (int off = -2; off <= 2; ++off) {
                int q[3] = {p[0], p[1], p[2]};
                q[a] += off;
                if (!holds(q[0], q[1], q[2])) return false;
            }
    }
    return true;
}

/// Whether every ENO stencil point is active. Inactive points of a narrow
/// band hold the clamped background, whose kink one-sided differences would
/// take for a feature; there the central stencil, which stays one point in,
/// is used.
inline bool eno_stencils_active(const DenseBlock& b, int x, int y, int z, int axis) {
    return all_eno_stencil_points(x, y, z, axis, [&](int i, int j, int k) { return b.on(i, j, k); });
}

/// Whether every ENO stencil point is finite.
inline bool eno_stencils_finite(const DenseBlock& b, int x, int y, int z, int axis) {
    return all_eno_stencil_points(x, y, z, axis, [&](int i, int j, int k) { return std::isfinite(b.at(i, j, k)); });
}

/// GridNormals::sharp. The block must hold two points of margin around both
/// ends of the edge (ENO stencils reach two points out); where a stencil
/// holds NaN or infinity, this is linear_crossing. The test is per stencil,
/// not per block: a block-wide one made a NaN anywhere in a leaf's block
/// (a hole, or outside a Python array) switch the whole leaf to linear
/// crossings, so the mesh depended on where the leaves fell.
inline Crossing sharp_crossing(const DenseBlock& b, int x, int y, int z, int axis) {
    if (!eno_stencils_active(b, x, y, z, axis) || (!b.all_finite && !eno_stencils_finite(b, x, y, z, axis)))
        return linear_crossing(b, x, y, z, axis);
    const int x1 = x + (axis == 0), y1 = y + (axis == 1), z1 = z + (axis == 2);
    const double s0 = b.at(x, y, z), s1 = b.at(x1, y1, z1);
    Crossing c;
    c.t = linear_root(s0, s1);
    // Per axis: of the two one-sided differences, the one whose next second
    // difference is smaller (ENO), where the central one straddles a kink.
    // bend: sum of |second differences| at the point, 0 on a flat face.
    // A second difference below kSmooth of the gradient's length is
    // curvature (radius above 1/kSmooth = 7 voxels), where the central
    // difference is second-order accurate and one-sided ones are not; kinks
    // of edges up to 150 degrees exceed it.
    constexpr double kSmooth = 0.15;
    // A crease: the directional derivative along the edge changes by more
    // than this fraction of the two ends' together (up to 2 across a
    // 90-degree edge). 0.05-0.4 gave the same feature error; 0.2 leaves the
    // curved Armadillo's normal error within 1.3% of the blended crossing's.
    constexpr double kCreaseKink = 0.2;
    // ... and only where both ends' gradients have the same length, as a
    // distance field's do everywhere: an ENO gradient whose axes came from
    // different faces (near a corner, where three meet) does not, and then
    // neither end's plane root is the crossing. At 5% a barely sampled box
    // corner moved 0.42 voxel (0.14 with the blend); at 3% no corner of the
    // test box is worse than with the blend.
    constexpr double kSameLength = 0.03;
    auto eno_gradient = [&b](int px, int py, int pz, double& bend, bool& one_sided) {
        vec3<double> g;
        bend = 0.0;
        one_sided = false;
        const int p[3] = {px, py, pz};
        double v[3][5];
        double len2 = 0;
        for (int a = 0; a < 3; ++a) {
            for (int off = -2; off <= 2; ++off) {
                int q[3] = {p[0], p[1], p[2]};
                q[a] += off;
                v[a][off + 2] = b.at(q[0], q[1], q[2]);
            }
            const double c = 0.5 * (v[a][3] - v[a][1]);
            len2 += c * c;
        }
        const double smooth = kSmooth * std::sqrt(len2);
        for (int a = 0; a < 3; ++a) {
            const double vm2 = v[a][0], vm1 = v[a][1], v0 = v[a][2], vp1 = v[a][3], vp2 = v[a][4];
            const double dp = vp1 - v0, dm = v0 - vm1, c0 = std::abs(vp1 - 2 * v0 + vm1);
            bend += c0;
            if (c0 > smooth && c0 > 1e-6 * (std::abs(dp) + std::abs(dm))) {
                const double cm = std::abs(v0 - 2 * vm1 + vm2), cp = std::abs(vp2 - 2 * vp1 + v0);
                g[a] = cm < cp ? dm : dp;
                one_sided = true;
            } else {
                g[a] = 0.5 * (dp + dm);
            }
        }
        return g;
    };
    double k0 = 0, k1 = 0;
    bool sided0 = false, sided1 = false;
    const vec3<double> g0 = eno_gradient(x, y, z, k0, sided0), g1 = eno_gradient(x1, y1, z1, k1, sided1);
    // Smooth at both ends: the linear crossing is the more accurate one.
    if (!sided0 && !sided1) return linear_crossing(b, x, y, z, axis);
    // An end whose stencil is linear sits in one face's region: trust it
    // more. The floor (1e-3 of the gradient size) keeps flat regions at the
    // plain interpolation.
    const double l0 = length(g0), l1 = length(g1);
    const double eps = 1e-3 * (l0 + l1) + 1e-300;
    if (!std::isfinite(eps)) return linear_crossing(b, x, y, z, axis);  // values near the overflow limit
    const double u0 = 1.0 / (k0 + eps), u1 = 1.0 / (k1 + eps);
    const double a0 = g0[axis], a1 = g1[axis];
    double t0 = a0 != 0.0 ? -s0 / a0 : -1.0, t1 = a1 != 0.0 ? 1.0 - s1 / a1 : -1.0;
    const bool ok0 = t0 >= 0.0 && t0 <= 1.0, ok1 = t1 >= 0.0 && t1 <= 1.0;
    // The ends' directional derivatives differ by more than smooth bending
    // does: the edge crosses a crease between the two ends' faces. Near a
    // crease a distance field is the max (where it is convex) or the min
    // (concave) of the faces' planes P0, P1, and the zero of max(P0, P1) is
    // the plane root nearer the negative end (of min: nearer the positive
    // end). That one root with its plane's normal keeps the crossing on a
    // face, where blending the two roots cut the crease: clean feature error
    // 0.10 -> 0.034-0.054 voxel on the box, CSG part and fandisk.
    if (ok0 || ok1) {
        const double kink = a1 - a0;  // > 0: convex along the edge
        if (std::abs(kink) > kCreaseKink * (std::abs(a0) + std::abs(a1)) &&
            std::abs(l0 - l1) <= kSameLength * std::max(l0, l1)) {
            const bool nearer_end0 = (s0 < 0.0) == (kink > 0.0);
            const bool use0 = ok0 && ok1 ? (nearer_end0 ? t0 <= t1 : t0 >= t1) : ok0;
            c.t = use0 ? t0 : t1;
            c.normal = normalized_or_zero(use0 ? g0 : g1);
            return c;
        }
    }
    if (!ok0) t0 = c.t;
    if (!ok1) t1 = c.t;
    c.t = (u0 * t0 + u1 * t1) / (u0 + u1);
    c.normal = normalized_or_zero(g0 * ((1.0 - c.t) * u0) + g1 * (c.t * u1));
    return c;
}

/// Whether the 27 values around block point (x, y, z) are finite.
inline bool neighbourhood_finite(const DenseBlock& b, int x, int y, int z) {
    for (int i = -1; i <= 1; ++i)
        for (int j = -1; j <= 1; ++j)
            for (int k = -1; k <= 1; ++k)
                if (!std::isfinite(b.at(x + i, y + j, z + k))) return false;
    return true;
}

/// Gradient of the least-squares linear fit of the 27 values around a block
/// point: per axis the mean of the nine central differences across the
/// point's 3x3 neighbourhood. Central differences where the neighbourhood is
/// not finite (tested per point, not per block: see sharp_crossing).
inline vec3<double> least_squares_gradient(const DenseBlock& b, int x, int y, int z) {
    if (!b.all_finite && !neighbourhood_finite(b, x, y, z)) return block_gradient(b, x, y, z);
    const int sx = b.dim * b.dim, sy = b.dim, c = b.index(x, y, z);
    const double* v = b.value.data();
    vec3<double> g{0, 0, 0};
    for (int j = -1; j <= 1; ++j)
        for (int k = -1; k <= 1; ++k) {
            g.x += v[c + sx + j * sy + k] - v[c - sx + j * sy + k];
            g.y += v[c + sy + j * sx + k] - v[c - sy + j * sx + k];
            g.z += v[c + 1 + j * sx + k * sy] - v[c - 1 + j * sx + k * sy];
        }
    return g * (1.0 / 18.0);
}

/// GridNormals::least_squares: the linear crossing, with both ends'
/// least-squares gradients interpolated to it.
inline Crossing least_squares_crossing(const DenseBlock& b, int x, int y, int z, int axis) {
    const int x1 = x + (axis == 0), y1 = y + (axis == 1), z1 = z + (axis == 2);
    Crossing c;
    c.t = linear_root(b.at(x, y, z), b.at(x1, y1, z1));
    const vec3<double> g0 = least_squares_gradient(b, x, y, z), g1 = least_squares_gradient(b, x1, y1, z1);
    c.normal = normalized_or_zero(g0 * (1.0 - c.t) + g1 * c.t);
    return c;
}

// Crossing oracles: oracle(block, x, y, z, axis) is the crossing on the
// lattice edge from block point (x, y, z) along axis. kMargin: lattice points
// of the block below the first cell that the oracle's stencils need.

/// Grids, GridNormals::central.
struct LinearOracle {
    static constexpr int kMargin = 1;
    Crossing operator()(const DenseBlock& b, int x, int y, int z, int axis) const {
        return linear_crossing(b, x, y, z, axis);
    }
};

/// Grids, GridNormals::least_squares.
struct LeastSquaresOracle {
    static constexpr int kMargin = 1;
    Crossing operator()(const DenseBlock& b, int x, int y, int z, int axis) const {
        return least_squares_crossing(b, x, y, z, axis);
    }
};

/// Grids, GridNormals::sharp.
struct SharpOracle {
    static constexpr int kMargin = 2;
    Crossing operator()(const DenseBlock& b, int x, int y, int z, int axis) const {
        return sharp_crossing(b, x, y, z, axis);
    }
};

/// Calls body(oracle) with the grid oracle for resolved `normals` (what
/// auto_parameters.cpp chose), for both drivers.
struct GridOracles {
    template <class Body>
    auto operator()(GridNormals normals, const Body& body) const {
        switch (normals) {
            case GridNormals::sharp: return body(SharpOracle{});
            case GridNormals::least_squares: return body(LeastSquaresOracle{});
            default: return body(LinearOracle{});
        }
    }
};

/// Procedural fields: crossings by root finding on the exact field along the
/// edge (to 1e-12 of its length), normals from the analytic gradient mapped
/// to index space.
struct ExactOracle {
    static constexpr int kMargin = 1;
    const ScalarField& field;
    const openvdb::math::Transform& xf;

    Crossing operator()(const DenseBlock& b, int x, int y, int z, int axis) const {
        const openvdb::Coord p0 = b.min + openvdb::Coord(x, y, z);
        openvdb::Vec3d i0 = p0.asVec3d(), i1 = i0;
        i1[axis] += 1.0;
        const openvdb::Vec3d w0 = xf.indexToWorld(i0), w1 = xf.indexToWorld(i1);
        const double f0 = field.value(w0), f1 = field.value(w1);
        Crossing c;
        if ((f0 < 0) != (f1 < 0) && std::isfinite(f0) && std::isfinite(f1)) {
            c.t = root_on_unit_interval([&](double t) { return field.value(w0 + (w1 - w0) * t); }, f0, f1, 1e-12);
        } else {
            // The float samples disagree with the exact field near a tangency;
            // stay consistent with the sampled signs.
            c.t = linear_crossing(b, x, y, z, axis).t;
        }
        const openvdb::Vec3d w = w0 + (w1 - w0) * c.t;
        const openvdb::Vec3d g = xf.baseMap()->applyJT(field.gradient(w));
        c.normal = normalized_or_zero({g.x(), g.y(), g.z()});
        return c;
    }
};

}  // namespace pqdc::detail
