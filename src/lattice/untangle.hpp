// Stage "untangle" (the uniform extractor; the octree has no proven safe
// positions yet): moves vertices of
// self-intersecting or degenerate faces towards per-vertex safe positions
// until the mesh is free of self-intersections (as find_self_intersections
// decides it, exactly).
//
// Contract. The caller gives one safe position per vertex such that the mesh
// with EVERY vertex at its safe position has no intersecting pair and no
// degenerate triangle (the drivers argue this for their positions; see
// safe_positions.hpp and the README's section on quality). Then:
//  - Whether two triangles intersect depends only on their six corners. If
//    all six sit at their safe positions the pair is a pair of the all-safe
//    mesh, so it does not intersect (same for a degenerate triangle's three
//    corners). Hence every offending pair has a corner that is not yet safe.
//  - Each round moves every such corner one step along the segment from its
//    original position to its safe one: half way, three quarters, then all
//    the way (kPartialSteps partial steps, then a snap). A snapped vertex
//    never moves again.
//  - So each round either finds nothing (done) or advances at least one
//    vertex by one of its kPartialSteps + 1 steps: the loop ends after at
//    most (kPartialSteps + 1) * V rounds, in practice after 1-5, and the
//    result is free of self-intersections.
// Partial steps first because most intersections are shallow folds that a
// small move removes, keeping the vertex close to its feature-preserving
// minimizer; the snap is the guarantee.
//
// Checks. The first round runs the exact finder on the whole mesh. Later
// rounds re-test only what can have changed: pairs with a triangle that
// touches a moved vertex. Candidates are the triangles whose bounding boxes
// share a hashed grid cell (of `cell_size`) with a moved triangle's box, a
// superset of those that can meet one; the exact finder runs on them.
// A driver that knows its mesh's structure can do both faster with the
// same result (UntangleSettings::whole_mesh_check and moved_check: the
// uniform driver's quad stars, uniform/quad_star_check.hpp).
#pragma once

#include "lattice/transform.hpp"
#include "pqdc/mesh.hpp"
#include "pqdc/self_intersections.hpp"
#include "pqdc/stats.hpp"

#include <openvdb/openvdb.h>

#include <cstdint>
#include <functional>
#include <vector>

namespace pqdc::detail {

struct UntangleCounters {
    std::uint64_t pairs_before = 0;       ///< intersecting pairs found by the first check
    std::uint64_t degenerate_before = 0;  ///< degenerate (and non-finite) triangles found by the first check
    std::uint64_t moved_vertices = 0;     ///< vertices moved at least once
    std::uint64_t snapped_vertices = 0;   ///< vertices moved all the way to their safe position
    std::uint64_t rounds = 0;             ///< checks that found something to repair
    std::uint64_t unresolved = 0;         ///< offending pairs + triangles left (0 when the contract holds)

