// Reading and writing meshes. Writers are atomic: they write a temporary file
// next to the target and rename it into place only after every byte was
// written and flushed, so a failure never leaves a partial or clobbered file.
#pragma once

#include "pqdc/mesh.hpp"

#include <string>

namespace pqdc {

enum class mesh_format { obj, ply, stl, off };

/// Format from the file extension (.obj, .ply, .off, .stl; case-insensitive).
/// Throws option_error naming the path and the supported extensions.
mesh_format mesh_format_from_path(const std::string& path);

/// Writes OBJ or ASCII OFF (text, shortest round-trip decimal coordinates,
/// OFF with edge count 0 and no comments), binary little-endian PLY (double
/// vertices, int32 face lists) or binary STL (float, quads split into two
/// triangles) chosen by extension. Atomic; throws io_error naming the path
/// and the reason.
void write_mesh(const Mesh& mesh, const std::string& path);

/// Reads OBJ (v/f lines; f a/b/c forms accepted), PLY (ascii or binary
/// little-endian; float or double vertices) or ASCII OFF (Geomview/CGAL: OFF
/// with optional ST/C/N prefixes whose extra vertex values are skipped, '#'
/// comments, face colors ignored; non-finite coordinates rejected). In every
/// format faces of 3 and 4 vertices become triangles and quads and larger
/// polygons triangle fans around their first vertex. STL is not read. Throws
/// input_error naming the path and, for text, the line of what is wrong.
Mesh read_mesh(const std::string& path);

}  // namespace pqdc
