// Uniform mode's safe vertex positions for the untangle stage
// (lattice/untangle.hpp): one point per vertex such that the mesh with every
// vertex there is free of self-intersections and degenerate triangles.
//
// A cell with one surface patch: its center. Where every cell has one vertex,
// each face is the unit square of the dual lattice around its crossing edge
// (the four cell centers), a face of the cubical complex whose vertices are
// the cell centers; distinct faces of a cubical complex meet only in shared
// edges or shared vertices, which are here shared indices as well (one index
// per center), and a square's two triangles (either diagonal) are
// non-degenerate and meet only along the diagonal. The map to world space is
// a similarity, so it keeps all of this.
//
// A cell with several patches (ambiguous configurations): the centers would
// coincide, so patch g gets c + kPatchPull * (m_g - c), with c the cell
// center and m_g the mean of the midpoints of the patch's crossing edges.
// m_g - c is the mean of the directions in which the patch's faces leave c
// (each face of edge e spans the quadrant of the dual square that points
// from c towards e), so the pull separates the patches along their own
// sides of the cell, and with kPatchPull = 1/2 each stays within a quarter
// cell of c. That this gives an intersection-free mesh is checked, not
// proven: exhaustively for all 256 configurations with every choice of
// joined faces, with single-vertex neighbours at their centers, and on random
// sign fields where most cells are ambiguous ([untangle] tests).
#pragma once

#include "lattice/transform.hpp"
#include "uniform/cell_tree.hpp"

#include <cstdint>
#include <vector>

namespace pqdc::detail {

constexpr double kPatchPull = 0.5;

/// Index-space safe position of patch `group` of a cell at `cell` with the
/// given configuration and joined faces.
openvdb::Vec3d safe_patch_position(const openvdb::Coord& cell, std::uint8_t config, std::uint8_t joined, int group);

/// A vertex's cell (index space) and what safe_patch_position() needs of it.
struct VertexCell {
    openvdb::Coord cell;
    std::uint8_t config = 0, joined = 0, patch = 0;
};

/// Per vertex of the cell tree's numbering (leaf_first[i] + cell's first
/// vertex + patch), `count` vertices: its VertexCell.
std::vector<VertexCell> vertex_cells(const std::vector<CellLeaf*>& leaves,
                                     const std::vector<std::uint64_t>& leaf_first, std::size_t count);

/// One safe world-space position per vertex (vertex_cells()' order).
std::vector<openvdb::Vec3d> safe_positions(const std::vector<VertexCell>& cells, const LatticeTransform& xf);

/// Per vertex: its patch within its cell (bits 0-3) and the cell's patch
/// count (bits 4-7). A cell's vertices are consecutive (its first vertex +
/// patch), which is what quad_star_check.hpp relies on.
std::vector<std::uint8_t> cell_patches(const std::vector<VertexCell>& cells);

}  // namespace pqdc::detail
