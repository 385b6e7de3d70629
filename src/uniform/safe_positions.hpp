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

/// Per vertex of the cell tree's numbering (leaf_first[i] + the cell's first
/// vertex + patch): its cell (index space) and what safe_patch_position()
/// needs of it. 8 bytes a vertex, the cell kept as its leaf's number and its
/// offset in the leaf: these exist next to the cell records and the quads at
/// the uniform run's peak.
class VertexCells {
public:
    VertexCells() = default;
    VertexCells(const std::vector<CellLeaf*>& leaves, const std::vector<std::uint64_t>& leaf_first, std::size_t count);

    std::size_t size() const { return vertex_.size(); }
    openvdb::Coord cell(std::size_t v) const {
        const std::uint32_t b = vertex_[v].bits;
        return origin_[vertex_[v].leaf] + openvdb::Coord(int(b >> 6 & 7), int(b >> 3 & 7), int(b & 7));
    }
    std::uint8_t config(std::size_t v) const { return std::uint8_t(vertex_[v].bits >> 9); }
    std::uint8_t joined(std::size_t v) const { return std::uint8_t(vertex_[v].bits >> 17 & 63); }
    int patch(std::size_t v) const { return int(vertex_[v].bits >> 23 & 3); }

private:
    struct Packed {
        std::uint32_t leaf;  ///< index into origin_
        std::uint32_t bits;  ///< offset in the leaf (x, y, z: 3 bits each), config, joined, patch
    };
    static_assert(kLeafDim == 8, "3 bits of offset per axis");
    std::vector<openvdb::Coord> origin_;  ///< per candidate leaf
    std::vector<Packed> vertex_;
};

/// Vertex v's safe world-space position.
inline openvdb::Vec3d safe_position(const VertexCells& cells, std::size_t v, const LatticeTransform& xf) {
    return xf.to_world(safe_patch_position(cells.cell(v), cells.config(v), cells.joined(v), cells.patch(v)));
}

/// Per vertex: its patch within its cell (bits 0-3) and the cell's patch
/// count (bits 4-7). A cell's vertices are consecutive (its first vertex +
/// patch), which is what quad_star_check.hpp relies on.
std::vector<std::uint8_t> cell_patches(const VertexCells& cells);

}  // namespace pqdc::detail
