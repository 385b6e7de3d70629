// Per-vertex normals from the field a mesh was extracted from: the field's
// gradient at each vertex, unit length, world space, pointing outward (the
// side the mesh's faces face). Written by pqdc::write_mesh as OBJ `vn` and
// PLY nx/ny/nz.
#pragma once

#include "pqdc/extract.hpp"
#include "pqdc/mesh.hpp"
#include "pqdc/procedural.hpp"

#include <openvdb/openvdb.h>

namespace pqdc {

/// Fills mesh.normals from a FloatGrid's or DoubleGrid's gradient at each
/// vertex: central differences at the 8 voxels around the vertex (the
/// stencil the extractor's Hermite normals use), interpolated trilinearly and
/// mapped to world space as a covector (inverse transpose of the voxel-to-
/// world Jacobian, so non-uniform scales and shears tilt normals correctly).
/// The sign is chosen once for the whole mesh so that normals agree with the
/// faces' winding (outward for pqdc's meshes, whatever the interior rule).
/// Where the gradient vanishes or is not finite the area-weighted normal of
/// the faces around the vertex is used; an isolated vertex gets (0, 0, 0).
/// Throws input_error for grids of another value type. Deterministic for any
/// thread count.
void compute_vertex_normals(Mesh& mesh, const openvdb::GridBase& grid);

/// The same normals, bit for bit, reading the grid one 128^3 internal node
/// (plus a 2-voxel halo) at a time through copies of its leaves: for a grid
/// read with VolumeLoading::delayed (out-of-core meshing, brick stores,
/// pqdc-mpi), whose own leaf buffers then stay in the file instead of
/// being loaded by the accessors. Memory: the mesh, a node key per vertex
/// and one node's voxels per thread.
void compute_vertex_normals_by_nodes(Mesh& mesh, const openvdb::GridBase& grid);

/// The same from a procedural field's analytic gradient.
void compute_vertex_normals(Mesh& mesh, const ScalarField& field);

/// Normals of a mesh pqdc extracted with the interior `inside`
/// (below_isovalue or above_isovalue; automatic throws option_error): each
/// from its vertex alone, so a mesh written brick by brick or by several
/// ranks gets them piece by piece (ExtractOptions::vertex_normals). The
/// gradient as above, pointing away from the inside. Where it vanishes or is
/// not finite (a vertex next to NaN values): the gradient of the trilinear
/// interpolant of the 8 voxels around the vertex; where that fails too,
/// (0, 0, 0). Same bit for bit as the overloads above wherever their
/// gradients are usable and agree with the faces.
void compute_vertex_normals(Mesh& mesh, const openvdb::GridBase& grid, Interior inside);

/// compute_vertex_normals(mesh, grid, inside), bit for bit, reading the grid
/// node by node as compute_vertex_normals_by_nodes does.
void compute_vertex_normals_by_nodes(Mesh& mesh, const openvdb::GridBase& grid, Interior inside);

/// A procedural field's analytic gradient, pointing away from its inside
/// (negative values); (0, 0, 0) where it vanishes or is not finite.
void compute_outward_vertex_normals(Mesh& mesh, const ScalarField& field);

}  // namespace pqdc
