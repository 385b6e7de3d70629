// Adaptive stage "polygons": feature-aware tangential relaxation, before the
// angle flips. Dual marching cubes on an octree puts vertices of cells of
// different sizes close together along sharp edges and where merged cells
// meet, which makes needles and caps that no flip can fix (flips may not
// cross a crease). Each vertex moves towards the centroid of its neighbours,
// but only along the directions in which its triangles' normals do not
// change: in the tangent plane on flat parts, along the edge on a crease,
// not at all at a corner (the normal tensor of Hildebrandt & Polthier 2007,
// "Constraint-based fairing of surface meshes"; as in the tangential
// smoothing of remeshers, Botsch & Kobbelt 2004). So the surface and its
// features stay where the quadrics put them, to first order.
#pragma once

#include <openvdb/openvdb.h>

#include <cstdint>
#include <vector>

namespace pqdc::adaptive_detail {

/// Limits of relax_tangentially. The defaults were chosen on bench_quality's
/// suite (see the .cpp).
struct RelaxLimits {
    /// Jacobi sweeps (>= 0; 0 switches the step off).
    int sweeps = 2;
    /// Fraction of the projected move to the neighbours' centroid taken per
    /// sweep, (0, 1].
    double step = 0.5;
    /// A direction is free when the normal tensor's eigenvalue along it is
    /// below this fraction of the largest, (0, 1): one free direction is a
    /// crease, none a corner.
    double free_ratio = 0.02;
    /// Largest move of a vertex per sweep, in voxels (the points are in index
    /// space), > 0: a tangential move leaves a curved surface by about
    /// move^2 * curvature.
    double max_move_voxels = 0.25;
    /// A move is refused when it turns one of the vertex's triangles by more
    /// than this, degrees, (0, 90).
    double max_turn_degrees = 30;
};

/// Moves the `movable` vertices of the alive triangles `tris` (points in
/// index space) as described in the file comment, all at once per sweep
/// (each from the positions of the previous sweep: the result does not
/// depend on threads). Left where they are besides: vertices of a boundary
/// or non-manifold edge, and any vertex whose move would turn one of its
/// triangles too far or make one degenerate. Returns the number of vertices
/// moved at least once.
std::size_t relax_tangentially(std::vector<openvdb::Vec3d>& points, const std::vector<openvdb::Vec3I>& tris,
                               const std::vector<std::uint8_t>& alive, const std::vector<std::uint8_t>& movable,
                               const RelaxLimits& limits = {});

}  // namespace pqdc::adaptive_detail
