// Internal: MeshStreamWriter's state, shared by its single-writer finish()
// (mesh_stream.cpp) and the collective finish(group) (mesh_stream_ranks.cpp).
#pragma once

#include "pqdc/exceptions.hpp"
#include "pqdc/mesh_stream.hpp"

#include "io/mesh_io_internal.hpp"

#include <sys/mman.h>

#include <cerrno>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

namespace pqdc {
namespace io {

/// The largest index seen in one kind of face, and the first face holding it
/// (named when that index turns out to be out of range).
struct IndexRange {
    std::uint64_t max = 0, face = 0;
    bool any = false;

    void add(const unsigned* idx, std::size_t count, int arity, std::uint64_t first_face) {
        for (std::size_t f = 0; f < count; ++f)
            for (int k = 0; k < arity; ++k) {
                const unsigned i = idx[f * std::size_t(arity) + std::size_t(k)];
                if (!any || i > max) {
                    max = i;
                    face = first_face + f;
                    any = true;
                }
            }
    }

    /// The range of faces that follow `first_face` faces already counted
    /// here (another writer's part, appended after this one's).
    void add(const IndexRange& later, std::uint64_t first_face) {
        if (later.any && (!any || later.max > max)) *this = {later.max, first_face + later.face, true};
    }
};

/// The scratch file's bytes mapped for reading (STL's points).
class ReadMapping {
public:
    ReadMapping(io::AtomicFileWriter& section, std::uint64_t bytes, const std::string& target) : bytes_(bytes) {
        if (bytes == 0) return;
        void* p = ::mmap(nullptr, bytes, PROT_READ, MAP_PRIVATE, section.flushed_descriptor(), 0);
        if (p == MAP_FAILED)
            throw io_error("cannot write '" + target + "': " + std::strerror(errno) +
                           " (while mapping the vertices written so far)");
        data_ = p;
    }
    ~ReadMapping() {
        if (data_) ::munmap(data_, bytes_);
    }
    ReadMapping(const ReadMapping&) = delete;
    ReadMapping& operator=(const ReadMapping&) = delete;
    const openvdb::Vec3d* points() const { return static_cast<const openvdb::Vec3d*>(data_); }

private:
    void* data_ = nullptr;
    std::uint64_t bytes_;
};

}  // namespace io

struct MeshStreamWriter::Impl {
    std::string path, target;  // target: what messages call it
    MeshWriteOptions options;
    MeshFormat format;
    bool normals;
    bool broken = false;
    std::uint64_t points = 0, triangles = 0, quads = 0;
    io::IndexRange triangle_range, quad_range;
    bool rank_part = false;  ///< holds one rank's part: only finish(group) may write it
    // Sections in file order: OBJ v, vn, f3, f4; PLY vertices, f3, f4;
    // OFF points, f3, f4; STL raw points, raw f3, raw f4.
    std::vector<std::unique_ptr<io::AtomicFileWriter>> sections;

    Impl(const std::string& p, const MeshWriteOptions& o, bool n)
        : path(p), target(p == "-" ? "standard output" : p), options(o), normals(n) {
        if (p == "-" && !o.format)
            throw option_error("writing a mesh to standard output needs a format (obj, ply, off or stl)");
        format = o.format ? *o.format : mesh_format_from_path(p);
        if (format == MeshFormat::stl) options.precision = VertexPrecision::float32;
        const int count = format == MeshFormat::obj ? 4 : 3;
        for (int i = 0; i < count; ++i)
            sections.push_back(std::make_unique<io::AtomicFileWriter>(path, io::AtomicFileWriter::Scratch{}));
    }

