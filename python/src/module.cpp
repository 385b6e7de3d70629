// pqdc._pqdc: the compiled half of the Python package (see python/pqdc/ for
// the public API). Exceptions are the classes defined in pqdc/_errors.py.
#include "decimate_job.hpp"
#include "extract_job.hpp"
#include "grid_bridge.hpp"
#include "mesh_file.hpp"
#include "mesh_state.hpp"
#include "python_names.hpp"

#include <pqdc/decimate.hpp>
#include <pqdc/exceptions.hpp>
#include <pqdc/extract.hpp>
#include <pqdc/mesh_io.hpp>
#include <pqdc/version.hpp>

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <openvdb/openvdb.h>

#include <cstdint>
#include <limits>
#include <string>
#include <utility>

namespace py = pybind11;
using pqdc::python::DecimateRequest;
using pqdc::python::MeshResult;
using pqdc::python::Request;
using pqdc::python::StreamRequest;
using pqdc::python::in_python_names;

namespace {

/// The Python exception classes, looked up once at import (never freed:
/// they live as long as the interpreter's module table).
struct ErrorClasses {
    PyObject *error, *option, *input, *write, *resource, *cancelled;
};
ErrorClasses errors;

void translate(std::exception_ptr p) {
    try {
        if (p) std::rethrow_exception(p);
    } catch (const pqdc::option_error& e) {
        PyErr_SetString(errors.option, in_python_names(e.what()).c_str());
    } catch (const pqdc::input_error& e) {
        PyErr_SetString(errors.input, in_python_names(e.what()).c_str());
    } catch (const pqdc::io_error& e) {
        PyErr_SetString(errors.write, e.what());
    } catch (const pqdc::resource_error& e) {
        PyErr_SetString(errors.resource, in_python_names(e.what()).c_str());
    } catch (const pqdc::cancelled_error& e) {
        PyErr_SetString(errors.cancelled, e.what());
    } catch (const pqdc::error& e) {
        PyErr_SetString(errors.error, e.what());
    } catch (const openvdb::Exception& e) {
        PyErr_SetString(errors.error, e.what());
    }
}

/// A read-only numpy view of `count` rows of `cols` T's at `data`, keeping
/// `owner` (the MeshResult's Python object) alive.
template <class T>
py::array view(const void* data, std::size_t count, std::size_t cols, const py::object& owner) {
    static const T empty[4] = {};
    py::array a(py::dtype::of<T>(), {py::ssize_t(count), py::ssize_t(cols)},
                {py::ssize_t(cols * sizeof(T)), py::ssize_t(sizeof(T))},
                static_cast<const T*>(count ? data : empty), owner);
    py::detail::array_proxy(a.ptr())->flags &= ~py::detail::npy_api::NPY_ARRAY_WRITEABLE_;
    return a;
}

/// Face indices as int32 without copying while they fit (< 2^31 vertices,
/// always true below 2^31), else an int64 copy.
template <class Face, std::size_t N>
py::array face_view(const std::vector<Face>& faces, std::size_t vertices, const py::object& owner) {
    static_assert(sizeof(Face) == N * sizeof(std::uint32_t), "faces are packed 32-bit indices");
    if (vertices <= std::size_t(std::numeric_limits<std::int32_t>::max()))
        return view<std::int32_t>(faces.data(), faces.size(), N, owner);
    py::array_t<std::int64_t> copy({py::ssize_t(faces.size()), py::ssize_t(N)});
    auto m = copy.mutable_unchecked<2>();
    for (std::size_t i = 0; i < faces.size(); ++i)
        for (std::size_t j = 0; j < N; ++j) m(py::ssize_t(i), py::ssize_t(j)) = faces[i][j];
    return std::move(copy);
}

py::dict stats_dict(const MeshResult& r) {
    py::dict d;
    for (const auto& [k, v] : r.counts) d[py::str(k)] = v;
    for (const auto& [k, v] : r.seconds) d[py::str(k)] = v;
    for (const auto& [k, v] : r.values) d[py::str(k)] = v;
    for (const auto& [k, v] : r.choices) d[py::str(k)] = v;
    for (const auto& [k, v] : r.labels) d[py::str(k)] = v;
    d["warnings"] = r.warnings;
    return d;
}

void bind_request(py::module_& m) {
    py::class_<Request>(m, "Request", "Checked options of pqdc.extract() (internal).")
        .def(py::init<>())
        .def_readwrite("isovalue", &Request::isovalue)
        .def_readwrite("sigma_n", &Request::sigma_n)
        .def_readwrite("interior", &Request::interior)
        .def_readwrite("faces", &Request::faces)
        .def_readwrite("normals", &Request::normals)
        .def_readwrite("denoise", &Request::denoise)
        .def_readwrite("containment", &Request::containment)
        .def_readwrite("adaptive", &Request::adaptive)
        .def_readwrite("max_error", &Request::max_error)
        .def_readwrite("max_cell_size", &Request::max_cell_size)
        .def_readwrite("threads", &Request::threads)
        .def_readwrite("memory_limit", &Request::memory_limit)
        .def_readwrite("min_component", &Request::min_component)
        .def_readwrite("progress", &Request::progress)
        .def_readwrite("bbox", &Request::bbox)
        .def_readwrite("mask_grid", &Request::mask_grid)
        .def_readwrite("mask_path", &Request::mask_path)
        .def_readwrite("mask_grid_name", &Request::mask_grid_name)
        .def_readwrite("invert_mask", &Request::invert_mask)
        .def_readwrite("double_precision", &Request::double_precision)
        .def_readwrite("spacing", &Request::spacing)
        .def_readwrite("origin", &Request::origin)
        .def_readwrite("zyx", &Request::zyx)
        .def_readwrite("sparse", &Request::sparse);
}

void bind_mesh(py::module_& m) {
    py::class_<MeshResult, std::shared_ptr<MeshResult>>(m, "MeshData", "The C++ mesh behind pqdc.Mesh (internal).")
        .def_property_readonly("vertices", [](py::object self) {
            const auto& r = self.cast<const MeshResult&>();
            return view<double>(r.mesh.points.data(), r.mesh.points.size(), 3, self);
        })
        .def_property_readonly("triangles", [](py::object self) {
            const auto& r = self.cast<const MeshResult&>();
            return face_view<openvdb::Vec3I, 3>(r.mesh.triangles, r.mesh.points.size(), self);
        })
        .def_property_readonly("quads", [](py::object self) {
            const auto& r = self.cast<const MeshResult&>();
            return face_view<openvdb::Vec4I, 4>(r.mesh.quads, r.mesh.points.size(), self);
        })
        .def_property_readonly("normals", [](py::object self) {
            const auto& n = pqdc::python::vertex_normals(self.cast<MeshResult&>());
            return view<double>(n.data(), n.size(), 3, self);
        })
        .def_property_readonly("values", [](py::object self) {
            const auto& v = pqdc::python::vertex_values(self.cast<MeshResult&>());
            return view<double>(v.data(), v.size(), 1, self).attr("reshape")(-1);
        })
        .def_property_readonly("stats", [](const MeshResult& r) { return stats_dict(r); })
        .def_property_readonly("checked_precision", [](const MeshResult& r) { return r.checked_precision; })
        .def("decimate", [](MeshResult& r, const DecimateRequest& request) {
            return pqdc::python::decimate_result(r, request);
        })
        .def("write", &pqdc::python::write_mesh_file)
        .def(py::pickle([](MeshResult& r) { return pqdc::python::mesh_state(r); },
                        [](const py::tuple& state) { return pqdc::python::mesh_from_state(state); }));
}

}  // namespace

