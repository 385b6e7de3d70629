// Removal of small connected components (spurious islands).
//
//   pqdc::ComponentFilterStats stats;
//   pqdc::Mesh clean = pqdc::remove_small_components(mesh, grid->voxelSize()[0], {}, &stats);
//
// Voxel-scale noise in a volume flips the sign of isolated lattice points
// near the surface; each flip becomes a small closed component. Components
// are groups of faces connected through shared points (the components
// TopologyReport counts). A component's size is the diagonal of its
// world-space bounding box divided by the voxel size: a length, defined for
// open and closed components alike, which does not depend on orientation,
// winding or closedness (an enclosed volume would need all three, and would
// remove thin sheets and filaments whose volume is small but whose extent is
// not).
#pragma once

#include "pqdc/mesh.hpp"

#include <cstddef>

namespace pqdc {

struct ComponentFilterOptions {
    /// Components whose bounding-box diagonal is below this many voxels are
    /// removed. Range [0, inf]; 0 keeps every component. Default 3.5 voxels.
    ///
    /// Why 3.5: a lattice point whose sign the noise flipped gives a closed
    /// component with its vertices in the 8 cells around the point (vertices
    /// clamped to their cells), so its diagonal is at most 2 sqrt(3) ~ 3.46
    /// voxels. Measured over bench_quality's suite at 128 cells with noise up
    /// to 0.3 voxel, the largest spurious components are 3.3 voxels across
    /// for pqdc at sigma_n 0 with sharp normals, 3.0-3.2 at sigma_n 0 and
    /// 0.1 (vertices at quadric minimizers spread over their cells) and 0.8
    /// for volumeToMesh (mass points); 3.5 removes all of them. A real
    /// droplet of radius r voxels has a diagonal of 2 sqrt(3) r ~ 3.46 r, so
    /// droplets of radius 1 voxel and more (2 voxels across) survive. Users
    /// who need smaller droplets pass 0 (or a smaller size).
    double min_diagonal_voxels = 3.5;
};

struct ComponentFilterStats {
    std::size_t components = 0;          ///< components of the input
    std::size_t removed_components = 0;
    std::size_t removed_faces = 0;       ///< triangles and quads
    std::size_t removed_points = 0;      ///< points of removed components
    /// Largest bounding-box diagonal among the removed components, voxels (0 if none).
    double largest_removed_diagonal_voxels = 0;
    /// Smallest bounding-box diagonal among the kept components, voxels (0 if none).
    double smallest_kept_diagonal_voxels = 0;
};

/// The mesh without its components smaller than options.min_diagonal_voxels.
/// Points of removed components are dropped; every other point (including
/// points no face uses) and every kept face stays, in its original order, so
/// the result is deterministic and a mesh with nothing to remove comes back
/// unchanged; normals (one per point) stay with their points. Faces with a
/// non-finite corner make their component's size NaN, and such components
/// are kept. voxel_size is the lattice spacing in the mesh's (world) units.
/// Throws option_error when voxel_size is not positive and finite or
/// min_diagonal_voxels is negative or NaN, input_error when a face refers to
/// a point that does not exist or normals are neither empty nor one per point.
Mesh remove_small_components(const Mesh& mesh, double voxel_size, const ComponentFilterOptions& options = {},
                             ComponentFilterStats* stats = nullptr);

}  // namespace pqdc
