// Exact detection of self-intersections in a polygon mesh.
//
//   pqdc::SelfIntersections si = pqdc::find_self_intersections(mesh);
//   if (si.pair_count > 0 || !si.degenerate_triangles.empty()) ...
//
// The mesh is read as triangles in the numbering of the other measures
// (include/pqdc/measure.hpp): the triangles 0..T-1, then each quad q as the
// triangles T + 2q (corners 0-1-2) and T + 2q + 1 (corners 0-2-3). Two
// triangles intersect when they share any point other than a shared edge or
// shared vertex, sharing meaning the same point index: coplanar overlaps,
// touching at a point and duplicated faces all count, and so do two corners
// at the same position under different indices (weld a triangle soup first).
// The two halves of a quad share its 0-2 diagonal, so a quad counts as
// intersecting itself only when it folds over that diagonal.
//
// Exact for any finite double coordinates: every decision is the sign of an
// orientation determinant, taken from a floating-point evaluation when a
// proven error bound (Shewchuk 1997) allows and from exact integer
// arithmetic otherwise. Candidate pairs come from a uniform grid of the
// triangles' boxes, or from a bounding-box tree for meshes of very unequal
// triangles; the tests run in parallel (TBB) and the result is the same for
// any thread count.
#pragma once

#include "pqdc/mesh.hpp"

#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <utility>
#include <vector>

namespace pqdc {

/// How candidate pairs are found. Changes speed only, never the result.
enum class BroadPhase {
    automatic,  ///< the grid when the triangles suit it (similar sizes), else the tree
    tree,       ///< always the bounding-box tree
    grid,       ///< reported in SelfIntersections::broad_phase only
};

struct SelfIntersectionOptions {
    /// Default automatic; grid is not accepted here (the grid may not suit).
    BroadPhase broad_phase = BroadPhase::automatic;
    /// Most triangles per leaf of the bounding-box tree. Changes speed and
    /// memory only, never the result. Range [1, 64]. Default 4.
    int leaf_triangles = 4;
    /// Most pairs kept in SelfIntersections::pairs (the first ones in sorted
    /// order); pair_count always counts all of them. Range >= 0. Default: all.
    std::size_t max_pairs = std::numeric_limits<std::size_t>::max();
    /// The points as tested: float64 (default) as they are; float32 each
    /// rounded to the nearest float first, as a float file stores them
    /// (a mesh free of intersections in double can cross once rounded).
    VertexPrecision stored_precision = VertexPrecision::float64;
    /// Called from the calling thread with the fraction of the tests done
    /// (0..1, about 64 times); returning false stops the search, which then
    /// throws cancelled_error. Default: none.
    std::function<bool(double)> progress;
};

struct SelfIntersections {
    std::size_t triangle_count = 0;  ///< triangles examined (triangles + 2 quads)
    /// Intersecting pairs of non-degenerate triangles.
    std::size_t pair_count = 0;
    /// (first, second) triangle numbers, first < second, sorted
    /// lexicographically; at most options.max_pairs of them.
    std::vector<std::pair<std::size_t, std::size_t>> pairs;
    /// Triangles with a repeated point index or three collinear (or
    /// coincident) corners, sorted. They have no interior and no well-defined
    /// sides, so they take no part in the pair tests (as in CGAL's
    /// Polygon_mesh_processing::self_intersections, which reports each as the
    /// pair (f, f)).
    std::vector<std::size_t> degenerate_triangles;
    /// Triangles with a NaN or infinite corner coordinate: not tested.
    std::size_t non_finite_triangle_count = 0;
    /// The broad phase that ran: grid or tree.
    BroadPhase broad_phase = BroadPhase::tree;

    /// No intersecting pair, no degenerate and no non-finite triangle.
    bool none() const { return pair_count == 0 && degenerate_triangles.empty() && non_finite_triangle_count == 0; }
};

/// Throws input_error when a face refers to a point that does not exist,
/// option_error for invalid options, cancelled_error when options.progress
/// returns false.
SelfIntersections find_self_intersections(const Mesh& mesh, const SelfIntersectionOptions& options = {});

/// The face (triangles first, then quads, as TopologyReport counts them)
/// that triangle number t of find_self_intersections belongs to.
inline std::size_t face_of_triangle(const Mesh& mesh, std::size_t t) {
    return t < mesh.triangles.size() ? t : mesh.triangles.size() + (t - mesh.triangles.size()) / 2;
}

/// Compact JSON object: triangle_count, pair_count,
/// degenerate_triangle_count, non_finite_triangle_count and the first (up
/// to) 10 pairs as first_pairs: [[first, second], ...].
std::string to_json(const SelfIntersections& result);

}  // namespace pqdc
