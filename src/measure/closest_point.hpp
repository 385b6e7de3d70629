// Closest points on triangles, shared by MeshDistance (measure) and the
// decimation's normal transfer: which part of the triangle the point lies
// on (for pseudo-normals) and its barycentric weights (for interpolating
// vertex attributes).
#pragma once

#include <openvdb/Types.h>

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace pqdc::closest_point {

using openvdb::Vec3d;

/// Which part of a triangle a closest point lies on; the sign of a distance
/// comes from that part's pseudo-normal.
enum class Feature : std::uint8_t { vertex_a, vertex_b, vertex_c, edge_ab, edge_bc, edge_ca, face };

struct ClosestPoint {
    Vec3d point;
    Feature feature;
};

inline ClosestPoint closest_on_segment(const Vec3d& p, const Vec3d& a, const Vec3d& b, Feature at_a,
                                       Feature at_b, Feature inside) {
    const Vec3d ab = b - a;
    const double len2 = ab.lengthSqr();
    const double t = ab.dot(p - a);
    if (!(t > 0.0) || !(len2 > 0.0)) return {a, at_a};
    if (t >= len2) return {b, at_b};
    return {a + ab * (t / len2), inside};
}

/// The nearest point of the three sides.
inline ClosestPoint closest_on_sides(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    ClosestPoint best = closest_on_segment(p, a, b, Feature::vertex_a, Feature::vertex_b, Feature::edge_ab);
    for (const ClosestPoint& q : {closest_on_segment(p, b, c, Feature::vertex_b, Feature::vertex_c, Feature::edge_bc),
                                  closest_on_segment(p, c, a, Feature::vertex_c, Feature::vertex_a, Feature::edge_ca)})
        if ((q.point - p).lengthSqr() < (best.point - p).lengthSqr()) best = q;
    return best;
}

/// For well-shaped triangles (see is_thin). Ericson, Real-Time Collision
/// Detection, 5.1.5: the Voronoi regions of the corners, sides and interior
/// in turn. Its region tests are differences of products of dot products,
/// whose rounding grows as 1 / thinness^2.
inline ClosestPoint closest_on_triangle(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    const Vec3d ab = b - a, ac = c - a, ap = p - a;
    const double d1 = ab.dot(ap), d2 = ac.dot(ap);
    if (d1 <= 0 && d2 <= 0) return {a, Feature::vertex_a};
    const Vec3d bp = p - b;
    const double d3 = ab.dot(bp), d4 = ac.dot(bp);
    if (d3 >= 0 && d4 <= d3) return {b, Feature::vertex_b};
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) return {a + ab * (d1 / (d1 - d3)), Feature::edge_ab};
    const Vec3d cp = p - c;
    const double d5 = ab.dot(cp), d6 = ac.dot(cp);
    if (d6 >= 0 && d5 <= d6) return {c, Feature::vertex_c};
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) return {a + ac * (d2 / (d2 - d6)), Feature::edge_ca};
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0)
        return {b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6))), Feature::edge_bc};
    const double denom = 1.0 / (va + vb + vc);
    return {a + ab * (vb * denom) + ac * (vc * denom), Feature::face};
}

/// Thin and zero-area triangles: the nearest point of the sides, or the foot
/// of p on the plane when it falls inside. Inside is decided by the signs of
/// triple products, which do not cancel like Ericson's region tests, and
/// the plane offset is measured from the nearest side point (in the plane,
/// next to the foot), so the normal's large relative rounding across a
/// sliver tilts it by almost nothing: errors stay near rounding of the
/// coordinates at any thinness.
inline ClosestPoint closest_on_thin_triangle(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    const ClosestPoint side = closest_on_sides(p, a, b, c);
    const Vec3d n = (b - a).cross(c - a);
    const double n2 = n.lengthSqr();
    if (!(n2 > 0.0) || !std::isfinite(n2)) return side;
    const Vec3d pa = a - p, pb = b - p, pc = c - p;
    if (!(n.dot(pb.cross(pc)) > 0 && n.dot(pc.cross(pa)) > 0 && n.dot(pa.cross(pb)) > 0)) return side;
    const Vec3d unit = n / std::sqrt(n2);
    const Vec3d foot = p - unit * unit.dot(p - side.point);
    if ((foot - p).lengthSqr() < (side.point - p).lengthSqr()) return {foot, Feature::face};
    return side;
}

/// Thin: twice the area below a tenth of the longest side squared (the
/// height onto that side below a tenth of its length), zero-area, or so
/// large that the squares overflow. Above that, Ericson's rounding (about
/// 1e-16 / thinness^2 of the triangle's size) stays below 1e-14, and none
/// of its divisions can be 0 / 0.
inline bool is_thin(const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    const double longest2 = std::max({(b - a).lengthSqr(), (c - b).lengthSqr(), (a - c).lengthSqr()});
    const double bound = 0.01 * longest2 * longest2;
    return !((b - a).cross(c - a).lengthSqr() >= bound) || !std::isfinite(bound);
}

/// Barycentric weights (of a, b, c) of a closest point of triangle a-b-c:
/// exact one-hot and two-sided weights at corners and on sides (where the
/// triangle may be degenerate), from sub-triangle areas along its normal
/// inside it.
inline Vec3d barycentric_weights(const Vec3d& a, const Vec3d& b, const Vec3d& c, const ClosestPoint& q) {
    auto along = [&q](const Vec3d& from, const Vec3d& to) {
        const Vec3d d = to - from;
        const double len2 = d.lengthSqr();
        return len2 > 0.0 ? std::clamp(d.dot(q.point - from) / len2, 0.0, 1.0) : 0.0;
    };
    double t = 0;
    switch (q.feature) {
        case Feature::vertex_a: return {1, 0, 0};
        case Feature::vertex_b: return {0, 1, 0};
        case Feature::vertex_c: return {0, 0, 1};
        case Feature::edge_ab: t = along(a, b); return {1 - t, t, 0};
        case Feature::edge_bc: t = along(b, c); return {0, 1 - t, t};
        case Feature::edge_ca: t = along(c, a); return {t, 0, 1 - t};
        case Feature::face: break;
    }
    const Vec3d n = (b - a).cross(c - a);
    const Vec3d w(std::max(0.0, n.dot((b - q.point).cross(c - q.point))),
                  std::max(0.0, n.dot((c - q.point).cross(a - q.point))),
                  std::max(0.0, n.dot((a - q.point).cross(b - q.point))));
    const double sum = w[0] + w[1] + w[2];
    return sum > 0.0 && std::isfinite(sum) ? w / sum : Vec3d(1.0 / 3.0);
}

/// The closest point of triangle a-b-c to p (Ericson's regions, or the
/// thin-triangle variant where those round badly).
inline ClosestPoint closest_on_any_triangle(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    return is_thin(a, b, c) ? closest_on_thin_triangle(p, a, b, c) : closest_on_triangle(p, a, b, c);
}

}  // namespace pqdc::closest_point
