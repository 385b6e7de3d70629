// The triangle-triangle tests built on the exact orientation predicates
// (geometry/exact_predicates.hpp). Triangle-triangle: two non-coplanar triangles meet iff an edge
// of one meets the other (the intersection is a segment on the planes'
// common line whose end points lie on edges), as in Guigue & Devillers,
// "Fast and robust triangle-triangle overlap test using orientation
// predicates" (2003); coplanar pairs are decided in the projection that
// drops the normal's largest coordinate. Neighbours sharing a vertex s are
// tested on the sides opposite s (non-coplanar) or on their wedges at s
// (coplanar), the two cases of CGAL's Polygon_mesh_processing
// self-intersection test for adjacent faces.

#include "exact_predicates.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace pqdc::exact {
namespace {

struct p2 {
    double x, y;
};

int o2(const p2& a, const p2& b, const p2& c) { return orient2d(a.x, a.y, b.x, b.y, c.x, c.y); }

/// Drops the coordinate where the normal of (a, b, c) is largest; for
/// coplanar input this keeps every 2D orientation (up to one global sign).
int dominant_axis(const point& a, const point& b, const point& c) {
    const point n = cross(b - a, c - a);
    const double x = std::fabs(n.x), y = std::fabs(n.y), z = std::fabs(n.z);
    if (!(x > 0 || y > 0 || z > 0)) return -1;
    return x >= y && x >= z ? 0 : (y >= z ? 1 : 2);
}

p2 project(const point& p, int axis) {
    return axis == 0 ? p2{p.y, p.z} : (axis == 1 ? p2{p.z, p.x} : p2{p.x, p.y});
}

bool on_segment(const p2& a, const p2& b, const p2& p) {  // p collinear with a, b
    return std::fmin(a.x, b.x) <= p.x && p.x <= std::fmax(a.x, b.x) && std::fmin(a.y, b.y) <= p.y &&
           p.y <= std::fmax(a.y, b.y);
}

bool segments_meet_2d(const p2& a, const p2& b, const p2& c, const p2& d) {
    const int o1 = o2(a, b, c), o2_ = o2(a, b, d), o3 = o2(c, d, a), o4 = o2(c, d, b);
    if (o1 * o2_ < 0 && o3 * o4 < 0) return true;
    return (o1 == 0 && on_segment(a, b, c)) || (o2_ == 0 && on_segment(a, b, d)) ||
           (o3 == 0 && on_segment(c, d, a)) || (o4 == 0 && on_segment(c, d, b));
}

bool point_in_triangle_2d(const p2& p, const p2& a, const p2& b, const p2& c) {  // closed
    const int s1 = o2(a, b, p), s2 = o2(b, c, p), s3 = o2(c, a, p);
    return !((s1 < 0 || s2 < 0 || s3 < 0) && (s1 > 0 || s2 > 0 || s3 > 0));
}

bool triangles_meet_2d(const p2 t[3], const p2 u[3]) {
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            if (segments_meet_2d(t[i], t[(i + 1) % 3], u[j], u[(j + 1) % 3])) return true;
    return point_in_triangle_2d(t[0], u[0], u[1], u[2]) || point_in_triangle_2d(u[0], t[0], t[1], t[2]);
}

/// Closed segment p-q and closed triangle t have a common point, given the
/// sides op, oq of p and q: orient3d(t[0], t[1], t[2], p or q).
bool segment_meets_triangle(const point& p, const point& q, const point t[3], int op, int oq) {
    if (op == oq && op != 0) return false;
    if (op == 0 && oq == 0) {
        const int axis = dominant_axis(t[0], t[1], t[2]);
        if (axis < 0) return true;  // degenerate triangle: undecided, say yes
        const p2 a = project(p, axis), b = project(q, axis);
        const p2 tt[3] = {project(t[0], axis), project(t[1], axis), project(t[2], axis)};
        for (int i = 0; i < 3; ++i)
            if (segments_meet_2d(a, b, tt[i], tt[(i + 1) % 3])) return true;
        return point_in_triangle_2d(a, tt[0], tt[1], tt[2]);
    }
    const int s1 = orient3d(p, q, t[0], t[1]), s2 = orient3d(p, q, t[1], t[2]), s3 = orient3d(p, q, t[2], t[0]);
    return !((s1 < 0 || s2 < 0 || s3 < 0) && (s1 > 0 || s2 > 0 || s3 > 0));
}

}  // namespace

