// Exact geometric predicates for triangle meshes with double coordinates:
// orientation tests and triangle-triangle intersection, including triangles
// that share a vertex or an edge (mesh neighbours), where "intersect" means
// "meet anywhere other than at what they share".
//
// Orientations are filtered (Shewchuk, "Adaptive Precision Floating-Point
// Arithmetic and Fast Robust Geometric Predicates", 1997: the static error
// bounds of orient2d/orient3d stage A) with an exact fallback in rational
// arithmetic (boost::multiprecision::cpp_rational; every double converts
// exactly), so every answer is the one exact arithmetic gives. The
// intersection tests are built only from these signs (no constructed
// points), so they are exact too; only degenerate (zero-area) triangles
// make them answer "intersect" without deciding, so a caller that refuses
// on "intersect" stays safe.
#pragma once

#include "pqdc/vec3.hpp"

namespace pqdc::exact {

using point = vec3<double>;

/// Sign (+1, -1, 0) of det[a - d, b - d, c - d]: which side of the plane
/// through a, b, c the point d is on.
int orient3d(const point& a, const point& b, const point& c, const point& d);

/// Sign of det[a - c, b - c] for 2D points.
int orient2d(double ax, double ay, double bx, double by, double cx, double cy);

/// Closed triangles t and u (no shared vertices) have a common point.
bool triangles_intersect(const point t[3], const point u[3]);

/// Triangles (s, a, b) and (s, c, d) sharing exactly the vertex s meet
/// somewhere other than s.
bool triangles_intersect_sharing_vertex(const point& s, const point& a, const point& b, const point& c,
                                        const point& d);

/// Triangles (s, t, a) and (s, t, c) sharing exactly the edge s-t overlap
/// beyond it (they are coplanar and fold onto each other).
bool triangles_overlap_sharing_edge(const point& s, const point& t, const point& a, const point& c);

}  // namespace pqdc::exact
