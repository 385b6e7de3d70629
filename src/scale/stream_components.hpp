// Stage "components" of a streamed run on one process
// (ExtractOptions::min_component_voxels): the small components found in the
// scratch files and dropped from the output, the same ones
// remove_small_components() drops from the in-core mesh. A union-find over
// the vertices (4 bytes each) joins the corners of every face, brick by
// brick; one pass over the vertices (the untangle stage's moves applied)
// bounds each component; the vertices of the small ones lose their used bit,
// so the output stage drops them and their faces (scale/stream_output.hpp)
// and the numbering closes up as it does for unused vertices. A
// distributed run's components may cross rank boundaries: such runs
// assemble the mesh instead (uniform/extract.cpp).
#pragma once

#include "pqdc/components.hpp"
#include "scale/stream_scratch.hpp"
#include "scale/stream_untangle.hpp"

#include <vector>

namespace pqdc::detail {

/// Clears the used bits of the vertices of `scratch`'s components whose
/// bounding-box diagonal (positions with `moved` applied, world space) is
/// below `min_diagonal_voxels` voxels of `voxel_size`; fills `stats` as
/// remove_small_components() does. `scratch` holds one process's whole
/// mesh (no corners at other ranks' vertices: logic_error otherwise).
void remove_streamed_islands(StreamScratch& scratch, const std::vector<MovedVertex>& moved, double voxel_size,
                             double min_diagonal_voxels, ComponentFilterStats& stats);

}  // namespace pqdc::detail
