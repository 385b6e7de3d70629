// MeshStreamWriter: write_mesh()'s files from a mesh that arrives in pieces.
//
// Each format is written as its sections (mesh_io_internal.hpp) by the same
// functions write_mesh() uses, so the bytes match by construction; here the
// sections go to scratch files while pieces arrive, and finish() writes the
// header, now that the counts are known, and copies the sections behind it.
// Text sections are formatted as they arrive. STL facets need the corners'
// coordinates, which may belong to any piece: its points and face indices are
// kept raw and the facets are made at finish() from the mapped points.
#include "pqdc/mesh_stream.hpp"

#include "pqdc/exceptions.hpp"

#include "io/mesh_io_internal.hpp"

#include <sys/mman.h>

#include <cerrno>
#include <cstring>
#include <limits>
#include <vector>

namespace pqdc {
namespace {

using io::AtomicFileWriter;

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
};

/// The scratch file's bytes mapped for reading (STL's points).
class ReadMapping {
public:
    ReadMapping(AtomicFileWriter& section, std::uint64_t bytes, const std::string& target) : bytes_(bytes) {
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

}  // namespace

struct MeshStreamWriter::Impl {
    std::string path, target;  // target: what messages call it
    MeshWriteOptions options;
    mesh_format format;
    bool normals;
    bool broken = false;
    std::uint64_t points = 0, triangles = 0, quads = 0;
    IndexRange triangle_range, quad_range;
    // Sections in file order: OBJ v, vn, f3, f4; PLY vertices, f3, f4;
    // OFF points, f3, f4; STL raw points, raw f3, raw f4.
    std::vector<std::unique_ptr<AtomicFileWriter>> sections;

    Impl(const std::string& p, const MeshWriteOptions& o, bool n)
        : path(p), target(p == "-" ? "standard output" : p), options(o), normals(n) {
        if (p == "-" && !o.format)
            throw option_error("writing a mesh to standard output needs a format (obj, ply, off or stl)");
        format = o.format ? *o.format : mesh_format_from_path(p);
        if (format == mesh_format::stl) options.precision = vertex_precision::float32;
        const int count = format == mesh_format::obj ? 4 : 3;
        for (int i = 0; i < count; ++i)
            sections.push_back(std::make_unique<AtomicFileWriter>(path, AtomicFileWriter::Scratch{}));
    }

    void append_points(const Mesh& piece) {
        const vertex_precision precision = options.precision;
        const openvdb::Vec3d* n = normals ? piece.normals.data() : nullptr;
        const std::size_t count = piece.points.size();
        switch (format) {
            case mesh_format::obj:
                io::obj_points(piece.points.data(), count, "v", precision, *sections[0]);
                io::obj_points(n, normals ? count : 0, "vn", precision, *sections[1]);
                break;
            case mesh_format::ply: io::ply_vertices(piece.points.data(), n, count, precision, *sections[0]); break;
            case mesh_format::off: io::off_points(piece.points.data(), count, precision, *sections[0]); break;
            case mesh_format::stl: sections[0]->append(piece.points.data(), count * sizeof(openvdb::Vec3d)); break;
        }
    }

    void append_faces(const unsigned* idx, std::size_t count, int arity) {
        AtomicFileWriter& out = *sections[sections.size() - (arity == 3 ? 2 : 1)];
        switch (format) {
            case mesh_format::obj: io::obj_faces(idx, count, arity, normals, out); break;
            case mesh_format::ply: io::ply_faces(idx, count, arity, out); break;
            case mesh_format::off: io::off_faces(idx, count, arity, out); break;
            case mesh_format::stl: out.append(idx, count * std::size_t(arity) * sizeof(unsigned)); break;
        }
    }

    io::MeshCounts counts() const { return {points, triangles, quads, normals}; }

    std::string header() const {
        switch (format) {
            case mesh_format::obj: return io::obj_header(counts());
            case mesh_format::ply: return io::ply_header(counts(), options.precision, target);
            case mesh_format::off: return io::off_header(counts());
            case mesh_format::stl: return io::stl_header(counts(), target);
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
    void stl_facets_of(AtomicFileWriter& section, int arity, const openvdb::Vec3d* p, AtomicFileWriter& out) {
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

MeshStreamWriter::MeshStreamWriter(const std::string& path, const MeshWriteOptions& options, bool with_normals)
    : impl_(std::make_unique<Impl>(path, options, with_normals)) {}

MeshStreamWriter::~MeshStreamWriter() = default;

void MeshStreamWriter::append(const Mesh& piece) {
    Impl& s = *impl_;
    if (s.broken) throw io_error("cannot write '" + s.target + "': an earlier part of it failed; start it again");
    s.broken = true;  // until this piece is in
    if (s.normals && piece.normals.size() != piece.points.size())
        throw input_error("cannot write '" + s.target + "': a piece has " + std::to_string(piece.normals.size()) +
                          " normals for " + std::to_string(piece.points.size()) +
                          " points (the writer was opened with normals: give one per point)");
    if (s.options.precision == vertex_precision::float32)
        for (std::size_t i = 0; i < piece.points.size(); ++i)
            io::check_float_range(piece.points[i], s.points + i, s.target);
    s.append_points(piece);
    s.triangle_range.add(io::triangle_indices(piece), piece.triangles.size(), 3, s.triangles);
    s.quad_range.add(io::quad_indices(piece), piece.quads.size(), 4, s.quads);
    s.append_faces(io::triangle_indices(piece), piece.triangles.size(), 3);
    s.append_faces(io::quad_indices(piece), piece.quads.size(), 4);
    s.points += piece.points.size();
    s.triangles += piece.triangles.size();
    s.quads += piece.quads.size();
    s.broken = false;
}

void MeshStreamWriter::finish() {
    Impl& s = *impl_;
    if (s.broken) throw io_error("cannot write '" + s.target + "': an earlier part of it failed; start it again");
    s.broken = true;
    s.check_indices();
    const std::string header = s.header();
    AtomicFileWriter out(s.path);
    if (s.options.progress) {
        std::uint64_t bytes = header.size();
        if (s.format == mesh_format::stl) bytes += 50 * (s.triangles + 2 * s.quads);
        else
            for (const auto& section : s.sections) bytes += section->position();
        out.set_progress(s.options.progress, bytes);
    }
    out.append(header);
    if (s.format == mesh_format::stl) {
        const ReadMapping points(*s.sections[0], s.points * sizeof(openvdb::Vec3d), s.target);
        s.stl_facets_of(*s.sections[1], 3, points.points(), out);
        s.stl_facets_of(*s.sections[2], 4, points.points(), out);
    } else {
        for (const auto& section : s.sections) section->copy_into(out);
    }
    out.commit();
    s.sections.clear();
    if (s.options.progress) s.options.progress(1.0);
}

const std::string& MeshStreamWriter::path() const { return impl_->path; }
std::uint64_t MeshStreamWriter::point_count() const { return impl_->points; }
std::uint64_t MeshStreamWriter::triangle_count() const { return impl_->triangles; }
std::uint64_t MeshStreamWriter::quad_count() const { return impl_->quads; }

}  // namespace pqdc
