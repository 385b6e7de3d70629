// Mesh decimation by edge collapses to the minimizer of summed probabilistic
// quadrics (Trettner & Kobbelt 2020, section 4.2; Garland & Heckbert 1997).
//
//   pqdc::DecimateOptions o;
//   o.target_ratio = 0.1;            // keep 10% of the faces
//   o.voxel_size = grid_voxel_size;  // sigmas and distances are in voxels
//   pqdc::DecimateStats s;
//   pqdc::decimate(mesh, o, &s);
//
// What the result guarantees (for any input that is accepted):
//   - Only edges whose two end points are manifold interior vertices (one
//     closed, consistently oriented fan) collapse. Boundary vertices,
//     vertices on non-manifold edges and non-manifold vertices are kept
//     exactly where they are, so open and non-manifold input is decimated
//     away from those places and left as it was there.
//   - Every collapse satisfies the link condition and leaves no vertex of
//     valence < 3, so a closed manifold keeps its genus and component count
//     and stays closed and edge-manifold.
//   - No face normal turns by more than max_normal_change_degrees and no
//     triangle of quality below min_triangle_quality is created (unless the
//     faces it replaces were already worse).
//   - No self-intersection is created: each collapse's new triangles are
//     tested with exact predicates against every triangle near them and
//     against the other collapses of the same pass, so input free of
//     self-intersections gives output free of them, in the precision the
//     output is stored in (stored_precision; with float32 "input" means
//     the input rounded to float). (Where the input
//     already intersects itself, a new face may meet a face that crossed
//     one of the faces it replaces, so decimation does not stall there.)
//   - With max_distance_voxels, every output vertex is within that distance
//     of the input surface (exact point-triangle distances): guaranteed for
//     every vertex a collapse moved, at stored_precision (a vertex no
//     collapse moved moves by its rounding to float only).
//     Each collapse also checks the midpoints of the edges it creates and
//     the centroids of the faces it creates, but other points inside output
//     faces, and the distance from the input back to the output, are not
//     bounded: those are estimates (bench_decimate measures them).
//   - The output is the same bytes for any thread count.
// Vertex normals: when mesh.normals holds one per point (read from a file,
// say), the output has them too. A vertex that did not move keeps its
// normal bit for bit; a moved one gets the input normals interpolated at
// its nearest point on the input faces around the input vertices merged
// into it, normalized. Empty normals stay empty; another count is an
// input_error.
// Quads are split into two triangles first, along the shorter diagonal
// unless only the other one lies inside the quad (a concave quad); the
// output has triangles only.
#pragma once

#include "pqdc/mesh.hpp"

#include <cstddef>
#include <functional>