bool triangles_intersect(const point t[3], const point u[3]) {
    const int u0 = orient3d(t[0], t[1], t[2], u[0]), u1 = orient3d(t[0], t[1], t[2], u[1]),
              u2 = orient3d(t[0], t[1], t[2], u[2]);
    if (u0 == u1 && u1 == u2 && u0 != 0) return false;  // u strictly on one side of t's plane
    const int t0 = orient3d(u[0], u[1], u[2], t[0]), t1 = orient3d(u[0], u[1], u[2], t[1]),
              t2 = orient3d(u[0], u[1], u[2], t[2]);
    if (t0 == t1 && t1 == t2 && t0 != 0) return false;
    if (u0 == 0 && u1 == 0 && u2 == 0) {  // coplanar
        const int axis = dominant_axis(t[0], t[1], t[2]);
        if (axis < 0) return true;
        const p2 tt[3] = {project(t[0], axis), project(t[1], axis), project(t[2], axis)};
        const p2 uu[3] = {project(u[0], axis), project(u[1], axis), project(u[2], axis)};
        return triangles_meet_2d(tt, uu);
    }
    // The edges' end point sides are the orientations above.
    const int ts[3] = {t0, t1, t2}, us[3] = {u0, u1, u2};
    for (int i = 0; i < 3; ++i) {
        if (segment_meets_triangle(t[i], t[(i + 1) % 3], u, ts[i], ts[(i + 1) % 3])) return true;
        if (segment_meets_triangle(u[i], u[(i + 1) % 3], t, us[i], us[(i + 1) % 3])) return true;
    }
    return false;
}

bool triangles_intersect_sharing_vertex(const point& s, const point& a, const point& b, const point& c,
                                        const point& d) {
    const int oa = orient3d(s, c, d, a), ob = orient3d(s, c, d, b);
    if (oa == 0 && ob == 0) {
        // Coplanar: near s each triangle is its wedge (a convex cone at s),
        // and two such cones meet beyond s iff a side ray of one lies in the
        // other (their intersection is a cone bounded by their side rays).
        const int axis = dominant_axis(s, a, b);
        if (axis < 0) return true;
        const p2 S = project(s, axis), A = project(a, axis), B = project(b, axis), C = project(c, axis),
                 D = project(d, axis);
        auto in_cone = [&](const p2& u, const p2& v, const p2& r) {
            const int sigma = o2(S, u, v);
            return sigma == 0 || (sigma * o2(S, u, r) >= 0 && sigma * o2(S, r, v) >= 0);
        };
        return in_cone(C, D, A) || in_cone(C, D, B) || in_cone(A, B, C) || in_cone(A, B, D);
    }
    // Not coplanar: the planes meet in a line L through s, and each triangle
    // meets L in a segment from s to a point of its side opposite s (or in s
    // alone). They overlap beyond s iff one of those far points lies in the
    // other triangle, i.e. iff a side opposite s meets the other triangle.
    if (oa == ob) return false;  // a and b strictly on one side: T1 touches T2's plane only at s
    const int oc = orient3d(s, a, b, c), od = orient3d(s, a, b, d);
    if (oc == od && oc != 0) return false;
    const point t1[3] = {s, a, b}, t2[3] = {s, c, d};
    // The sides are those computed above (same arguments, same order).
    return segment_meets_triangle(a, b, t2, oa, ob) || segment_meets_triangle(c, d, t1, oc, od);
}

bool triangles_overlap_sharing_edge(const point& s, const point& t, const point& a, const point& c) {
    if (orient3d(s, t, a, c) != 0) return false;
    const int axis = dominant_axis(s, t, a);
    if (axis < 0) return true;
    const p2 S = project(s, axis), T = project(t, axis), A = project(a, axis), C = project(c, axis);
    const int sa = o2(S, T, A), sc = o2(S, T, C);
    return sa == 0 || sc == 0 || sa == sc;
}

}  // namespace pqdc::exact
