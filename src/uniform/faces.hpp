// Uniform stage "faces": one quad (or two triangles) per crossing lattice
// edge whose four cells take part; each cell owns the three edges leaving its
// minimum corner. The driver then drops the vertices no face uses
// (drop_unused_vertices), after the untangle stage.
#pragma once

#include "lattice/resources.hpp"
#include "lattice/transform.hpp"
#include "pqdc/mesh.hpp"
#include "pqdc/stats.hpp"
#include "uniform/cell_tree.hpp"

#include <cstdint>
#include <vector>

namespace pqdc::detail {

/// stats.boundary_crossings (crossings without a face: a cell around them
/// is missing) and crossing_edges of the cell leaves (leaves[i] may be
/// null); leaf_faces[i] / leaf_incidences[i]: leaf i's faces and (cell,
/// crossing edge) pairs as counted by classify_leaf.
void count_boundary_crossings(const CellTree& cells, const std::vector<CellLeaf*>& leaves,
                              const std::vector<std::uint32_t>& leaf_faces,
                              const std::vector<std::uint32_t>& leaf_incidences, const Progress& progress,
                              ExtractStats& stats);

/// The quads of every cell leaf, in leaf order (leaves[i] may be null: no
/// crossed cell), into mesh.quads, counter-clockwise seen from outside;
/// sides[k]: 2 * axis + 1 when quad k's outward direction is +axis, else
/// 2 * axis. leaf_first[i]: index of leaf i's first vertex in mesh.points;
/// leaf_faces[i] as for count_boundary_crossings.
void build_quads(const CellTree& cells, const std::vector<CellLeaf*>& leaves,
                 const std::vector<std::uint64_t>& leaf_first, const std::vector<std::uint32_t>& leaf_faces,
                 const LatticeTransform& xf, const ExtractOptions& options, const Progress& progress, Mesh& mesh,
                 std::vector<std::uint8_t>& sides);

/// mesh.quads (with build_quads' sides) into mesh.triangles, two per quad
/// in quad order: the split whose triangles both face the quad's outward
/// side, and of those the better shaped. mesh.quads is emptied. Needs only
/// the points: the in-core driver splits after the cell records are gone.
void split_quads(const std::vector<std::uint8_t>& sides, const LatticeTransform& xf, const ExtractOptions& options,
                 Mesh& mesh);

/// stats.triangles and stats.quads for `quads` faces of options.faces.
void count_faces(const ExtractOptions& options, std::uint64_t quads, ExtractStats& stats);

/// build_quads(), then split_quads() for triangle output; fills
/// stats.triangles and quads.
void build_faces(const CellTree& cells, const std::vector<CellLeaf*>& leaves,
                 const std::vector<std::uint64_t>& leaf_first, const std::vector<std::uint32_t>& leaf_faces,
                 const LatticeTransform& xf, const ExtractOptions& options, const Progress& progress, Mesh& mesh,
                 ExtractStats& stats);

/// Crossings of the leaf's cells that get no face (a neighbour cell is
/// missing). Each is counted by the first of its four cells (owner, -u, -v,
/// -u-v) that exists, whether or not that is the owner.
std::uint64_t count_open_crossings(const CellTree& cells, const CellLeaf& leaf);

/// Drops vertices that no face references, keeping the order of the others
/// (cells whose crossings all lack a neighbour cell got one).
void drop_unused_vertices(Mesh& mesh);

}  // namespace pqdc::detail
