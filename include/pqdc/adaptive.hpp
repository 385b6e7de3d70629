// Adaptive isosurface extraction: octree dual marching cubes (Schaefer &
// Warren, "Dual Marching Cubes: Primal Contouring of Dual Grids", PG 2004)
// driven by probabilistic plane quadrics.
//
//   pqdc::AdaptiveOptions options;
//   options.base.sigma_n = 0.1;
//   options.max_error_voxels = 0.1;  // voxels
//   pqdc::Mesh mesh = pqdc::extract_adaptive(*grid, options);
//
// Pipeline (all in index space; the output is mapped to world space with the
// grid transform):
//  1. Hermite data on the finest lattice, as extract() takes it: every cell
//     with an active corner, finite corners and a sign change gets the plane
//     quadrics of its crossing edges (crossing by linear interpolation of the
//     grid or by root finding on a procedural field; unit normal from the
//     gradient; a zero or non-finite gradient gives a point-only term).
//  2. Bottom-up octree simplification, across OpenVDB leaf boundaries, up to
//     max_cell_size_voxels. Eight sibling cells (missing siblings hold no
//     surface) merge into their parent when all of these hold:
//       - every child is itself a leaf with a manifold sign configuration;
//       - the topology tests of Ju et al. 2002 ("Dual Contouring of Hermite
//         Data", §4.2) pass on the parent's 27 lattice points: its corner
//         configuration is manifold, and the sign at the middle of every
//         edge, every face and the cube agrees with one of that element's
//         corners;
//       - the parent's vertex (the minimizer of the summed probabilistic
//         quadric, see sigma_n below) lies inside the parent cell;
//       - the collapse error is below max_error_voxels. The error is a
//         distance in voxels: the larger of (a) for each child, the root
//         mean square distance from the parent's vertex to the child's
//         Hermite planes (the classical part of the quadric, free of the
//         sigma_n regularization, which grows with cell size), maximized over
//         the children, and (b) the field's first-order distance
//         |g| / |grad g| at the vertex (the planes bound it only on average),
//         and (c) with sigma_n > 0, twice the vertex's distance from the
//         classical minimizer (pseudo-inverse, eigenvalue cutoff 0.01), so
//         that the regularization cannot pull a weakly sampled corner or edge
//         off its feature by more than half the bound, and (d) four times the
//         field distance at the midpoints between the vertex and its
//         children's vertices (faces will reach about twice as far, so this
//         estimates their sagitta on curved regions);
//       - the octree stays 2:1 balanced (no leaf next to the parent, across a
//         face, edge or corner, is more than one level finer).
//  3. One vertex per leaf holding surface (at its minimizer) and one per
//     empty leaf (at a lattice point inside it). The dual grid is generated
//     from the octree by the cell/face/edge/vertex recursion of Schaefer &
//     Warren: every octree corner gives one dual cell whose 8 corners are the
//     vertices of the leaves around it (cells around T-junctions are
//     degenerate).
//  4. Marching cubes on every dual cell. Empty leaves are classified by the
//     sign of the field at their vertex. Surface leaves always count as
//     inside: their vertex lies on the surface (up to the merge error), so
//     the field's sign there is noise, which would split the surface into
//     slivers and bubbles; a fixed side is a symbolic perturbation of the
//     field there. The price: only surface leaves that border an outside
//     (empty) leaf get a vertex, so outside features thinner than about one
//     cell are closed: sub-voxel cavities vanish, and islands or sheets less
//     than about a voxel apart fuse (inside features, e.g. thin plates, are
//     kept). Empty outside leaves that surface leaves wall in (at most 8
//     voxels together, typically in the air wedge of a concave crease) count
//     as inside too (stats->filled_pockets), else each would become a
//     closed, inside-out bubble. On smooth and CAD-like surfaces the topology equals the uniform
//     extractor's; on voxel-scale noise it does not. A crossing on a dual edge from a
//     surface leaf is placed at that leaf's vertex (the feature-preserving
//     position; the root of the field along the edge lies within the merge
//     error of it). Crossings on edges between two empty leaves (only where
//     the surface leaves the domain) are found by root finding on the field
//     (trilinear sampling of the grid, or the exact procedural field).
//     Crossings are keyed by their pair of leaves, so dual cells that share a
//     face share its vertices: the mesh is crack-free. Ambiguous faces always
//     separate the inside corners, a rule both cells sharing a face apply
//     identically. A loop is triangulated as a fan from a corner whose
//     diagonals join no two crossings on a common cell face (so the cell
//     across that face cannot add the same edge), else around an added
//     vertex at its centroid projected onto the surface.
//  5. Crossings placed on the same surface vertex are merged by edge
//     collapses that satisfy the link condition, which keeps the mesh a
//     closed, edge-manifold, consistently oriented surface. The result is
//     essentially a dual-contouring mesh over the leaf vertices: one vertex
//     per surface leaf that borders the outside. Where the surface folds
//     through one leaf vertex no collapse is allowed; those copies are moved
//     1e-4 of the way to their neighbours' centroid, so no face has zero area.
//     Along a concave crease the crease cells border no outside leaf (their
//     neighbours across the crease are surface leaves), so the loops cut the
//     crease off; each such unused vertex where the field is concave splits
//     the nearest edge that cuts through the outside, and edges that still
//     do are flipped to join the crease vertices (src/adaptive/crease_splits.cpp;
//     not in pinned cells; kept only where no triangle around is crossed).
//  6. No faces across a gap: counting surface leaves as inside joins two
//     sheets whose leaves share a face across the empty space between them
//     (two flat slabs 12 voxels apart at the default error, before this
//     step). Edges whose middle lies more than min(1 + max_error_voxels, 2)
//     voxels outside the surface while the outward normals at their ends
//     face each other (or the field is flat there) pin the finest cells
//     around their ends, and the octree is built again until none is left
//     (src/adaptive/bridges.hpp). Concave creases, whose faces meet at an
//     angle rather than face each other, are left alone. Gaps of less than
//     about twice that distance can still close, as can any gap with an
//     unbounded max_error_voxels (its vertices may sit anywhere in their cells).
//  7. No self-intersections: the mesh (in world space, at
//     base.stored_precision) is checked exactly; the finest cells around
//     every offending triangle are kept from merging and the octree is built
//     again, until that pins nothing new; what is left (in finest leaves)
//     moves towards cell centers as in extract(); should that not resolve
//     it, the result is extract()'s mesh with the same options
//     (stats->untangle_fallback and a warning say so). See
//     src/adaptive/untangle.hpp and the README's section on quality.
//
// sigma_n on coarse cells: the probabilistic quadric's regularization pulls
// the minimizer towards the mass point of the samples by about
// sigma_n^2 * (cell size) / 4 voxels at a sharp feature. To keep features
// sharp at every level, a cell of edge length s voxels uses the normal
// variance sigma_n^2 / s, which bounds that drift by the finest level's
// sigma_n^2 / 4 voxel at any cell size, when the feature's faces are
// sampled evenly; error term (c) above bounds it when they are not.
// sigma_n = 0 (pseudo-inverse) and infinity (mass point) are used unchanged.
//
// Containment: finest-level vertices follow base.containment (as extract());
// a merge whose vertex would leave the merged cell is refused, so coarse
// vertices always lie inside their cell.
//
// Determinism: the result is identical (same vertices, same order) for any
// number of threads. Every stage is TBB-parallel; the edge collapses of step 5
// run per octree root, the roots of one coordinate parity class at a time
// (they share no triangle), then the few edges between roots in order.
#pragma once

