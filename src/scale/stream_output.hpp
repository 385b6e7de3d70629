// Stage "write pieces" of a streamed run (issue 14, phases 2 and 3): the
// mesh kept in the scratch files goes to a MeshStreamWriter brick by brick,
// with the untangle stage's moves applied and the unused vertices dropped
// (their indices closed up, as drop_unused_vertices does in core), and the
// faces at unused vertices (removed components: scale/stream_components.hpp)
// too, so the file has the in-core run's bytes. In a distributed run each rank numbers
// its used vertices after the earlier ranks' (one all-gather of the
// counts, one of the final numbers of the vertices used across a rank
// boundary) and appends its pieces to its own writer; the writers are then
// finished together (MeshStreamWriter::finish(group)): the per-rank parts
// joined in rank order. In-process ranks sharing one writer send their
// pieces to rank 0 instead.
#pragma once

#include "lattice/resources.hpp"
#include "pqdc/distributed.hpp"
#include "pqdc/mesh.hpp"
#include "pqdc/mesh_stream.hpp"
#include "scale/stream_scratch.hpp"
#include "scale/stream_untangle.hpp"

#include <cstdint>
#include <functional>
#include <vector>

namespace pqdc::detail {

/// Where the used vertices go in the file.
struct UsedNumbering {
    std::uint64_t first = 0;  ///< the final number of this rank's first used vertex
    std::uint64_t total = 0;  ///< every rank's used vertices: the file's vertex count
    /// The final numbers of `foreign` (StreamNumbering::foreign), in its
    /// order; kUnusedVertex for one no longer used (a removed component's).
    std::vector<std::uint64_t> foreign;
};

/// UsedNumbering's mark of a vertex the file does not hold.
constexpr std::uint64_t kUnusedVertex = ~std::uint64_t(0);

/// Collective over `group`: the final numbering of every rank's used
/// vertices (`foreign`: StreamNumbering::foreign).
UsedNumbering number_used(const StreamScratch& scratch, const std::vector<std::uint64_t>& foreign, RankGroup& group);

/// Where a rank's pieces go.
enum class PieceParts {
    /// Every rank appends its pieces to its own writer, the ranks' parts
    /// joined later in rank order (MeshStreamWriter::finish(group) across
    /// processes, StreamWriterParts::absorb within one); not for STL, whose
    /// pieces go to rank 0.
    each_rank_its_writer,
    /// Every rank sends its pieces to rank 0, which appends them to its
    /// writer in rank order (when a caller's hook must see them in order).
    all_to_rank_0,
};

/// Collective over `group`: every rank's bricks as pieces, in brick order,
/// to `out` as `parts` says; `each_piece` (may be empty) sees each piece
/// where it is appended, final indices and positions, before it is
/// appended. `moved`: every rank's moves.
void write_streamed(StreamScratch& scratch, const UsedNumbering& numbers, const std::vector<std::uint64_t>& foreign,
                    const std::vector<MovedVertex>& moved, RankGroup& group, PieceParts parts, MeshStreamWriter& out,
                    const std::function<void(Mesh&)>& each_piece, const ProgressSpan& progress);

}  // namespace pqdc::detail
