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

#include "io/mesh_stream_impl.hpp"

#include <stdexcept>

namespace pqdc {

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
    if (s.options.precision == VertexPrecision::float32)
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
    if (s.rank_part)
        throw std::logic_error("MeshStreamWriter: this writer holds one rank's part of '" + s.target +
                               "'; every rank finishes it together with finish(group)");
    if (s.broken) throw io_error("cannot write '" + s.target + "': an earlier part of it failed; start it again");
    s.broken = true;
    s.check_indices();
    const std::string header = s.header();
    io::AtomicFileWriter out(s.path);
    if (s.options.progress) {
        std::uint64_t bytes = header.size();
        if (s.format == MeshFormat::stl) bytes += 50 * (s.triangles + 2 * s.quads);
        else
            for (const auto& section : s.sections) bytes += section->position();
        out.set_progress(s.options.progress, bytes);
    }
    out.append(header);
    if (s.format == MeshFormat::stl) {
        const io::ReadMapping points(*s.sections[0], s.points * sizeof(openvdb::Vec3d), s.target);
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
MeshFormat MeshStreamWriter::format() const { return impl_->format; }
bool MeshStreamWriter::with_normals() const { return impl_->normals; }

namespace detail {

void StreamWriterParts::hold_rank_part(MeshStreamWriter& out) { out.impl_->rank_part = true; }

std::unique_ptr<MeshStreamWriter> StreamWriterParts::sibling(const MeshStreamWriter& out) {
    const MeshStreamWriter::Impl& s = *out.impl_;
    return std::make_unique<MeshStreamWriter>(s.path, s.options, s.normals);
}

void StreamWriterParts::absorb(MeshStreamWriter& into, MeshStreamWriter& later) {
    MeshStreamWriter::Impl &a = *into.impl_, &b = *later.impl_;
    if (a.broken || b.broken) throw io_error("cannot write '" + a.target + "': an earlier part of it failed; start it again");
    a.broken = true;  // until every section is in
    for (std::size_t k = 0; k < a.sections.size(); ++k) b.sections[k]->copy_into(*a.sections[k]);
    a.triangle_range.add(b.triangle_range, a.triangles);
    a.quad_range.add(b.quad_range, a.quads);
    a.points += b.points, a.triangles += b.triangles, a.quads += b.quads;
    b.sections.clear();
    b.broken = true;
    a.broken = false;
}

}  // namespace detail

}  // namespace pqdc