namespace pqdc {

/// Which error quadric each vertex accumulates.
enum class DecimateMetric {
    /// Probabilistic triangle quadrics (eqs. 11, 13-15): every corner with
    /// isotropic positional noise sigma_position_voxels. Area-weighted, so
    /// small noisy triangles do not pin the surface. The default.
    triangle,
    /// Probabilistic plane quadrics (eqs. 6-8) through each face's centroid
    /// along its unit normal, weighted by face area, with normal noise
    /// sigma_normal and positional noise sigma_position_voxels.
    plane,
    /// Triangle quadrics for the placement plus an algebraic-sphere
    /// curvature term in the cost (Mesh Simplification With Curvature Error
    /// Metric, poster): each vertex gets the sphere fitted to its one-ring
    /// (points and normals), spheres interpolate along the collapsing edge,
    /// and the cost adds the sphere distance integrated along the new edges.
    curvature,
};

/// What decimate() needs at its peak per input triangle, bytes: measured
/// with pqdc-decimate, whose peak RSS grows by 258 bytes per input triangle
/// from 0.24 to 3 M triangles (its input mesh, about 24 of them, included;
/// 285 before the face grid's boxes and the sort's buffers were reused).
inline constexpr std::size_t kDecimateBytesPerTriangle = 300;

/// DecimateOptions::sigma_position_voxels: estimate the input's vertex noise
/// and use it (see the field).
inline constexpr double sigma_position_auto = -1.0;

struct DecimateOptions {
    /// Stop when the mesh has at most this many triangles. 0 = no face
    /// target. Range >= 0. Default 0.
    std::size_t target_faces = 0;
    /// Stop when the mesh has at most this fraction of the input's triangles
    /// (after quads are split). 0 = no ratio target. Range [0, 1]. Default 0.
    double target_ratio = 0;
    /// Refuse collapses that would put a vertex farther than this from the
    /// input surface, voxels. 0 = no distance limit. Range >= 0. Default 0.
    /// At least one of target_faces, target_ratio and max_distance_voxels
    /// must be set; with several, decimation stops at the first one reached.
    double max_distance_voxels = 0;
    /// World units per voxel: the unit of every length below. 0 = the mean
    /// edge length of the input (dual contouring output has edges of about
    /// one voxel). Range >= 0. Default 0.
    double voxel_size = 0;
    DecimateMetric metric = DecimateMetric::triangle;
    /// Positional noise (standard deviation) of the input vertices, voxels.
    /// Range > 0, or sigma_position_auto (the default): the noise is
    /// estimated from the input, as the robust spread (median absolute
    /// value) of every movable vertex's offset from its one-ring's centroid
    /// along its normal, and sigma is max(0.02, 0.7 x the estimate). The factor and
    /// the floor were chosen on bench_decimate's clean and noisy inputs:
    /// clean CAD edges want about 0.01-0.03 (0.1 rounds them at low
    /// budgets), noise of s voxels about 0.7 s. DecimateStats reports both.
    double sigma_position_voxels = sigma_position_auto;
    /// Normal noise of the plane metric, a fraction of the unit normal
    /// (dimensionless). Range > 0. Default 0.05.
    double sigma_normal = 0.05;
    /// Largest angle a face's normal may turn in one collapse, degrees.
    /// Range (0, 180). Default 75.
    double max_normal_change_degrees = 75;
    /// Smallest quality 4 sqrt(3) area / (sum of squared sides) of a created
    /// triangle (1 equilateral, 0 degenerate); a collapse whose old faces
    /// were worse may go down to their worst. Range [0, 1). Default 0.1.
    double min_triangle_quality = 0.1;
    /// Worker threads, 0 = all cores. Output is the same for any value.
    /// Range >= 0. Default 0.
    int threads = 0;
    /// Fail early (resource_error, before allocating) when the decimation's
    /// estimated peak memory exceeds this many bytes: kDecimateBytesPerTriangle
    /// per input triangle (quads count as two), beside the caller's mesh.
    /// 0 = 80% of physical memory. Default 0.
    std::size_t memory_limit_bytes = 0;
    /// The precision the result will be stored in. float32: every point is
    /// rounded to float first and every collapse's position before it is
    /// checked, so the guarantees above hold for the coordinates a float
    /// file holds (checked in double and rounded afterwards, a collapse can
    /// make faces meet and pass the distance bound, by up to a float's
    /// rounding, 6e-8 relative to the coordinates). The returned points are
    /// then floats held in doubles. The distance bound is measured to the
    /// input as given. Default float64 (the returned mesh; pqdc-decimate
    /// and pqdc --decimate set their output's precision).
    VertexPrecision stored_precision = VertexPrecision::float64;
    /// Called from the calling thread between the set-up's steps, before
    /// each pass, within it (between its stages and slices of its checks:
    /// at most about 0.25 s apart per million triangles on one thread) and at the
    /// end, with the finished fraction in [0, 1] (of the faces to remove,
    /// within a pass estimated from its planned collapses; never lower than
    /// before; 1 at the end); return false to cancel: decimate() then
    /// throws cancelled_error and leaves the mesh as it was. Optional.
    std::function<bool(double fraction)> progress;
};

struct DecimateStats {
    std::size_t input_faces = 0;         ///< triangles after splitting quads
    std::size_t output_faces = 0;
    std::size_t output_vertices = 0;     ///< points of the decimated mesh (every one used by a face)
    std::size_t collapses = 0;
    std::size_t passes = 0;
    std::size_t locked_vertices = 0;     ///< boundary / non-manifold vertices kept fixed
    /// Input faces that repeat a point, left out (zero-area needles, as STL
    /// welding makes of facets with two equal corners); not in input_faces.
    std::size_t dropped_faces = 0;
    /// Candidate collapses refused, by reason (a candidate refused in several
    /// passes counts each time).
    std::size_t rejected_link = 0;       ///< link condition or valence
    std::size_t rejected_flip = 0;       ///< a normal turned too far
    std::size_t rejected_quality = 0;    ///< a created triangle below the quality bound
    std::size_t rejected_intersection = 0;  ///< a created triangle would intersect another
    std::size_t rejected_distance = 0;   ///< the new vertex farther than max_distance_voxels
    double voxel_size = 0;               ///< the voxel size used, world units
    double noise_voxels = 0;             ///< the estimated vertex noise (sigma_position_auto only), voxels
    double sigma_position_voxels = 0;    ///< the positional sigma used, voxels
    double seconds = 0;                  ///< wall time of decimate()
};

/// decimate()'s first check, for callers that know a lower bound on the
/// triangle count before they hold the mesh (pqdc-decimate from the file's
/// header; see mesh_file_face_count): throws resource_error when that many
/// triangles (quads count as two) would need more than the memory limit of
/// `options`, kDecimateBytesPerTriangle each.
void check_decimate_memory(std::size_t triangles, const DecimateOptions& options);

/// Decimates `mesh` in place (see the file comment for what is
/// guaranteed). Points no face uses are dropped; the remaining points keep
/// their relative order; faces that repeat a point are left out
/// (DecimateStats::dropped_faces). Throws option_error for options out of
/// range or no target, input_error for a face that refers to a missing
/// point or a used point with a NaN or infinite coordinate,
/// resource_error when the estimated memory exceeds the limit, and
/// cancelled_error when options.progress returned false (the mesh is then
/// unchanged in every case). `stats` may be null.
void decimate(Mesh& mesh, const DecimateOptions& options, DecimateStats* stats = nullptr);

/// The option checks decimate() starts with: throws option_error naming
/// the field out of range, or that no target was given.
void validate(const DecimateOptions& options);

}  // namespace pqdc
