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

/// The faces of every cell leaf, in leaf order (leaves[i] may be null: no
/// crossed cell). leaf_first[i]: index of leaf i's first vertex in mesh.points;
/// leaf_faces[i] / leaf_incidences[i]: its faces and (cell, crossing edge)
/// pairs as counted by classify_leaf. Fills mesh.triangles or mesh.quads and
/// stats.triangles, quads, boundary_crossings and crossing_edges.
void build_faces(const CellTree& cells, const std::vector<CellLeaf*>& leaves,
                 const std::vector<std::uint64_t>& leaf_first, const std::vector<std::uint32_t>& leaf_faces,
                 const std::vector<std::uint32_t>& leaf_incidences, const LatticeTransform& xf,
                 const ExtractOptions& options, const Progress& progress, Mesh& mesh, ExtractStats& stats);

/// Drops vertices that no face references, keeping the order of the others
/// (cells whose crossings all lack a neighbour cell got one).
void drop_unused_vertices(Mesh& mesh);

}  // namespace pqdc::detail
