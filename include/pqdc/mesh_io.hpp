// Reading and writing meshes. Writers are atomic: they write a temporary file
// next to the target and rename it into place only after every byte was
// written and flushed, so a failure never leaves a partial or clobbered file.
// The path "-" writes to standard output (not atomic; a format is required).
#pragma once

#include "pqdc/mesh.hpp"

#include <cstdint>
#include <functional>
#include <optional>
#include <string>

namespace pqdc {

enum class MeshFormat { obj, ply, stl, off };
/// The name before 0.1.1, kept for callers' source.
using mesh_format [[deprecated("pqdc::mesh_format is now pqdc::MeshFormat")]] = MeshFormat;

struct MeshWriteOptions {
    /// File format; std::nullopt (default) = from the path's extension. Required for "-".
    std::optional<MeshFormat> format;
    /// PLY stores binary floats of this precision; OBJ and OFF print the
    /// shortest decimal that reads back to the same value at this precision.
    /// STL is always float32. Default float32.
    VertexPrecision precision = VertexPrecision::float32;
    /// Called with the fraction of the file written so far (0..1), from the
    /// writing thread, about every 4 MiB. Default: none.
    std::function<void(double)> progress;
};

/// Format from the file extension (.obj, .ply, .off, .stl; case-insensitive).
/// Throws option_error naming the path and the supported extensions.
MeshFormat mesh_format_from_path(const std::string& path);

/// Format from its name ("obj", "ply", "off", "stl"; case-insensitive).
/// Throws option_error naming the value and the supported names.
MeshFormat mesh_format_from_name(const std::string& name);

/// The format's name as messages give it: "OBJ", "PLY", "OFF" or "STL".
const char* mesh_format_name(MeshFormat format);

/// Whether write_mesh() stores vertex normals in this format: PLY (nx/ny/nz)
/// and OBJ (vn) do; OFF and STL have no place for them.
bool format_holds_vertex_normals(MeshFormat format);

/// The precision write_mesh() stores vertices in: `requested`, except in
/// STL, which holds floats only. What a caller checks the mesh at
/// (ExtractOptions and DecimateOptions::stored_precision).
VertexPrecision stored_vertex_precision(MeshFormat format, VertexPrecision requested);

/// Writes OBJ or ASCII OFF (text; OFF with edge count 0 and no comments),
/// binary little-endian PLY (float or double vertices, int32 face lists) or
/// binary STL (float, quads split into two triangles). Vertex normals, when
/// mesh.normals is not empty, go to OBJ `vn` lines (faces then `f a//a ...`)
/// and PLY nx/ny/nz properties; OFF and STL have no per-vertex normals.
/// Atomic; throws io_error naming the path and the reason, input_error for
/// a mesh with out-of-range indices or normals of the wrong count.
void write_mesh(const Mesh& mesh, const std::string& path, const MeshWriteOptions& options = {});

/// Reads OBJ (v/vn/f lines; f a/b/c forms accepted), PLY (ascii or binary
/// little-endian; any numeric vertex type; nx/ny/nz read as normals), ASCII
/// OFF (Geomview/CGAL: OFF with optional ST/C/N prefixes whose extra vertex
/// values are skipped, '#' comments, face colors ignored; non-finite
/// coordinates rejected) or binary STL (corners with identical coordinates
/// become one shared vertex). In every format faces of 3 and 4 vertices
/// become triangles and quads and larger polygons triangle fans around their
/// first vertex from which no fan triangle folds over (a concave polygon's
/// fan from a corner that does not see it all would overlap itself; the
/// first vertex when none does). OBJ normals are kept when there is one `vn` per `v`. Throws
/// input_error naming the path and, for text, the line of what is wrong.
Mesh read_mesh(const std::string& path);

/// The number of faces a mesh file's header announces, from its first bytes
/// alone: PLY (the face element's count), OFF (the counts after "OFF") and
/// binary STL (the triangle count, when the file's size matches it). Each
/// face becomes at least one triangle, so a file read_mesh() accepts holds
/// at least this many; callers use it to refuse a file too large for them
/// before reading it. std::nullopt when the format announces no count (OBJ,
/// ASCII STL), or the header cannot be parsed or announces more faces than
/// the file's size can hold: read_mesh() then says what is wrong. Throws
/// input_error naming the path when the file cannot be opened.
std::optional<std::uint64_t> mesh_file_face_count(const std::string& path);

}  // namespace pqdc
