// Uniform stage "gather", between "cells" and "faces": the cells stage left
// each candidate leaf's cell records and vertices apart (leaf-parallel);
// the faces stage looks up neighbours across leaves and indexes one vertex
// array, so both are joined here, in leaf order.
#pragma once

#include "lattice/resources.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/mesh.hpp"
#include "uniform/cell_tree.hpp"
#include "uniform/cells.hpp"

#include <cstdint>
#include <vector>

namespace pqdc::detail {

/// The cell leaves of `r` into `cells` (`leaves`: each candidate leaf's,
/// null where it has no cell) and the per-leaf vertex lists into
/// mesh.points, in leaf order; `first[i]` is leaf i's first vertex. Throws
/// resource_error for more vertices than 32-bit indices address or than
/// the memory limit allows. Progress from 0.45 to 0.46.
void gather_vertices(LeafResults& r, const ExtractOptions& options, const Progress& progress, CellTree& cells,
                     std::vector<CellLeaf*>& leaves, std::vector<std::uint64_t>& first, Mesh& mesh);

}  // namespace pqdc::detail