PYBIND11_MODULE(_pqdc, m) {
    m.doc() = "Compiled core of the pqdc package; use the pqdc module.";
    m.attr("__version__") = pqdc::version_string;  // the one version, from CMake's project()
    openvdb::initialize();
    const py::module_ e = py::module_::import("pqdc._errors");
    const auto keep = [&e](const char* name) { return py::object(e.attr(name)).release().ptr(); };
    errors = {keep("Error"), keep("OptionError"), keep("InputError"),
              keep("WriteError"), keep("ResourceError"), keep("CancelledError")};
    py::register_exception_translator(&translate);
    m.attr("SIGMA_N_AUTO_VALUE") = pqdc::sigma_n_auto;
    bind_request(m);
    bind_mesh(m);
    py::class_<DecimateRequest>(m, "DecimateRequest", "Checked options of pqdc.decimate() (internal).")
        .def(py::init<>())
        .def_readwrite("target_faces", &DecimateRequest::target_faces)
        .def_readwrite("target_ratio", &DecimateRequest::target_ratio)
        .def_readwrite("max_distance", &DecimateRequest::max_distance)
        .def_readwrite("voxel_size", &DecimateRequest::voxel_size)
        .def_readwrite("metric", &DecimateRequest::metric)
        .def_readwrite("sigma_position", &DecimateRequest::sigma_position)
        .def_readwrite("sigma_normal", &DecimateRequest::sigma_normal)
        .def_readwrite("threads", &DecimateRequest::threads)
        .def_readwrite("memory_limit", &DecimateRequest::memory_limit)
        .def_readwrite("double_precision", &DecimateRequest::double_precision)
        .def_readwrite("progress", &DecimateRequest::progress);
    m.attr("SIGMA_POSITION_AUTO_VALUE") = pqdc::sigma_position_auto;
    m.def("decimate_arrays", &pqdc::python::decimate_arrays, py::arg("vertices"), py::arg("faces"),
          py::arg("normals"), py::arg("request"));
    m.def("extract_array", &pqdc::python::extract_array, py::arg("array"), py::arg("mask"), py::arg("request"));
    py::class_<StreamRequest>(m, "StreamRequest", "Where and how pqdc.extract_to_file writes (internal).")
        .def(py::init<>())
        .def_readwrite("output", &StreamRequest::output)
        .def_readwrite("brick_size", &StreamRequest::brick_size)
        .def_readwrite("brick_runs", &StreamRequest::brick_runs);
    m.def("extract_file_to", &pqdc::python::extract_file_to, py::arg("path"), py::arg("grid"), py::arg("request"),
          py::arg("stream"));
    m.def("split_file", &pqdc::python::split_file, py::arg("path"), py::arg("grid"), py::arg("dir"),
          py::arg("brick_size"), py::arg("progress"));
    m.def("extract_grid", &pqdc::python::extract_grid_object, py::arg("grid"), py::arg("request"),
          "None when the object is not a pyopenvdb grid.");
    m.def("extract_file", &pqdc::python::extract_file, py::arg("path"), py::arg("grid"), py::arg("request"));
    m.def("grid_bridge_available", &pqdc::python::grid_bridge_available);
    m.def("read_mesh_file", &pqdc::python::read_mesh_file, py::arg("path"));
}
