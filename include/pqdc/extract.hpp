// Dual contouring of sparse volumes with probabilistic plane quadrics.
//
//   openvdb::FloatGrid::Ptr grid = ...;
//   pqdc::ExtractOptions options;
//   options.sigma_n = 0.1;
//   pqdc::Mesh mesh = pqdc::extract(*grid, options);
//
// Hermite data (edge crossings and unit normals) are taken on every lattice
// edge whose end points lie on opposite sides of the isovalue. Each active
// cell gets one vertex per connected surface patch (marching-cubes edge
// group), at the minimizer of the sum of its patch's probabilistic plane
// quadrics built in cell-local coordinates. One quad per crossing edge joins
// the vertices of the four cells around it.
//
// Domain: a lattice cell takes part when at least one of its 8 corners is
// active (an active voxel or an active tile at any tree level) and none is
// NaN; inactive corners use their stored value (a level set's signed
// background, a fog volume's empty zero). A closed surface inside the active
// region gives a closed, edge-manifold mesh; where the surface leaves the
// active region the mesh has boundary edges there and only there.
//
// Determinism: the result is identical (same vertices, same order) for any
// number of threads.
#pragma once

#include "pqdc/mesh.hpp"
#include "pqdc/procedural.hpp"
#include "pqdc/stats.hpp"

#include <openvdb/openvdb.h>

#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <optional>
#include <string>

namespace pqdc {

/// Which side of the isovalue is inside the surface.
enum class Interior {
    /// Decided per grid by choose_interior(): from the grid class (level
    /// set: below, fog volume: above), else from the background (inactive)
    /// value (inside is the side the background is not on), else from the
    /// values on the boundary of the active region (likewise), else below.
    automatic,
    below_isovalue,  ///< inside where value < isovalue (signed distance, inside negative)
    above_isovalue,  ///< inside where value > isovalue (density, inside denser)
};

/// Where a cell's vertex may lie.
enum class Containment {
    clamp_to_cell,  ///< minimizers outside the cell are clamped to it (counted in stats)
    unconstrained,  ///< the minimizer as is, wherever it lies
};

/// How grid crossings get their normals (procedural fields always use the
/// analytic gradient).
enum class GridNormals {
    /// Chosen from the volume (ExtractStats::gradient): sharp on distance
    /// fields (level sets, unknown classes with inside below the isovalue),
    /// central on densities (fog volumes; their clamped ramps look like kinks
    /// to one-sided stencils), least_squares on noisy data that are not
    /// denoised (Denoise::off). Denoised data use sharp on the smoothed field.
    automatic,
    /// Central differences at both ends of the edge, interpolated to the
    /// crossing: smooth, least noise, but blurred within a voxel of a sharp
    /// edge or corner (the stencil straddles it).
    central,
    /// For clean distance fields with sharp features (CAD models, converted
    /// meshes): per axis the one-sided difference on the side where the
    /// samples stay linear (ENO), ends weighted by how linear their stencils
    /// are, and the crossing moved to the better end's first-order root.
    /// Reproduces corners of a sampled box about twice as closely; on noisy
    /// data it amplifies the noise (one-sided differences).
    sharp,
    /// The gradient of the least-squares linear fit of the 3x3x3 values at
    /// both ends (the mean of nine central differences per axis): three times
    /// less noise than central, blurred over one more voxel. For noisy data.
    least_squares,
};

/// Denoising, two stages: (1) the field near the surface is smoothed by a
/// feature-preserving filter (each neighbour predicts the value from its own
/// gradient, weighted by how well its gradient agrees: edges keep their
/// kink), so the cells' topology stops following the noise; (2) each cell's
/// vertex minimizes the quadrics of its 3x3x3 cell neighbourhood, weighted
/// by distance and normal agreement, the lattice form of the filtered
/// quadrics of Trettner & Kobbelt 2020, section 5.2 (the adaptive extractor
/// does stage 1 only). See the README, "Noisy volumes".
enum class Denoise {
    automatic,  ///< on when the estimated noise (ExtractStats::noise_voxels) is at least 0.08 voxel
    off,        ///< each cell's own samples and the field as it is
    on,         ///< always
};

/// ExtractOptions::sigma_n value asking pqdc to choose sigma_n from the
/// volume's estimated noise (the default).
inline constexpr double sigma_n_auto = -1.0;

enum class FaceType {
    triangles,  ///< each quad split along its better diagonal (see extract())
    quads,      ///< one planar-or-not quad per crossing edge
};

/// The part of the volume to mesh. A lattice cell takes part only when its
/// centre lies in every region given (and it is in the domain, see above), so
/// the mesh is open exactly where the surface leaves the region, and inside
/// it the mesh is the whole grid's: the same vertices and faces.
struct MeshRegion {
    /// Axis-aligned box in world units (min and max corner, min <= max on
    /// every axis), tested at each cell's centre mapped to world space.
    /// Default: none (unbounded).
    std::optional<openvdb::BBoxd> bbox;
    /// A grid limiting the surface to its active voxels (bool, mask, fog,
    /// unknown-class float/double and int grids) or its inside (level sets:
    /// value < 0, including the inactive interior). It may have its own
    /// transform: each cell's centre is mapped to the mask's index space and
    /// the voxel there decides (for a mask with the grid's own transform: the
    /// voxel at the cell's minimum corner). Default: none.
    openvdb::GridBase::ConstPtr mask;
    /// Mesh where the mask does not hold instead. Mask and inverted mask
    /// split the cells exactly, each cell to one side; a face needs all four
    /// cells around its edge, so the faces whose cells straddle the seam
    /// (one band of faces along it) are in neither mesh. Default false.
    bool invert_mask = false;

