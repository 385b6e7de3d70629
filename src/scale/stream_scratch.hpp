// What a streamed run (issue 14, phase 2: scale/stream_cells.hpp) keeps of
// the mesh outside memory: each brick's own vertices (position before the
// untangle stage, cell and patch, from which the safe position follows) and
// own faces (global vertex
// indices, before unused vertices are dropped), appended brick after brick
// to two unlinked scratch files next to the output, and read back one brick
// at a time by the untangle and output stages. In memory stay only the
// per-brick counts, one bit per vertex (used by a face or not) and the
// corners at other ranks' vertices (a distributed run's rank boundaries).
#pragma once

#include "io/atomic_file.hpp"
#include "bricks/coord_hash.hpp"

#include <openvdb/openvdb.h>

#include <cstdint>
#include <string>
#include <vector>

namespace pqdc::detail {

struct ScratchVertex {
    openvdb::Vec3d position;  ///< world space, as the cells stage placed it
    openvdb::Coord cell;      ///< index space: the cell the vertex belongs to
    /// The cell's corner signs, joined faces and the vertex's patch: what
    /// safe_patch_position() (uniform/safe_positions.hpp) needs.
    std::uint8_t config = 0, joined = 0, patch = 0, unused = 0;
};
static_assert(sizeof(ScratchVertex) == 40, "scratch records are 40 bytes");

/// A face corner at a vertex of an earlier rank's bricks (a distributed
/// run): known first by its candidate leaf and place within the leaf, after
/// the ranks' exchange by its global number (scale/stream_numbering.hpp).
struct ForeignCorner {
    std::uint64_t position;  ///< in this rank's flattened face indices
    std::uint64_t vertex;    ///< leaf << 32 | vertex within the leaf; then the global number
    openvdb::Coord cell;     ///< index space: the vertex's cell
    std::uint32_t unused = 0;
};

class StreamScratch {
public:
    /// Scratch files next to `target` (the output path; "-": the temporary
    /// directory). `quads`: faces are quads, else triangles.
    StreamScratch(const std::string& target, bool quads);

    /// Appends the next brick: its vertices (numbered on from vertex_count())
    /// and its faces (4 indices per quad, 3 per triangle, flattened, in this
    /// rank's numbering). The corners in `foreign` (positions within this
    /// brick's indices, increasing) are other ranks' vertices: their entries
    /// in face_indices are placeholders.
    void add_brick(const std::vector<ScratchVertex>& vertices, const std::vector<std::uint32_t>& face_indices,
                   std::vector<ForeignCorner> foreign = {});

    /// The global number of this rank's first vertex (0 on one process):
    /// from here on vertex numbers are global.
    void number_from(std::uint64_t first) { first_global_ = first; }
    std::uint64_t first_global() const { return first_global_; }

    std::size_t bricks() const { return vertex_first_.size() - 1; }
    /// This rank's vertices.
    std::uint64_t vertex_count() const { return vertex_first_.back(); }
    /// The global number of brick `brick`'s first vertex.
    std::uint64_t first_vertex(std::size_t brick) const { return first_global_ + vertex_first_[brick]; }
    int arity() const { return arity_; }
    /// Corners at other ranks' vertices, by position; the exchange resolves them.
    std::vector<ForeignCorner>& foreign() { return foreign_; }
    std::uint64_t first_index(std::size_t brick) const { return index_first_[brick]; }
    /// Marks global vertex v, one of this rank's, used by another rank's face.
    void mark_used(std::uint64_t v);
    /// Marks global vertex v, one of this rank's, unused: the output drops
    /// it and the faces at it (a removed component's: scale/stream_components.hpp).
    void mark_unused(std::uint64_t v);
    /// The used flags of this rank's vertices (bit v of word v / 64, v from first_global()).
    const std::vector<std::uint64_t>& used() const { return used_; }
    /// How many of this rank's vertices a face uses: the vertices the file will hold.
    std::uint64_t used_count() const;

    /// Brick `brick`'s vertices and flattened faces (global numbers), as added.
    void read_vertices(std::size_t brick, std::vector<ScratchVertex>& out);
    void read_faces(std::size_t brick, std::vector<std::uint32_t>& out);

private:
    int arity_;
    AtomicFileWriter vertices_, faces_;
    std::vector<std::uint64_t> vertex_first_{0}, index_first_{0};
    std::vector<std::uint64_t> used_;
    std::vector<ForeignCorner> foreign_;
    std::uint64_t first_global_ = 0;
};

}  // namespace pqdc::detail
