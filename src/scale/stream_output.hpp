// Stage "write" of a streamed run (issue 14, phase 2): the mesh kept in the
// scratch files goes to a MeshStreamWriter brick by brick, with the untangle
// stage's moves applied and the unused vertices dropped (their indices
// closed up, as drop_unused_vertices does in core), so the file has the
// in-core run's bytes.
#pragma once

#include "lattice/resources.hpp"
#include "pqdc/mesh.hpp"
#include "pqdc/mesh_stream.hpp"
#include "scale/stream_scratch.hpp"
#include "scale/stream_untangle.hpp"

#include <cstdint>
#include <functional>
#include <vector>

namespace pqdc::detail {

/// Appends every brick of `scratch` to `out` as one piece (scratch.used_count()
/// vertices in all); `each_piece` (may be empty) sees each piece, final
/// indices and positions, before it is appended.
void write_streamed(StreamScratch& scratch, const std::vector<MovedVertex>& moved, MeshStreamWriter& out,
                             const std::function<void(Mesh&)>& each_piece, const ProgressSpan& progress);

}  // namespace pqdc::detail