    void append_points(const Mesh& piece) {
        const VertexPrecision precision = options.precision;
        const openvdb::Vec3d* n = normals ? piece.normals.data() : nullptr;
        const std::size_t count = piece.points.size();
        switch (format) {
            case MeshFormat::obj:
                io::obj_points(piece.points.data(), count, "v", precision, *sections[0]);
                io::obj_points(n, normals ? count : 0, "vn", precision, *sections[1]);
                break;
            case MeshFormat::ply: io::ply_vertices(piece.points.data(), n, count, precision, *sections[0]); break;
            case MeshFormat::off: io::off_points(piece.points.data(), count, precision, *sections[0]); break;
            case MeshFormat::stl: sections[0]->append(piece.points.data(), count * sizeof(openvdb::Vec3d)); break;
        }
    }

    void append_faces(const unsigned* idx, std::size_t count, int arity) {
        io::AtomicFileWriter& out = *sections[sections.size() - (arity == 3 ? 2 : 1)];
        switch (format) {
            case MeshFormat::obj: io::obj_faces(idx, count, arity, normals, out); break;
            case MeshFormat::ply: io::ply_faces(idx, count, arity, out); break;
            case MeshFormat::off: io::off_faces(idx, count, arity, out); break;
            case MeshFormat::stl: out.append(idx, count * std::size_t(arity) * sizeof(unsigned)); break;
        }
    }

    /// write_mesh() declares normals only for a mesh that has them: none
    /// without points, so neither does an empty streamed mesh (the same
    /// header in core and streamed).
    io::MeshCounts counts() const { return {points, triangles, quads, normals && points > 0}; }

    std::string header() const {
        switch (format) {
            case MeshFormat::obj: return io::obj_header(counts());
            case MeshFormat::ply: return io::ply_header(counts(), options.precision, target);
            case MeshFormat::off: return io::off_header(counts());
            case MeshFormat::stl: return io::stl_header(counts(), target);
        }
        return {};
    }

    void check_indices() const {
        if (triangle_range.any && triangle_range.max >= points)
            io::throw_bad_index(target, "triangle", triangle_range.face, triangle_range.max, points);
        if (quad_range.any && quad_range.max >= points)
            io::throw_bad_index(target, "quad", quad_range.face, quad_range.max, points);
    }

    /// STL: facets of one raw index section, read back in chunks.
    void stl_facets_of(io::AtomicFileWriter& section, int arity, const openvdb::Vec3d* p, io::AtomicFileWriter& out) {
        const std::size_t face_bytes = std::size_t(arity) * sizeof(unsigned);
        std::vector<unsigned> chunk((std::size_t(1) << 20) * std::size_t(arity));
        const int fd = section.flushed_descriptor();
        const std::uint64_t total = section.position();
        for (std::uint64_t at = 0; at < total;) {
            const std::size_t want = std::size_t(std::min<std::uint64_t>(chunk.size() * sizeof(unsigned), total - at));
            const ssize_t got = ::pread(fd, chunk.data(), want, off_t(at));
            if (got < 0 && errno == EINTR) continue;
            if (got <= 0 || std::size_t(got) % face_bytes != 0)
                throw io_error("cannot write '" + target + "': " + std::strerror(got < 0 ? errno : EIO) +
                               " (while reading back the faces written so far)");
            io::stl_facets(p, chunk.data(), std::size_t(got) / face_bytes, arity, out);
            at += std::uint64_t(got);
        }
    }
};

namespace detail {

/// What the library's streamed runs do with writers beyond the public API.
struct StreamWriterParts {
    /// Marks `out` as one rank's part: only finish(group) may write it.
    static void hold_rank_part(MeshStreamWriter& out);
    /// A writer for the same target, options and normals, for the pieces
    /// of one in-process run of bricks (absorbed later, never finished).
    static std::unique_ptr<MeshStreamWriter> sibling(const MeshStreamWriter& out);
    /// Appends everything `later` holds to `into`, as if its pieces had
    /// been appended to `into` (a byte copy of the formatted sections);
    /// `later` is then spent.
    static void absorb(MeshStreamWriter& into, MeshStreamWriter& later);
};

}  // namespace detail
}  // namespace pqdc
