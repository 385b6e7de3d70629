// Reading and writing meshes. Writers are atomic: they write a temporary file
// next to the target and rename it into place only after every byte was
// written and flushed, so a failure never leaves a partial or clobbered file.
#pragma once

#include "pqdc/mesh.hpp"

#include <string>

namespace pqdc {

enum class mesh_format { obj, ply, stl };

/// Format from the file extension (.obj, .ply, .stl; case-insensitive).
/// Throws option_error naming the path and the supported extensions.
mesh_format mesh_format_from_path(const std::string& path);

/// Writes OBJ (text, shortest round-trip decimal coordinates), binary
/// little-endian PLY (double vertices, int32 face lists) or binary STL
/// (float, quads split into two triangles) chosen by extension. Atomic;
/// throws io_error naming the path and the reason.
void write_mesh(const Mesh& mesh, const std::string& path);

/// Reads OBJ (v/f lines; faces of 3 or 4 vertices; f a/b/c forms accepted)
/// or PLY (ascii or binary little-endian; float or double vertices). Throws
/// input_error naming the path and what is wrong.
Mesh read_mesh(const std::string& path);

}  // namespace pqdc
