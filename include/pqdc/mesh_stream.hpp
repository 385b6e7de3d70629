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
// twice the file.
#pragma once

#include "pqdc/mesh.hpp"
#include "pqdc/mesh_io.hpp"

#include <cstdint>
#include <memory>
#include <string>

namespace pqdc {

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

    /// The target path as given ("-": standard output).
    const std::string& path() const;
    std::uint64_t point_count() const;
    std::uint64_t triangle_count() const;
    std::uint64_t quad_count() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace pqdc
