#include "decimate_job.hpp"

#include "choice.hpp"
#include "run_control.hpp"

#include <pqdc/decimate.hpp>
#include <pqdc/exceptions.hpp>

#include <cstdint>
#include <initializer_list>
#include <limits>
#include <utility>

namespace py = pybind11;

namespace pqdc::python {
namespace {

DecimateOptions options_of(const DecimateRequest& r, double source_voxel_size) {
    DecimateOptions o;
    o.target_faces = r.target_faces;
    o.target_ratio = r.target_ratio;
    o.max_distance_voxels = r.max_distance;
    o.voxel_size = r.voxel_size > 0 ? r.voxel_size : source_voxel_size;
    o.metric = parse_choice<DecimateMetric>("metric", r.metric,
                                            {{"triangle", DecimateMetric::triangle},
                                             {"plane", DecimateMetric::plane},
                                             {"curvature", DecimateMetric::curvature}});
    o.sigma_position_voxels = r.sigma_position;
    o.sigma_normal = r.sigma_normal;
    o.threads = r.threads;
    o.memory_limit_bytes = std::size_t(r.memory_limit);
    o.stored_precision = r.double_precision ? VertexPrecision::float64 : VertexPrecision::float32;
    return o;
}

/// Runs pqdc::decimate on `out.mesh` without the GIL and records its stats;
/// the normals it carried over become the result's vertex normals. Ctrl-C
/// and the request's progress callback act within the passes.
void run(DecimateOptions options, const py::object& progress, MeshResult& out) {
    DecimateStats s;
    RunControl rc(progress);
    options.progress = rc.stage(0.0, 1.0);
    try {
        py::gil_scoped_release nogil;
        decimate(out.mesh, options, &s);
    } catch (const cancelled_error&) {
        rc.rethrow_pending();
        throw;
    }
    out.checked_precision = options.stored_precision == VertexPrecision::float64 ? "double" : "float";
    out.counts.insert(out.counts.end(), {
        {"decimate_input_triangles", s.input_faces}, {"decimate_output_triangles", s.output_faces},
        {"decimate_collapses", s.collapses}, {"decimate_passes", s.passes},
        {"decimate_locked_vertices", s.locked_vertices},
        {"decimate_dropped_faces", s.dropped_faces},
        {"decimate_refused_link", s.rejected_link}, {"decimate_refused_flip", s.rejected_flip},
        {"decimate_refused_quality", s.rejected_quality}, {"decimate_refused_intersection", s.rejected_intersection},
        {"decimate_refused_distance", s.rejected_distance}});
    out.values.insert(out.values.end(), {{"decimate_voxel_size", s.voxel_size},
                                         {"decimate_noise_voxels", s.noise_voxels},
                                         {"decimate_sigma_position_voxels", s.sigma_position_voxels}});
    out.seconds.emplace_back("seconds_decimate", s.seconds);
    out.fields.normals = std::move(out.mesh.normals);
    out.mesh.normals.clear();
}

/// The rows of an (N, 3) array of any real dtype (shape checked by the caller).
std::vector<openvdb::Vec3d> vec3_rows(const py::array& array) {
    const auto a = py::array_t<double, py::array::forcecast>::ensure(array);
    if (!a) throw py::error_already_set();
    const auto r = a.unchecked<2>();
    std::vector<openvdb::Vec3d> rows(std::size_t(r.shape(0)));
    for (py::ssize_t i = 0; i < r.shape(0); ++i) rows[std::size_t(i)] = {r(i, 0), r(i, 1), r(i, 2)};
    return rows;
}

template <class Index>
void copy_faces(const py::array_t<std::int64_t>& faces, std::size_t vertices, std::vector<Index>& out) {
    const auto f = faces.unchecked<2>();
    const py::ssize_t n = f.shape(1);
    out.resize(std::size_t(f.shape(0)));
    for (py::ssize_t i = 0; i < f.shape(0); ++i)
        for (py::ssize_t j = 0; j < n; ++j) {
            const std::int64_t v = f(i, j);
            if (v < 0 || std::uint64_t(v) >= vertices)
                throw input_error("pqdc.decimate: face " + std::to_string(i) + " refers to vertex " +
                                  std::to_string(v) + ", but there are " + std::to_string(vertices) +
                                  " vertices (indices start at 0)");
            out[std::size_t(i)][int(j)] = std::uint32_t(v);
        }
}

}  // namespace

std::shared_ptr<MeshResult> decimate_result(MeshResult& input, const DecimateRequest& request) {
    const DecimateOptions options = options_of(request, input.source.voxel_size);
    auto out = std::make_shared<MeshResult>();
    out->mesh.points = input.mesh.points;
    out->mesh.triangles = input.mesh.triangles;
    out->mesh.quads = input.mesh.quads;
    // Normals known without a grid (read from a file, or sampled before the
    // grid was released) are carried over by pqdc::decimate.
    const bool carry_normals = !input.source.grid && input.fields.normals.size() == input.mesh.points.size();
    if (carry_normals) out->mesh.normals = input.fields.normals;
    out->counts = input.counts;
    out->seconds = input.seconds;
    out->values = input.values;
    out->choices = input.choices;
    out->labels = input.labels;
    out->warnings = input.warnings;
    run(options, request.progress, *out);
    // The counts describe this mesh; decimate_input_triangles keeps the extraction's.
    for (auto& [key, value] : out->counts) {
        if (key == "vertices") value = out->mesh.points.size();
        if (key == "triangles") value = out->mesh.triangles.size();
        if (key == "quads") value = out->mesh.quads.size();
    }
    // Copying the grid's pointer needs the GIL (it may own a Python reference).
    out->source = input.source;
    if (!out->source.grid)
        out->fields_unavailable =
            std::string("the vertex ") + (carry_normals ? "values" : "normals and values") +
            " of a decimated mesh are sampled from the grid of the mesh it was decimated from, " +
            (input.source.voxel_size > 0
                 ? "which released that grid when its own vertex normals or values were read; call decimate() "
                   "before reading them"
                 : "and that mesh came from arrays or a file: there is no grid");
    return out;
}

std::shared_ptr<MeshResult> decimate_arrays(const py::array& vertices, const py::array& faces,
                                            const py::array& normals, const DecimateRequest& request) {
    if (vertices.ndim() != 2 || vertices.shape(1) != 3)
        throw option_error("pqdc.decimate: vertices must have shape (N, 3), got " + std::to_string(vertices.ndim()) +
                           " dimensions" + (vertices.ndim() == 2 ? " with " + std::to_string(vertices.shape(1)) +
                                                                       " columns" : std::string()));
    if (faces.ndim() != 2 || (faces.shape(1) != 3 && faces.shape(1) != 4))
        throw option_error("pqdc.decimate: faces must have shape (M, 3) (triangles) or (M, 4) (quads)");
    if (std::uint64_t(vertices.shape(0)) > std::numeric_limits<std::uint32_t>::max())
        throw option_error("pqdc.decimate: at most 2^32 - 1 vertices");
    const auto f = py::array_t<std::int64_t, py::array::forcecast>::ensure(faces);
    if (!f) throw py::error_already_set();
    const bool with_normals = normals.size() > 0;
    if (with_normals && (normals.ndim() != 2 || normals.shape(0) != vertices.shape(0) || normals.shape(1) != 3))
        throw option_error("pqdc.decimate: normals must have the vertices' shape (" +
                           std::to_string(vertices.shape(0)) + ", 3), got " + shape_text(normals));
    auto out = std::make_shared<MeshResult>();
    out->mesh.points = vec3_rows(vertices);
    if (with_normals) out->mesh.normals = vec3_rows(normals);
    if (f.shape(1) == 3) copy_faces(f, out->mesh.points.size(), out->mesh.triangles);
    else copy_faces(f, out->mesh.points.size(), out->mesh.quads);
    run(options_of(request, 0.0), request.progress, *out);
    out->labels.emplace_back("source", "arrays");
    out->fields_unavailable = std::string("a mesh decimated from arrays has no field to sample vertex ") +
                              (with_normals ? "values" : "normals or values") + " from" +
                              (with_normals ? "" : " (pass normals= to carry vertex normals over)");
    return out;
}

}  // namespace pqdc::python
