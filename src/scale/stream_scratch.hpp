// What a streamed run (issue 14, phase 2: scale/stream_cells.hpp) keeps of
// the mesh outside memory: each brick's own vertices (position before the
// untangle stage, cell and patch, from which the safe position follows) and
// own faces (global vertex
// indices, before unused vertices are dropped), appended brick after brick
// to two unlinked scratch files next to the output, and read back one brick
// at a time by the untangle and output stages. In memory stay only the
// per-brick counts and one bit per vertex (used by a face or not).
#pragma once

#include "io/atomic_file.hpp"

#include <openvdb/openvdb.h>

#include <cstdint>
#include <string>
#include <vector>

namespace pqdc::detail {

struct CoordHash {
    std::size_t operator()(const openvdb::Coord& c) const {
        return std::size_t(std::uint64_t(std::uint32_t(c.x())) * 0x9E3779B97F4A7C15ull ^
                           std::uint64_t(std::uint32_t(c.y())) * 0xC2B2AE3D27D4EB4Full ^
                           std::uint64_t(std::uint32_t(c.z())) * 0x165667B19E3779F9ull);
    }
};

struct ScratchVertex {
    openvdb::Vec3d position;  ///< world space, as the cells stage placed it
    openvdb::Coord cell;      ///< index space: the cell the vertex belongs to
    /// The cell's corner signs, joined faces and the vertex's patch: what
    /// safe_patch_position() (uniform/safe_positions.hpp) needs.
    std::uint8_t config = 0, joined = 0, patch = 0, unused = 0;
};
static_assert(sizeof(ScratchVertex) == 40, "scratch records are 40 bytes");

class StreamScratch {
public:
    /// Scratch files next to `target` (the output path; "-": the temporary
    /// directory). `quads`: faces are quads, else triangles.
    StreamScratch(const std::string& target, bool quads);

    /// Appends the next brick: its vertices (numbered on from vertex_count())
    /// and its faces (4 indices per quad, 3 per triangle, flattened).
    void add_brick(const std::vector<ScratchVertex>& vertices, const std::vector<std::uint32_t>& face_indices);

    std::size_t bricks() const { return vertex_first_.size() - 1; }
    std::uint64_t vertex_count() const { return vertex_first_.back(); }
    std::uint64_t first_vertex(std::size_t brick) const { return vertex_first_[brick]; }
    int arity() const { return arity_; }
    /// The used flags of every vertex (bit v of word v / 64).
    const std::vector<std::uint64_t>& used() const { return used_; }
    /// How many vertices a face uses: the vertices the file will hold.
    std::uint64_t used_count() const;

    /// Brick `brick`'s vertices and flattened faces, as added.
    void read_vertices(std::size_t brick, std::vector<ScratchVertex>& out);
    void read_faces(std::size_t brick, std::vector<std::uint32_t>& out);

private:
    int arity_;
    AtomicFileWriter vertices_, faces_;
    std::vector<std::uint64_t> vertex_first_{0}, index_first_{0};
    std::vector<std::uint64_t> used_;
};

}  // namespace pqdc::detail