    UntangleCounters& operator+=(const UntangleCounters& o) {
        pairs_before += o.pairs_before;
        degenerate_before += o.degenerate_before;
        moved_vertices += o.moved_vertices;
        snapped_vertices += o.snapped_vertices;
        rounds += o.rounds;
        unresolved += o.unresolved;
        return *this;
    }
    /// Adds the counters to stats.untangle_* (found: pairs and degenerate triangles).
    void add_to(ExtractStats& stats) const {
        stats.untangle_found += pairs_before + degenerate_before;
        stats.untangle_moved += moved_vertices;
        stats.untangle_snapped += snapped_vertices;
        stats.untangle_rounds += rounds;
    }
};

struct UntangleSettings {
    /// With float32 the mesh must be free of intersections after rounding
    /// its points to float (only the rounded points are checked, not the
    /// double ones); the all-safe mesh is assumed to stay so after rounding,
    /// which holds
    /// while coordinates are below 2^20 voxels (float's spacing is then below
    /// an eighth of a voxel, far below the gaps between the all-safe mesh's
    /// faces that share no corner). Default float64.
    VertexPrecision stored = VertexPrecision::float64;
    /// Called from the calling thread with the fraction of the first
    /// (whole-mesh) check done, then with 1 during repair rounds: the
    /// cancellation points. It may throw (the drivers' Progress does) or
    /// return false (find_self_intersections then throws cancelled_error).
    /// Default: none.
    std::function<bool(double)> progress;
    /// The check of the whole mesh: what find_self_intersections_at(mesh,
    /// points, options) returns, found some faster way where the mesh's
    /// origin allows (the uniform driver: uniform/quad_star_check.hpp).
    /// Default: that function itself.
    std::function<SelfIntersections(const Mesh&, const std::vector<openvdb::Vec3d>&, const SelfIntersectionOptions&)>
        whole_mesh_check;
    /// The check after a round of moves, where the mesh's origin allows: it
    /// sets `found` to every intersecting pair with a triangle at one of the
    /// (sorted) moved vertices and every degenerate or non-finite such
    /// triangle, at `points`, and returns true; false leaves the round to
    /// untangle's own check (the triangles near the moved ones, through a
    /// hashed grid). Both find the mesh's every offending pair: before the
    /// moves every one was found, and each found pair had its corners moved
    /// (or all snapped, when it cannot offend). Default: none.
    std::function<bool(const std::vector<openvdb::Vec3d>& points, const std::vector<std::uint32_t>& moved,
                       SelfIntersections& found)>
        moved_check;
};

/// The points as they will be stored: rounded to float for float32 output
/// (what the checks look at), else a copy.
std::vector<openvdb::Vec3d> points_as_stored(const std::vector<openvdb::Vec3d>& points, VertexPrecision stored);

/// Number of partial steps before the snap (fractions 1/2, 3/4).
constexpr int kPartialSteps = 2;

/// A point's safe position, in the points' space. Asked for the moved
/// points only, so a driver may compute it instead of holding one per point.
using SafePosition = std::function<openvdb::Vec3d(std::uint32_t point)>;

/// Repairs `mesh` in place (points only; faces and their order unchanged).
/// `safe` gives every point's safe position; `cell_size` is the lattice
/// spacing in the points' space (for the candidate hash only). Returns true
/// when the result is free of self-intersections; false only when the safe
/// positions break the contract (then counters.unresolved > 0).
bool untangle(Mesh& mesh, const SafePosition& safe, double cell_size, const UntangleSettings& settings,
              UntangleCounters& counters);
/// untangle() with the safe positions held, one per point.
bool untangle(Mesh& mesh, const std::vector<openvdb::Vec3d>& safe, double cell_size,
              const UntangleSettings& settings, UntangleCounters& counters);

/// The warning of a repair that could not finish (counters.unresolved > 0),
/// into stats.warnings: with float32 output, coordinates too large for
/// float's spacing; otherwise a bug to report.
void warn_unresolved(const UntangleCounters& counters, VertexPrecision stored, ExtractStats& stats);

/// untangle() for a driver: world-space points, the lattice spacing from
/// the transform; adds the counters to stats.untangle_* (and
/// warn_unresolved()). Returns untangle()'s result.
bool untangle_mesh(Mesh& mesh, const SafePosition& safe, const LatticeTransform& xf,
                   const UntangleSettings& settings, ExtractStats& stats);

/// What an exact check of a mesh found, at the precision it will be stored in.
struct OffendingCorners {
    std::uint64_t pairs = 0;       ///< intersecting triangle pairs
    std::uint64_t degenerate = 0;  ///< degenerate and non-finite triangles
    /// The corners of every triangle in such a pair or degenerate, each once, sorted.
    std::vector<std::uint32_t> vertices;
    bool none() const { return pairs == 0 && degenerate == 0; }
};

/// The check untangle() starts with, for drivers that repair otherwise (the
/// adaptive one refines its octree). settings.progress as for untangle().
OffendingCorners find_offending_corners(const Mesh& mesh, const UntangleSettings& settings);

/// The offending (intersecting or degenerate) pairs + triangles of `mesh`
/// with every vertex at `safe`; 0 when the positions meet the contract.
std::uint64_t count_unsafe(const Mesh& mesh, const std::vector<openvdb::Vec3d>& safe);

}  // namespace pqdc::detail
