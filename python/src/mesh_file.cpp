#include "mesh_file.hpp"

#include <pqdc/mesh_io.hpp>

#include <pybind11/pybind11.h>

#include <utility>

namespace pqdc::python {

std::shared_ptr<MeshResult> read_mesh_file(const std::string& path) {
    auto out = std::make_shared<MeshResult>();
    {
        pybind11::gil_scoped_release nogil;
        out->mesh = read_mesh(path);
    }
    out->labels.emplace_back("source", path);
    out->counts.insert(out->counts.end(), {{"vertices", out->mesh.points.size()},
                                           {"triangles", out->mesh.triangles.size()},
                                           {"quads", out->mesh.quads.size()}});
    // The file's normals are the mesh's vertex normals; the values have no source.
    out->fields.normals = std::move(out->mesh.normals);
    out->mesh.normals.clear();
    out->fields_unavailable = "a mesh read from '" + path + "' has no field to sample vertex " +
                              (out->fields.normals.empty() ? "normals or values" : "values") + " from";
    return out;
}

}  // namespace pqdc::python
