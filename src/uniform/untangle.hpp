// Uniform stage "untangle": the safe positions of the mesh's vertices
// (uniform/safe_positions.hpp), the quad-star check (uniform/quad_star_check.hpp)
// and the repair that moves vertices towards their safe positions
// (lattice/untangle.hpp), for a mesh held whole in memory. The streamed
// runs do the same brick by brick (scale/stream_cells.hpp, stream_untangle.hpp).
#pragma once

#include "lattice/resources.hpp"
#include "lattice/transform.hpp"
#include "pqdc/mesh.hpp"
#include "pqdc/stats.hpp"
#include "uniform/safe_positions.hpp"

#include <vector>

namespace pqdc::detail {

/// Stage "untangle" of the mesh whose vertices lie in the cells
/// `vertex_cells`: the quad-star check and the repair towards the safe
/// positions, which moves points only (faces unchanged). Its arrays are
/// gone on return. Progress from 0.5 to 0.95.
void untangle_lattice_mesh(Mesh& mesh, VertexCells vertex_cells, const LatticeTransform& xf,
                           const ExtractOptions& options, const Progress& progress, ExtractStats& stats);

}  // namespace pqdc::detail