    bool empty() const { return !bbox && !mask; }
};

struct ExtractOptions {
    /// Standard deviation of the assumed normal noise, as a fraction of the
    /// unit normal (dimensionless; never scaled by voxel size; on non-cubic
    /// or sheared voxels, of the index-space unit normal, since quadrics are
    /// built in index space). Range [0, inf], or sigma_n_auto.
    /// 0 = classical quadrics minimized with the pseudo-inverse; inf = mass
    /// point of the cell's crossings; sigma_n_auto = chosen from the
    /// estimated noise (0.1 on clean data, 0.25 on noisy data; the value used
    /// is in ExtractStats::sigma_n). Default sigma_n_auto.
    double sigma_n = sigma_n_auto;
    /// The surface level, in the grid's value units. Default 0.
    double isovalue = 0.0;
    /// Inside/outside convention. Default: from the grid class.
    Interior interior = Interior::automatic;
    /// Vertex placement policy. Default: clamp to the cell.
    Containment containment = Containment::clamp_to_cell;
    /// The precision the caller will store the vertices in. Rounding to
    /// float32 moves vertices by up to ~1e-7 of their coordinates, enough to
    /// make two nearly touching faces cross (or uncross). The uniform
    /// extractor's self-intersection repair checks the positions as they
    /// will be stored: with float32 the mesh rounded to float is
    /// intersection-free, the returned double-precision points themselves
    /// are not checked. Default float64 (the returned mesh); the CLI sets
    /// float32 for float PLY/OBJ/OFF and STL.
    VertexPrecision stored_precision = VertexPrecision::float64;
    /// Output polygons. Default: triangles.
    FaceType faces = FaceType::triangles;
    /// Fill Mesh::normals (a streamed run: the writer's normals, which must
    /// be made with_normals) with each final vertex's outward normal from
    /// the field, as compute_vertex_normals(mesh, grid, inside) gives it for
    /// the interior the run chose: a function of the vertex alone, so every
    /// run (in core, by bricks, streamed, distributed) writes the same
    /// normals. Default false.
    bool vertex_normals = false;
    /// Remove the components of the mesh whose bounding-box diagonal is
    /// below this many voxels (of the grid's shortest voxel side), as
    /// remove_small_components() does; counted in ExtractStats::components.
    /// Every run removes the same ones: a streamed run finds the components
    /// with 4 bytes per vertex (a union-find over its scratch files; ranks
    /// join the components that cross their boundaries).
    /// Range [0, inf]; 0 (default) keeps everything.
    double min_component_voxels = 0;
    /// Normals of grid crossings. Default: automatic.
    GridNormals normals = GridNormals::automatic;
    /// Quadric filtering over neighbouring cells. Default: automatic.
    Denoise denoise = Denoise::automatic;
    /// sigma_n == 0 only: eigenvalues of A below this fraction of the largest
    /// are treated as zero by the pseudo-inverse. Range [0, 1). Default 0.01,
    /// i.e. singular values of the stacked normals below 0.1 of the largest
    /// (classical DC's truncation). Larger values smooth like sigma_n > 0.
    double pseudo_inverse_cutoff = 0.01;
    /// Fail early (resource_error) when the estimated peak memory of the
    /// result and intermediate arrays exceeds this many bytes. 0 = 80% of
    /// physical memory. Default 0.
    std::size_t memory_limit_bytes = 0;
    /// Mesh only part of the volume (box and/or mask). Default: everything.
    /// Also what to do when a volume is too large to mesh at once.
    MeshRegion region;
    /// Called from the calling thread with the finished fraction in [0, 1];
    /// return false to cancel (extract throws cancelled_error). Optional.
    std::function<bool(double fraction)> progress;
    /// Called at most once, from the calling thread, when extract() or an
    /// assembling extract_bricks() of a grid has read the grid for the last
    /// time: after stage "cells", before the stages that build the mesh's
    /// largest arrays. A caller that owns the grid may free it there (e.g.
    /// grid.clear()); the run then hands the freed memory back to the
    /// system, and its peak memory drops by the grid's size (the 12.7 M-voxel
    /// sphere of the README: 667 -> 563 MiB). Not called when the run will
    /// read the grid again: with vertex_normals, when the mesh has no faces
    /// (the caller may want to find out why), when the surface may hug the
    /// active region's edge (the warning about it reads the grid), in
    /// streamed runs and in adaptive mode. Optional.
    std::function<void()> values_done;
};

/// Which side of the isovalue a grid's inside is, and why.
struct InteriorChoice {
    Interior side = Interior::below_isovalue;  ///< below_isovalue or above_isovalue, never automatic
    /// Why, in words: "--interior / options.interior", "grid class level set",
    /// "background -1000 is below the isovalue 300", ...
    std::string reason;
};

/// Resolves options.interior for a float or double grid (the rule at
/// Interior::automatic). The last step reads the active region's boundary
/// values, a pass over the active voxels, and is reached only for grids of
/// unknown class whose background equals the isovalue. Other value types
/// resolve by class and background only.
InteriorChoice choose_interior(const openvdb::GridBase& grid, const ExtractOptions& options);

/// Meshes the isosurface of a float or double grid.
/// Index space is meshed and vertices mapped through the grid's affine
/// transform (any non-singular scale, shear, rotation or mirror).
/// Throws option_error for invalid options, input_error for an unsupported
/// grid (non-scalar value type, a non-affine (frustum) or singular transform,
/// a mask of an unsupported type), resource_error when the result would not fit in memory,
/// cancelled_error when options.progress returned false.
Mesh extract(const openvdb::FloatGrid& grid, const ExtractOptions& options,
             ExtractStats* stats = nullptr);
Mesh extract(const openvdb::DoubleGrid& grid, const ExtractOptions& options,
             ExtractStats* stats = nullptr);
/// Dispatches on the grid's value type (float, double); other types throw input_error.
Mesh extract(const openvdb::GridBase& grid, const ExtractOptions& options,
             ExtractStats* stats = nullptr);

/// Meshes a procedural field: samples it with sample_field(), then takes
/// crossings by root finding on the exact field along each edge and normals
/// from its analytic gradient. options.isovalue and interior are ignored
/// (the surface is f = 0, inside negative).
Mesh extract(const ScalarField& field, const ProceduralSampling& sampling,
             const ExtractOptions& options, ExtractStats* stats = nullptr);

/// The grid extract(field, sampling, options) meshes: sample_field()'s
/// grid, restricted to the 128^3 lattice nodes near options.region when it
/// is bounded. Throws resource_error before anything is sampled when its
/// dense leaves would exceed options.memory_limit_bytes (0: 80% of physical
/// memory), where sample_field() would allocate until the system refuses.
openvdb::FloatGrid::Ptr sample_field_within_limits(const ScalarField& field, const ProceduralSampling& sampling,
                                                   const ExtractOptions& options);

/// Throws option_error (naming the field) when options are out of range.
void validate(const ExtractOptions& options);

}  // namespace pqdc
