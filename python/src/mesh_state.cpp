#include "mesh_state.hpp"

#include <pqdc/exceptions.hpp>

#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include <cstring>
#include <string>
#include <vector>

namespace py = pybind11;

namespace pqdc::python {
namespace {

constexpr int kStateVersion = 2;  // 2: with the checked precision

/// The bytes of a vector of fixed-size records, as Python bytes.
template <class T>
py::bytes record_bytes(const std::vector<T>& v) {
    return py::bytes(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(T));
}

template <class T>
std::vector<T> records(const py::handle& bytes, const char* what) {
    const std::string s = bytes.cast<std::string>();
    if (s.size() % sizeof(T) != 0) throw input_error(std::string("a pickled pqdc.Mesh has a damaged ") + what);
    std::vector<T> v(s.size() / sizeof(T));
    if (!s.empty()) std::memcpy(static_cast<void*>(v.data()), s.data(), s.size());
    return v;
}

}  // namespace

py::tuple mesh_state(MeshResult& result) {
    const VertexFields& fields = vertex_fields(result);  // sampled now if the grid is still there
    return py::make_tuple(kStateVersion, record_bytes(result.mesh.points), record_bytes(result.mesh.triangles),
                          record_bytes(result.mesh.quads), record_bytes(fields.normals), record_bytes(fields.values),
                          result.source.voxel_size,
                          py::make_tuple(result.counts, result.seconds, result.values, result.choices, result.labels,
                                         result.warnings),
                          result.fields_unavailable, result.checked_precision);
}

std::shared_ptr<MeshResult> mesh_from_state(const py::tuple& state) {
    if (state.size() != 10 || state[0].cast<int>() != kStateVersion)
        throw input_error("not a pickled pqdc.Mesh of this pqdc version; pickle it again with this one");
    auto out = std::make_shared<MeshResult>();
    out->mesh.points = records<openvdb::Vec3d>(state[1], "vertex array");
    out->mesh.triangles = records<openvdb::Vec3I>(state[2], "triangle array");
    out->mesh.quads = records<openvdb::Vec4I>(state[3], "quad array");
    const std::size_t n = out->mesh.points.size();
    for (const auto& t : out->mesh.triangles)
        for (int k = 0; k < 3; ++k)
            if (t[k] >= n) throw input_error("a pickled pqdc.Mesh has a damaged triangle array");
    for (const auto& q : out->mesh.quads)
        for (int k = 0; k < 4; ++k)
            if (q[k] >= n) throw input_error("a pickled pqdc.Mesh has a damaged quad array");
    out->fields.normals = records<openvdb::Vec3d>(state[4], "normal array");
    out->fields.values = records<double>(state[5], "value array");
    std::call_once(out->sampled, [] {});  // the fields are the saved ones; there is no grid to sample
    out->source.voxel_size = state[6].cast<double>();
    const py::tuple stats = state[7].cast<py::tuple>();
    out->counts = stats[0].cast<decltype(out->counts)>();
    out->seconds = stats[1].cast<decltype(out->seconds)>();
    out->values = stats[2].cast<decltype(out->values)>();
    out->choices = stats[3].cast<decltype(out->choices)>();
    out->labels = stats[4].cast<decltype(out->labels)>();
    out->warnings = stats[5].cast<decltype(out->warnings)>();
    out->fields_unavailable = state[8].cast<std::string>();
    out->checked_precision = state[9].cast<std::string>();
    return out;
}

}  // namespace pqdc::python
