// Writing a mesh that arrives in pieces and need not fit in memory (meshes
// of volumes larger than memory, made brick by brick). The file is the same,
// byte for byte, as write_mesh() of the whole mesh would write: vertices in
// the order they are appended, then every triangle, then every quad, in the
// order they are appended. Every format's header states counts known only at
// the end, so the sections go to scratch files in the target's directory
// (unlinked at once: nothing is left behind, whatever happens) and finish()
// assembles them into a temporary file that is renamed over the target, as
// write_mesh() does. Peak memory is a few buffers of 4 MiB (STL maps the
// points' scratch file at finish()); the target's disk needs room for about
// twice the file. Several processes (the ranks of a pqdc::RankGroup) can
// each append a part and write one file together with finish(group).
#pragma once

#include "pqdc/mesh.hpp"
#include "pqdc/mesh_io.hpp"

#include <cstdint>
#include <memory>
#include <string>

namespace pqdc {

class RankGroup;  // pqdc/distributed.hpp
namespace detail {
struct StreamWriterParts;  // the library's streamed runs: parts of one file written at once
}

/// How MeshStreamWriter::finish(group) brings the ranks' parts together.
enum class PartTransfer {
    /// Each rank writes its part into rank 0's temporary file, at the offset
    /// the other parts' sizes give it (the ranks format in parallel and no
    /// bytes cross the network to rank 0), when every rank can open that
    /// file: a file system all ranks share. Otherwise as through_root.
    shared_file,
    /// Each rank sends its part's bytes to rank 0, which writes them.
    through_root,
};

class MeshStreamWriter {
public:
    /// Starts writing `path` ("-" for standard output, which needs
    /// options.format) with write_mesh()'s options; `with_normals`: every
    /// piece brings one normal per point (OBJ vn, PLY nx ny nz). Throws
    /// option_error for an unknown format, io_error when the target's
    /// directory cannot hold the scratch files.
    MeshStreamWriter(const std::string& path, const MeshWriteOptions& options = {}, bool with_normals = false);
    /// Without finish(): the target is left as it was.
    ~MeshStreamWriter();
    MeshStreamWriter(const MeshStreamWriter&) = delete;
    MeshStreamWriter& operator=(const MeshStreamWriter&) = delete;

    /// Appends piece.points (and piece.normals) as the next vertices and
    /// piece's triangles and quads as the next faces of each kind. Face
    /// indices are global: they may refer to vertices of any piece, earlier
    /// or later; finish() checks them. Throws input_error for normals of the
    /// wrong count or, at float32 precision, a coordinate beyond float's
    /// range (naming the vertex's global index); io_error when a scratch
    /// file cannot be written. After a throw the writer only discards.
    void append(const Mesh& piece);

    /// Writes the file and renames it into place (throws input_error, naming
    /// the face, when an index is not below the final vertex count, and
    /// io_error). options.progress is called with the fraction assembled.
    void finish();

    /// Collective over `group`, called by every rank with a writer for the
    /// same target and options: writes the file of every rank's appended
    /// pieces, rank 0's first, then rank 1's, and so on (as if all had been
    /// appended to one writer in rank order), and renames it into place.
    /// Face indices are global over all parts. Every rank returns, or every
    /// rank throws: input_error for an index not below the total vertex
    /// count (naming the face's number in the whole file), io_error when any
    /// rank fails to write (naming the rank), and nothing is left behind.
    /// STL needs every corner's coordinates in one place, so only rank 0's
    /// writer may hold STL pieces (logic_error otherwise). A group of one is
    /// finish().
    void finish(RankGroup& group, PartTransfer transfer = PartTransfer::shared_file);

    /// The target path as given ("-": standard output).
    const std::string& path() const;
    std::uint64_t point_count() const;
    std::uint64_t triangle_count() const;
    std::uint64_t quad_count() const;
    /// The format being written (from options.format or the path).
    MeshFormat format() const;
    /// Whether every piece brings one normal per point (the constructor's with_normals).
    bool with_normals() const;

private:
    friend struct detail::StreamWriterParts;
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace pqdc
