// The exchange of a streamed run between its first pass (scale/
// stream_cells.hpp) and the untangle stage, on one process or among the
// ranks of a distributed run (issue 14, phase 3). Each rank has meshed its
// contiguous share of the bricks in its own numbering; faces at the first
// of its bricks also use vertices of the rank before (their lower
// neighbours), known only by candidate leaf and place in it. One all-gather
// of the vertex counts per leaf gives every rank the global number of every
// leaf's first vertex (8 bytes per candidate leaf), so each rank numbers its
// own vertices, resolves those foreign corners, and turns the first check's
// findings into global seeds. The foreign corners are also used vertices of
// the earlier ranks, which the output stage must not drop: they are shared,
// and each rank marks its own.
#pragma once

#include "pqdc/distributed.hpp"
#include "scale/stream_cells.hpp"
#include "scale/stream_scratch.hpp"

#include <cstdint>
#include <vector>

namespace pqdc::detail {

/// What every rank knows after the exchange.
struct StreamNumbering {
    std::vector<std::uint64_t> seeds;    ///< every rank's offending corners: global, sorted, unique
    std::vector<std::uint64_t> foreign;  ///< vertices faces use across a rank boundary: global, sorted, unique
    std::uint64_t vertices = 0;          ///< every rank's, before unused ones are dropped
    StreamCounts counts;                 ///< every rank's, summed
};

/// Collective over `group`: numbers `scratch` (this rank's first pass,
/// `mine`) globally. `leaves`: the candidate leaves of the run. Throws
/// resource_error when the mesh has 2^32 vertices or more.
StreamNumbering number_streamed(const StreamedCells& mine, std::size_t leaves, StreamScratch& scratch, RankGroup& group);

}  // namespace pqdc::detail
