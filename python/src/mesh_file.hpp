// pqdc.read_mesh() and Mesh.write(): mesh files (.obj, .ply, .off, .stl)
// from and to Python.
#pragma once

#include "extract_job.hpp"

#include <memory>
#include <string>

namespace pqdc::python {

/// pqdc::read_mesh with the GIL released. The file's vertex normals (PLY
/// nx/ny/nz, OBJ vn) become the mesh's; there are no field values.
std::shared_ptr<MeshResult> read_mesh_file(const std::string& path);

/// pqdc::write_mesh with the GIL released; with `normals`, the mesh's
/// vertex normals too (vertex_normals(): sampled from the grid first when
/// needed), which only PLY and OBJ hold (option_error for OFF and STL).
void write_mesh_file(MeshResult& result, const std::string& path, bool double_precision, bool normals);

}  // namespace pqdc::python
