// Exact geometric predicates for triangle meshes with double coordinates:
// orientation tests and triangle-triangle intersection, including triangles
// that share a vertex or an edge (mesh neighbours), where "intersect" means
// "meet anywhere other than at what they share".
//
// The orientations are the shared exact ones (geometry/exact_predicates.hpp:
// Shewchuk's filters, then expansions or integers), on this module's point
// type. The intersection tests are built only from these signs (no
// constructed points), so they are exact too; only degenerate (zero-area)
// triangles make them answer "intersect" without deciding, so a caller that
// refuses on "intersect" stays safe. Files including this header are
// compiled with -ffp-contract=off (the filters' error bounds need it).
#pragma once

#include "geometry/exact_predicates.hpp"
#include "pqdc/vec3.hpp"

#include <cmath>
#include <limits>

namespace pqdc::exact {

using point = vec3<double>;

/// Sign (+1, -1, 0) of det[a - d, b - d, c - d]: which side of the plane
/// through a, b, c the point d is on; 0 for non-finite input.
inline int orient3d(const point& a, const point& b, const point& c, const point& d) {
    auto v = [](const point& p) { return openvdb::Vec3d(p.x, p.y, p.z); };
    return detail::orient3d(v(a), v(b), v(c), v(d));
}

/// Sign of det[a - c, b - c] for 2D points.
inline int orient2d(double ax, double ay, double bx, double by, double cx, double cy) {
    return detail::orient2d(ax, ay, bx, by, cx, cy);
}

/// Closed triangles t and u (no shared vertices) have a common point.
bool triangles_intersect(const point t[3], const point u[3]);

/// Triangles (s, a, b) and (s, c, d) sharing exactly the vertex s meet
/// somewhere other than s.
bool triangles_intersect_sharing_vertex(const point& s, const point& a, const point& b, const point& c,
                                        const point& d);

/// Triangles (s, t, a) and (s, t, c) sharing exactly the edge s-t overlap
/// beyond it (they are coplanar and fold onto each other).
bool triangles_overlap_sharing_edge(const point& s, const point& t, const point& a, const point& c);

/// Fast half of orient3d for many points against one plane: the plane's
/// cross product is formed once, and each point costs one dot product and
/// Shewchuk's stage-A error bound (the same expression shape as orient3d's,
/// with the triangle's first corner as the reference point). Answers only
/// what the bound certifies; 0 means "near the plane, ask orient3d".
struct plane_filter {
    point a{}, n{}, perm{};
    explicit plane_filter(const point t[3]) : a(t[0]) {
        const point e1 = t[1] - t[0], e2 = t[2] - t[0];
        const double xy = e1.y * e2.z, yx = e1.z * e2.y, zx = e1.z * e2.x, xz = e1.x * e2.z, xy2 = e1.x * e2.y,
                     yx2 = e1.y * e2.x;
        n = {xy - yx, zx - xz, xy2 - yx2};
        perm = {std::fabs(xy) + std::fabs(yx), std::fabs(zx) + std::fabs(xz), std::fabs(xy2) + std::fabs(yx2)};
    }
    /// +1 / -1: q is certainly strictly on that side (one fixed convention
    /// per plane); 0: undecided.
    int side(const point& q) const {
        constexpr double eps = std::numeric_limits<double>::epsilon() / 2;
        constexpr double bound = (7.0 + 56.0 * eps) * eps;
        const double vx = q.x - a.x, vy = q.y - a.y, vz = q.z - a.z;
        const double det = vx * n.x + vy * n.y + vz * n.z;
        const double err = bound * (std::fabs(vx) * perm.x + std::fabs(vy) * perm.y + std::fabs(vz) * perm.z);
        return det > err ? 1 : (-det > err ? -1 : 0);
    }
};

}  // namespace pqdc::exact
