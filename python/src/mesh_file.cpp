#include "mesh_file.hpp"

#include <pqdc/exceptions.hpp>
#include <pqdc/mesh_io.hpp>

#include <pybind11/pybind11.h>

#include <mutex>
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

void write_mesh_file(MeshResult& result, const std::string& path, bool double_precision, bool normals) {
    MeshWriteOptions o;
    o.precision = double_precision ? VertexPrecision::float64 : VertexPrecision::float32;
    if (!normals) {
        pybind11::gil_scoped_release nogil;
        write_mesh(result.mesh, path, o);
        return;
    }
    const MeshFormat format = mesh_format_from_path(path);
    if (!format_holds_vertex_normals(format))
        throw option_error("Mesh.write: '" + path + "' is " + mesh_format_name(format) +
                           ", which holds no vertex normals; write .ply or .obj, or leave normals=False");
    const std::vector<openvdb::Vec3d>& n = vertex_normals(result);  // may sample (GIL held)
    pybind11::gil_scoped_release nogil;
    // The normals stand in the mesh only while it is written; the lock is
    // taken without the GIL, so a second writer waiting for it cannot block
    // this one's return.
    const std::lock_guard<std::mutex> lock(result.write_lock);
    result.mesh.normals = n;
    try {
        write_mesh(result.mesh, path, o);
    } catch (...) {
        std::vector<openvdb::Vec3d>().swap(result.mesh.normals);
        throw;
    }
    std::vector<openvdb::Vec3d>().swap(result.mesh.normals);
}

}  // namespace pqdc::python
