// Exact orientation predicates on double coordinates (internal).
//
// Each returns the sign (+1, 0, -1) of a determinant of coordinate
// differences, exactly, for any finite doubles: first evaluated in floating
// point and accepted when its magnitude exceeds Shewchuk's proven forward
// error bound ("Adaptive Precision Floating-Point Arithmetic and Fast Robust
// Geometric Predicates", 1997, the stage-A bounds of orient2d/orient3d),
// else recomputed in exact integer arithmetic (every double is an integer
// times a power of two).
#pragma once

#include <openvdb/Types.h>

namespace pqdc {
namespace detail {

/// Sign of det [a - d; b - d; c - d] (rows): positive when d lies below the
/// plane through a, b, c, "below" being the side from which a, b, c appear
/// clockwise.
int orient3d(const openvdb::Vec3d& a, const openvdb::Vec3d& b, const openvdb::Vec3d& c, const openvdb::Vec3d& d);

/// Sign of det [a - c; b - c]: positive when a, b, c are counter-clockwise.
int orient2d(double ax, double ay, double bx, double by, double cx, double cy);

/// The same signs computed in exact arithmetic only (no filter); for tests.
int orient3d_exact(const openvdb::Vec3d& a, const openvdb::Vec3d& b, const openvdb::Vec3d& c, const openvdb::Vec3d& d);
int orient2d_exact(double ax, double ay, double bx, double by, double cx, double cy);

}  // namespace detail
}  // namespace pqdc