#include "pqdc/extract.hpp"
#include "pqdc/mesh.hpp"
#include "pqdc/procedural.hpp"
#include "pqdc/stats.hpp"

#include <openvdb/openvdb.h>

#include <array>
#include <cstdint>

namespace pqdc {

struct AdaptiveOptions {
    /// sigma_n, isovalue, interior, containment (finest level only), faces
    /// (quads: marching-cubes polygons with 4 corners stay quads; others are
    /// fanned into triangles), normals (grid crossings), pseudo_inverse_cutoff,
    /// memory_limit_bytes and progress mean what they mean for extract().
    ExtractOptions base;
    /// Largest collapse error (see the file comment) a merge may have, in
    /// voxels (a distance; an index-space one, so on non-cubic voxels a world
    /// distance of at most this many of the longest voxel edges). Range [0, inf]. 0 disables merging: the result is
    /// dual marching cubes on the finest lattice; infinity leaves only the
    /// topology, containment, balance and size limits. Every merged vertex
    /// lies within this distance of the surface (first order); faces are
    /// held to it only approximately (term (d): on a sphere the mean face
    /// distance stays near E/2, the worst faces reach a few E). Default 0.1
    /// voxel: flat and gently curved regions still merge into large cells
    /// (a sphere 256 voxels across: 9k triangles instead of 617k) while
    /// vertices stay on the surface to a tenth of a voxel.
    double max_error_voxels = 0.1;
    /// Edge length of the largest octree cell, in voxels. A power of two in
    /// [1, 4096]. Default 64.
    int max_cell_size_voxels = 64;
};

/// Meshes the isosurface of a float or double grid adaptively.
/// Cells with a NaN or infinite corner take no part (like inactive ones).
/// Any affine transform is meshed (as extract() does); options.base.region
/// restricts the finest cells and then the polygons (faces with a vertex
/// outside the region are dropped).
/// Throws option_error for invalid options, input_error for an unsupported
/// grid (non-scalar value type, a non-affine (frustum) or singular
/// transform, index coordinates spanning more than 2^19 voxels along an
/// axis), resource_error when the estimated
/// memory exceeds base.memory_limit_bytes, cancelled_error when
/// base.progress returned false. For grids larger than memory (delay-loaded,
/// brick stores) see pqdc::extract_adaptive_bricks in pqdc/bricks.hpp: same bytes.
Mesh extract_adaptive(const openvdb::FloatGrid& grid, const AdaptiveOptions& options,
                      AdaptiveStats* stats = nullptr);
Mesh extract_adaptive(const openvdb::DoubleGrid& grid, const AdaptiveOptions& options,
                      AdaptiveStats* stats = nullptr);
/// Dispatches on the grid's value type (float, double); other types throw input_error.
Mesh extract_adaptive(const openvdb::GridBase& grid, const AdaptiveOptions& options,
                      AdaptiveStats* stats = nullptr);

/// Meshes a procedural field adaptively: the lattice comes from
/// sample_field(); crossings on lattice edges and on dual edges are found by
/// root finding on the exact field, normals from its analytic gradient, and
/// the field at dual vertices is exact. base.isovalue and base.interior are
/// ignored (the surface is f = 0, inside negative).
Mesh extract_adaptive(const ScalarField& field, const ProceduralSampling& sampling,
                      const AdaptiveOptions& options, AdaptiveStats* stats = nullptr);

/// Throws option_error (naming the field) when options are out of range.
void validate(const AdaptiveOptions& options);

}  // namespace pqdc
