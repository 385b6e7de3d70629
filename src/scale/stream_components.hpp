// Stage "components" of a streamed run on one process
// (ExtractOptions::min_component_voxels): the small components found in the
// scratch files and dropped from the output, the same ones
// remove_small_components() drops from the in-core mesh. A union-find over
// the vertices (4 bytes each) joins the corners of every face, brick by
// brick; one pass over the vertices (the untangle stage's moves applied)
// bounds each component; the vertices of the small ones lose their used bit,
// so the output stage drops them and their faces (scale/stream_output.hpp)
// and the numbering closes up as it does for unused vertices. On several
// ranks (or concurrent runs) each rank does this for its own faces and
// vertices, and the components that cross rank boundaries are joined
// through the vertices faces use across them: one record per such vertex
// and one box per such component go to every rank, which all decide alike.
#pragma once

#include "pqdc/components.hpp"
#include "pqdc/distributed.hpp"
#include "scale/stream_scratch.hpp"
#include "scale/stream_untangle.hpp"

#include <vector>

namespace pqdc::detail {

/// Collective over `group`: clears the used bits of the vertices of the
/// components whose bounding-box diagonal (positions with `moved` applied,
/// world space) is below `min_diagonal_voxels` voxels of `voxel_size`, on
/// every rank; fills `stats` as remove_small_components() does, the same on
/// every rank. `foreign`: the group's vertices used across rank boundaries
/// (StreamNumbering::foreign). Components that cross rank boundaries are
/// joined through it: each rank sends one record per boundary vertex it
/// holds and one box per component that crosses.
void remove_streamed_islands(StreamScratch& scratch, const std::vector<MovedVertex>& moved,
                             const std::vector<std::uint64_t>& foreign, double voxel_size,
                             double min_diagonal_voxels, RankGroup& group, ComponentFilterStats& stats);

}  // namespace pqdc::detail
