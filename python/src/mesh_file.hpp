// pqdc.read_mesh(): a mesh file (.obj, .ply, .off, .stl) as a pqdc.Mesh, to
// decimate or write again from Python.
#pragma once

#include "extract_job.hpp"

#include <memory>
#include <string>

namespace pqdc::python {

/// pqdc::read_mesh with the GIL released. The file's vertex normals (PLY
/// nx/ny/nz, OBJ vn) become the mesh's; there are no field values.
std::shared_ptr<MeshResult> read_mesh_file(const std::string& path);

}  // namespace pqdc::python
