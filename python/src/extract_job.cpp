#include "extract_job.hpp"
#include "python_names.hpp"

#include "array_grid.hpp"
#include "choice.hpp"
#include "grid_bridge.hpp"
#include "run_control.hpp"

#include <algorithm>
#include <pqdc/adaptive.hpp>
#include <pqdc/brick_store.hpp>
#include <pqdc/bricks.hpp>
#include <pqdc/components.hpp>
#include <pqdc/exceptions.hpp>
#include <pqdc/extract.hpp>
#include <pqdc/mesh_io.hpp>
#include <pqdc/mesh_stream.hpp>
#include <pqdc/self_intersections.hpp>
#include <pqdc/volume_io.hpp>

#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <unistd.h>

#include <chrono>
#include <limits>
#include <cmath>
#include <optional>
#include <sstream>

namespace py = pybind11;

namespace pqdc::python {

std::string shape_text(const py::array& a) {
    std::ostringstream s;
    s << "(";
    for (py::ssize_t i = 0; i < a.ndim(); ++i) s << (i ? ", " : "") << a.shape(i);
    s << (a.ndim() == 1 ? ",)" : ")");
    return s.str();
}

namespace {

ExtractOptions base_options(const Request& r) {
    ExtractOptions o;
    o.sigma_n = r.sigma_n;
    o.isovalue = r.isovalue;
    o.interior = parse_choice<Interior>("interior", r.interior,
                                 {{"auto", Interior::automatic},
                                  {"below", Interior::below_isovalue},
                                  {"above", Interior::above_isovalue}});
    o.faces = parse_choice<FaceType>("faces", r.faces, {{"triangles", FaceType::triangles}, {"quads", FaceType::quads}});
    o.normals = parse_choice<GridNormals>("normals", r.normals,
                                   {{"auto", GridNormals::automatic},
                                    {"central", GridNormals::central},
                                    {"sharp", GridNormals::sharp},
                                    {"least_squares", GridNormals::least_squares}});
    o.denoise = parse_choice<Denoise>("denoise", r.denoise,
                               {{"auto", Denoise::automatic}, {"on", Denoise::on}, {"off", Denoise::off}});
    o.containment = parse_choice<Containment>("containment", r.containment,
                                       {{"clamp", Containment::clamp_to_cell},
                                        {"unconstrained", Containment::unconstrained}});
    o.memory_limit_bytes = std::size_t(r.memory_limit);
    o.stored_precision = r.double_precision ? VertexPrecision::float64 : VertexPrecision::float32;
    o.min_component_voxels = r.min_component;  // checked by the Python layer (validate() below as well)
    if (!r.bbox.empty()) {
        if (r.bbox.size() != 6)
            throw option_error("bbox must be six numbers (xmin, ymin, zmin, xmax, ymax, zmax), world units; got " +
                               std::to_string(r.bbox.size()));
        o.region.bbox = openvdb::BBoxd(openvdb::Vec3d(r.bbox[0], r.bbox[1], r.bbox[2]),
                                       openvdb::Vec3d(r.bbox[3], r.bbox[4], r.bbox[5]));
    }
    validate(o);
    if (r.threads < 0) throw option_error("threads must be a positive count or None (all cores), got " +
                                          std::to_string(r.threads));
    if (r.adaptive) {
        AdaptiveOptions a;
        a.max_error_voxels = r.max_error;
        a.max_cell_size_voxels = r.max_cell_size;
        validate(a);
    }
    return o;
}

std::size_t physical_memory_share() {
    const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
    if (pages <= 0 || page <= 0) return 0;
    return std::size_t(double(pages) * double(page) * 0.8);
}

void add_stats(const ExtractStats& s, MeshResult& out) {
    out.counts.insert(out.counts.end(), {
        {"active_cells", s.active_cells}, {"crossing_edges", s.crossing_edges},
        {"degenerate_normals", s.degenerate_normals}, {"vertices", s.vertices},
        {"multi_vertex_cells", s.multi_vertex_cells}, {"clamped_vertices", s.clamped_vertices},
        {"fallback_vertices", s.fallback_vertices}, {"triangles", s.triangles}, {"quads", s.quads},
        {"boundary_crossings", s.boundary_crossings}, {"non_finite_values", s.non_finite_values},
        {"noise_samples", s.noise_samples}, {"denoise_radius", std::uint64_t(s.denoise_radius)},
        {"components_found", s.components.components},
        {"components_removed", s.components.removed_components},
        {"components_removed_faces", s.components.removed_faces},
        {"components_removed_vertices", s.components.removed_points}});
    // The component diagonals as the CLI's --stats gives them: None when no
    // component was removed (kept), not 0.
    const ComponentFilterStats& c = s.components;
    const auto unless_none = [](bool applies, double v) { return applies ? std::optional<double>(v) : std::nullopt; };
    out.values.insert(out.values.end(),
                      {{"noise_voxels", s.noise_voxels}, {"sigma_n", s.sigma_n},
                       {"components_largest_removed_diagonal_voxels",
                        unless_none(c.removed_components > 0, c.largest_removed_diagonal_voxels)},
                       {"components_smallest_kept_diagonal_voxels",
                        unless_none(c.removed_components < c.components, c.smallest_kept_diagonal_voxels)}});
    out.choices.emplace_back("gradient", s.gradient);
    // One entry per pipeline stage, as ExtractStats::stages names them.
    for (const StageTime& stage : s.stages) {
        std::string key = "seconds_" + stage.name;
        std::replace(key.begin(), key.end(), ' ', '_');
        out.seconds.emplace_back(key, stage.seconds);
    }
    out.seconds.emplace_back("seconds_extract", s.seconds_total);
}

void add_stats(const AdaptiveStats& s, MeshResult& out) {
    add_stats(static_cast<const ExtractStats&>(s), out);
    out.counts.insert(out.counts.end(), {
        {"surface_leaves", s.surface_leaves}, {"empty_leaves", s.empty_leaves}, {"merges", s.merges},
        {"refused_error", s.refused_error}, {"refused_topology", s.refused_topology},
        {"refused_containment", s.refused_containment}, {"refused_balance", s.refused_balance},
        {"refused_pinned", s.refused_pinned}, {"untangle_pinned_cells", s.untangle_pinned_cells},
        {"untangle_unresolved", s.untangle_unresolved},
        {"untangle_fallback", std::uint64_t(s.untangle_fallback)},
        {"untangle_flips_dropped", std::uint64_t(s.untangle_flips_dropped)}, {"dual_cells", s.dual_cells}, {"filled_pockets", s.filled_pockets}, {"undefined_leaves_inside", s.undefined_leaves_inside}, {"collapsed_vertices", s.collapsed_vertices},
        {"added_vertices", s.added_vertices}, {"separated_vertices", s.separated_vertices}, {"relaxed_vertices", s.relaxed_vertices},
        {"angle_flips", s.angle_flips}, {"bridges_found", s.bridges_found},
        {"bridge_pinned_cells", s.bridge_pinned_cells}});
}

/// The library's rule for grids (class, background, active boundary);
/// arrays have no grid class and were converted assuming "below".
InteriorChoice resolve(const ExtractOptions& options, const openvdb::GridBase& grid, bool array) {
    if (array && options.interior == Interior::automatic) return {Interior::below_isovalue, "array (no grid class)"};
    return choose_interior(grid, options);
}

/// How the mesh's points relate to the grid's index space.
struct Placement {
    bool array = false;                        ///< identity grid transform; map by spacing/origin afterwards
    std::array<double, 3> spacing{1, 1, 1}, origin{0, 0, 0};
};

/// An array is meshed in index space and placed afterwards, so the
/// library's float check saw index coordinates. Placed far from the origin
/// (or at sub-normal spacings) float's spacing can be coarse against the
/// array's: the placed mesh is checked as float stores it, and a warning
/// says what the library says for a grid in that case.
void check_float_placement(const Mesh& mesh, const Placement& place, VertexPrecision stored, ExtractStats& stats) {
    if (stored != VertexPrecision::float32 || mesh.points.empty()) return;
    const double spacing = std::min({place.spacing[0], place.spacing[1], place.spacing[2]});
    double largest = 0;
    for (const openvdb::Vec3d& p : mesh.points)
        largest = std::max({largest, std::abs(p[0]), std::abs(p[1]), std::abs(p[2])});
    constexpr double kReach = double(1 << 20);  // voxels: as lattice/untangle.cpp's guarantee
    if (largest < kReach * spacing && spacing >= kReach * double(std::numeric_limits<float>::min())) return;
    SelfIntersectionOptions as_stored;
    as_stored.stored_precision = VertexPrecision::float32;
    const SelfIntersections found = find_self_intersections(mesh, as_stored);
    const std::size_t left = found.pair_count + found.degenerate_triangles.size();
    if (left == 0) return;
    stats.warnings.push_back(std::to_string(left) +
                             " intersecting triangle pairs or degenerate triangles are in the mesh as stored in "
                             "float: its coordinates are too large (or too small) for float's spacing against the "
                             "array's spacing (float output stays intersection-free up to 2^20 voxels from the "
                             "origin); store it in double precision (--precision double)");
}

/// Meshes `grid` (kept in out.source for the vertex fields) within `mask`
/// (null: none; in the grid's world space); progress covers [from, 1]. Runs
/// without the GIL: never copy `r` here (its progress member is a Python
/// reference).
void mesh_grid(const openvdb::GridBase::ConstPtr& grid, const Request& r, const Placement& place,
               const openvdb::GridBase::ConstPtr& mask, RunControl& rc, double from, MeshResult& out) {
    ExtractOptions options = base_options(r);
    options.region.mask = mask;
    options.region.invert_mask = r.invert_mask && mask;
    // Arrays have no grid class: "auto" means below, as for level sets.
    const InteriorChoice choice = resolve(options, *grid, place.array);
    const Interior interior = choice.side;
    options.interior = interior;
    options.progress = rc.stage(from, 1.0);
    if (place.array && options.region.bbox) {
        // The array's grid is index space; the box is in world units.
        openvdb::Vec3d lo, hi;
        for (int a = 0; a < 3; ++a) {
            const std::size_t i = std::size_t(a);
            lo[a] = (options.region.bbox->min()[a] - place.origin[i]) / place.spacing[i];
            hi[a] = (options.region.bbox->max()[a] - place.origin[i]) / place.spacing[i];
        }
        options.region.bbox = openvdb::BBoxd(lo, hi);
    }
    // An array's grid is in index space, where a voxel is 1 along every
    // axis: its islands are measured once the points are in world units, in
    // the shortest spacing, as a grid's are in its shortest voxel side.
    if (place.array) options.min_component_voxels = 0;
    AdaptiveStats adaptive_stats;
    ExtractStats uniform_stats;
    ExtractStats& stats = r.adaptive ? adaptive_stats : uniform_stats;
    if (r.adaptive) {
        AdaptiveOptions a;
        a.base = options;
        a.max_error_voxels = r.max_error;
        a.max_cell_size_voxels = r.max_cell_size;
        out.mesh = extract_adaptive(*grid, a, &adaptive_stats);
    } else {
        out.mesh = extract(*grid, options, &uniform_stats);
    }
    out.checked_precision = options.stored_precision == VertexPrecision::float64 ? "double" : "float";
    out.labels.emplace_back("mode", r.adaptive ? "adaptive" : "uniform");
    out.labels.emplace_back("interior", interior == Interior::above_isovalue ? "above" : "below");
    out.labels.emplace_back("interior_reason", choice.reason);
    out.source.grid = grid;
    out.source.outward_sign = interior == Interior::above_isovalue ? -1.0 : 1.0;
    out.source.array = place.array;
    out.source.spacing = place.spacing;
    out.source.origin = place.origin;
    const openvdb::Vec3d voxel = grid->voxelSize();
    out.source.voxel_size = place.array ? std::min({place.spacing[0], place.spacing[1], place.spacing[2]})
                                        : std::min({voxel[0], voxel[1], voxel[2]});
    if (place.array) {
        auto& points = out.mesh.points;
        tbb::parallel_for(std::size_t(0), points.size(), [&](std::size_t i) {
            for (int a = 0; a < 3; ++a)
                points[i][a] = place.origin[std::size_t(a)] + place.spacing[std::size_t(a)] * points[i][a];
        });
        if (r.min_component > 0) {
            ComponentFilterOptions filter;
            filter.min_diagonal_voxels = r.min_component;
            out.mesh = remove_small_components(out.mesh, out.source.voxel_size, filter, &stats.components);
            stats.vertices = out.mesh.points.size();
            stats.triangles = out.mesh.triangles.size();
            stats.quads = out.mesh.quads.size();
        }
        check_float_placement(out.mesh, place, options.stored_precision, stats);
    }
    if (r.adaptive) add_stats(adaptive_stats, out);
    else add_stats(uniform_stats, out);
    for (const std::string& w : stats.warnings) out.warnings.push_back(in_python_names(w));
}

VertexFields sample_fields(const MeshResult& r, RunControl& rc) {
    const FieldSource& src = r.source;
    const auto& points = r.mesh.points;
    std::vector<openvdb::Vec3d> index(points.size());
    openvdb::Mat3d covector = openvdb::Mat3d::identity();
    if (src.array) {
        for (int a = 0; a < 3; ++a) covector(a, a) = 1.0 / src.spacing[std::size_t(a)];
        tbb::parallel_for(std::size_t(0), points.size(), [&](std::size_t i) {
            for (int a = 0; a < 3; ++a)
                index[i][a] = (points[i][a] - src.origin[std::size_t(a)]) / src.spacing[std::size_t(a)];
        });
    } else {
        // Row-vector convention (world = index * L): the covector map is L^-1 on column vectors.
        const auto& xf = src.grid->transform();
        covector = xf.baseMap()->getAffineMap()->getMat4().getMat3().inverse();
        tbb::parallel_for(std::size_t(0), points.size(), [&](std::size_t i) { index[i] = xf.worldToIndex(points[i]); });
    }
    return sample_vertex_fields(*src.grid, index, src.outward_sign, covector, rc.stage(0.0, 1.0));
}

/// Runs job() with the GIL released and the thread limit set; re-raises a
/// Python exception caught by the progress hook instead of cancelled_error.
template <class Job>
void run_released(const Request& r, RunControl& rc, const Job& job) {
    try {
        py::gil_scoped_release nogil;
        std::optional<tbb::global_control> limit;
        if (r.threads > 0) limit.emplace(tbb::global_control::max_allowed_parallelism, std::size_t(r.threads));
        job();
    } catch (const cancelled_error&) {
        rc.rethrow_pending();
        throw;
    }
}

ElementType element_type(const py::dtype& dt) {
    const char kind = dt.kind();
    const auto size = dt.itemsize();
    if (kind == 'b') return ElementType::b8;
    if (kind == 'f' && size == 2) return ElementType::f16;
    if (kind == 'f' && size == 4) return ElementType::f32;
    if (kind == 'f' && size == 8) return ElementType::f64;
    if (kind == 'i' || kind == 'u') {
        const bool u = kind == 'u';
        switch (size) {
        case 1: return u ? ElementType::u8 : ElementType::i8;
        case 2: return u ? ElementType::u16 : ElementType::i16;
        case 4: return u ? ElementType::u32 : ElementType::i32;
        case 8: return u ? ElementType::u64 : ElementType::i64;
        default: break;
        }
    }
    throw py::type_error("pqdc.extract: arrays of dtype " + py::str(py::handle(dt)).cast<std::string>() +
                         " are not supported; pass a float, integer or bool array (e.g. array.astype(numpy.float32))");
}

ArrayView array_view(const py::array& array, bool zyx) {
    if (array.ndim() != 3)
        throw input_error("pqdc.extract: expected a 3-D array, got a " + std::to_string(array.ndim()) +
                          "-D array of shape " + shape_text(array) + " (stack 2-D slices with numpy.stack)");
    ArrayView v;
    v.type = element_type(array.dtype());
    if (!array.dtype().attr("isnative").cast<bool>())
        throw input_error("pqdc.extract: the array is not in native byte order; convert it with "
                          "array.astype(array.dtype.newbyteorder('='))");
    v.data = static_cast<const char*>(array.data());
    for (int i = 0; i < 3; ++i) {
        const int axis = zyx ? 2 - i : i;
        v.shape[std::size_t(i)] = array.shape(axis);
        v.strides[std::size_t(i)] = array.strides(axis);
        if (array.shape(axis) < 2)
            throw input_error("pqdc.extract: the array has shape " + shape_text(array) +
                              "; every axis needs at least 2 voxels to hold a cell");
    }
    return v;
}

/// The pyopenvdb grid of Request::mask_grid (GIL held; destroy it with the GIL).
BorrowedGrid borrow_mask(const Request& r) {
    if (r.mask_grid.is_none()) return {};
    BorrowedGrid b = borrow_grid(r.mask_grid);
    if (!b.grid)
        throw py::type_error("pqdc.extract: mask must be a numpy array (for an array source), a pyopenvdb grid, "
                             "the path of a .vdb file or (path, grid name); got " +
                             py::str(py::type::handle_of(r.mask_grid).attr("__name__")).cast<std::string>());
    return b;
}

/// The mask in world space: the borrowed grid, or the .vdb file's grid (read here, GIL released).
openvdb::GridBase::ConstPtr world_mask(const Request& r, const BorrowedGrid& borrowed) {
    if (borrowed.grid) return borrowed.grid;
    if (!r.mask_path.empty()) return read_mask_grid(r.mask_path, r.mask_grid_name).grid;
    return nullptr;
}

/// A world-space mask seen from an array's index space (the array's grid has
/// the identity transform; its world is origin + spacing * index): the same
/// tree under the transform followed by the inverse of that placement.
openvdb::GridBase::ConstPtr in_array_index_space(const openvdb::GridBase::ConstPtr& mask, const Placement& place) {
    openvdb::math::Transform::Ptr xf = mask->transform().copy();
    xf->postTranslate(-openvdb::Vec3d(place.origin[0], place.origin[1], place.origin[2]));
    xf->postScale(openvdb::Vec3d(1.0 / place.spacing[0], 1.0 / place.spacing[1], 1.0 / place.spacing[2]));
    return mask->copyGridReplacingTransform(xf);
}

MaskView mask_view(const py::object& mask, const py::array& array, bool zyx) {
    MaskView m;
    if (mask.is_none()) return m;
    const auto a = py::reinterpret_borrow<py::array>(mask);
    if (a.dtype().kind() != 'b') throw py::type_error("pqdc.extract: mask must be a bool array, got dtype " +
                                                      py::str(py::handle(a.dtype())).cast<std::string>());
    if (a.ndim() != 3 || a.shape(0) != array.shape(0) || a.shape(1) != array.shape(1) || a.shape(2) != array.shape(2))
        throw input_error("pqdc.extract: mask has shape " + shape_text(a) + " but the array has shape " +
                          shape_text(array) + "; they must match");
    m.data = static_cast<const std::uint8_t*>(a.data());
    for (int i = 0; i < 3; ++i) {
        m.strides[std::size_t(i)] = a.strides(zyx ? 2 - i : i);
        m.shape[std::size_t(i)] = a.shape(zyx ? 2 - i : i);
    }
    return m;
}

void check_placement(const Request& r) {
    for (int i = 0; i < 3; ++i) {
        if (!(r.spacing[std::size_t(i)] > 0) || !std::isfinite(r.spacing[std::size_t(i)]))
            throw option_error("spacing must be three positive finite voxel sizes (x, y, z), got (" +
                               std::to_string(r.spacing[0]) + ", " + std::to_string(r.spacing[1]) + ", " +
                               std::to_string(r.spacing[2]) + ")");
        if (!std::isfinite(r.origin[std::size_t(i)]))
            throw option_error("origin must be three finite numbers (x, y, z)");
    }
}

void check_scalar(const openvdb::GridBase& grid, const std::string& what) {
    if (grid.isType<openvdb::FloatGrid>() || grid.isType<openvdb::DoubleGrid>()) return;
    const std::string name = grid.getName().empty() ? what + " grid (unnamed)" : what + " grid '" + grid.getName() + "'";
    const std::string type = grid.valueType();
    const bool vector = type.rfind("vec", 0) == 0;
    const bool mask = type == "bool" || type == "mask";
    throw input_error(name + " holds " + type + " values; pqdc meshes scalar float or double grids" +
                      (vector ? " (for a vector grid, mesh a component or the magnitude)"
                       : mask ? " (for a mask, convert it to a float grid of 0 and 1 and mesh it at isovalue=0.5, "
                                "interior='above')"
                              : " (convert it to float)"));
}

}  // namespace

const VertexFields& vertex_fields(MeshResult& result) {
    if (result.source.grid) {
        RunControl rc{py::none()};  // Ctrl-C only
        const auto t0 = std::chrono::steady_clock::now();
        bool ran = false;
        try {
            py::gil_scoped_release nogil;
            std::call_once(result.sampled, [&] {
                result.fields = sample_fields(result, rc);
                ran = true;
            });
        } catch (const cancelled_error&) {
            rc.rethrow_pending();
            throw;
        }
        if (ran)
            result.seconds.emplace_back("seconds_normals",
                                        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
        result.source.grid.reset();  // with the GIL: may drop a Python reference
    }
    return result.fields;
}

namespace {

template <class Field>
const Field& complete(const Field& field, const MeshResult& result, const char* what) {
    if (field.size() == result.mesh.points.size()) return field;
    throw input_error(result.fields_unavailable.empty() ? std::string("this mesh has no vertex ") + what
                                                        : result.fields_unavailable);
}

}  // namespace

const std::vector<openvdb::Vec3d>& vertex_normals(MeshResult& result) {
    return complete(vertex_fields(result).normals, result, "normals");
}

const std::vector<double>& vertex_values(MeshResult& result) {
    return complete(vertex_fields(result).values, result, "values");
}

std::shared_ptr<MeshResult> extract_array(const py::array& array, const py::object& mask, const Request& r) {
    const ArrayView view = array_view(array, r.zyx);
    const MaskView mview = mask_view(mask, array, r.zyx);
    check_placement(r);
    ExtractOptions checked = base_options(r);
    const BorrowedGrid mask_object = borrow_mask(r);  // destroyed with the GIL held
    RunControl rc(r.progress);
    auto out = std::make_shared<MeshResult>();
    run_released(r, rc, [&] {
        ConversionOptions c;
        c.isovalue = r.isovalue;
        c.interior = checked.interior == Interior::automatic ? Interior::below_isovalue : checked.interior;
        c.sparse = r.sparse;
        // Automatic denoising keeps the narrow apron: the automatic
        // settings already depend on which voxels are stored (README).
        c.apron = checked.denoise == Denoise::on ? kDenoiseApron : kApron;
        c.memory_limit_bytes = r.memory_limit ? std::size_t(r.memory_limit) : physical_memory_share();
        c.progress = rc.stage(0.0, 0.3);
        ConversionStats cs;
        const openvdb::GridBase::Ptr grid = array_to_grid(view, c, &cs);
        out->counts.insert(out->counts.end(), {{"array_blocks", cs.blocks},
                                               {"array_dense_leaves", cs.dense_leaves},
                                               {"array_tiles", cs.tiles},
                                               {"array_grid_bytes", cs.grid_bytes}});
        out->seconds.emplace_back("seconds_convert", cs.seconds);
        Placement place;
        place.array = true;
        place.spacing = r.spacing;
        place.origin = r.origin;
        openvdb::GridBase::ConstPtr region_mask;
        if (mview.data) region_mask = mask_to_grid(mview);
        else if (const auto world = world_mask(r, mask_object)) region_mask = in_array_index_space(world, place);
        mesh_grid(grid, r, place, region_mask, rc, 0.3, *out);
    });
    out->labels.emplace_back("source", "array");
    return out;
}

std::shared_ptr<MeshResult> extract_grid_object(const py::handle& object, const Request& r) {
    const BorrowedGrid borrowed = borrow_grid(object);  // destroyed with the GIL held
    if (!borrowed.grid) return nullptr;
    check_scalar(*borrowed.grid, "the pyopenvdb");
    base_options(r);
    const BorrowedGrid mask_object = borrow_mask(r);
    RunControl rc(r.progress);
    auto out = std::make_shared<MeshResult>();
    run_released(r, rc, [&] { mesh_grid(borrowed.grid, r, Placement{}, world_mask(r, mask_object), rc, 0.0, *out); });
    out->labels.emplace_back("source", "grid");
    out->labels.emplace_back("grid", borrowed.grid->getName());
    return out;
}

/// input_error unless `asked` is empty or the grid the store at `path` holds.
void check_store_grid(const std::string& path, const std::string& holds, const std::string& asked) {
    if (!asked.empty() && asked != holds)
        throw input_error("the brick store '" + path + "' holds grid '" + holds + "', not '" + asked +
                          "'; leave grid out or name that grid");
}

/// A brick store's grid, its voxels left in the brick files until meshed
/// (what the CLI meshes in core); `grid_name` must be empty or its name.
LoadedGrid store_grid(const std::string& path, const std::string& grid_name) {
    LoadedGrid store = read_brick_store(path);
    check_store_grid(path, store.grid->getName(), grid_name);
    return store;
}

namespace {

/// The CLI logs which grid it took from a file with several; a Python
/// caller reads the warnings.
void warn_of_grid_choice(const LoadedGrid& loaded, const std::string& path, MeshResult& out) {
    if (!loaded.chosen_automatically || loaded.scalar_grid_names.size() < 2) return;
    std::string names;
    for (const std::string& n : loaded.scalar_grid_names) names += (names.empty() ? "'" : ", '") + n + "'";
    out.warnings.push_back("'" + path + "' has several scalar grids (" + names + "); meshed '" +
                           loaded.grid->getName() + "', the first by name (choose one with grid=NAME)");
}

}  // namespace

std::shared_ptr<MeshResult> extract_file(const std::string& path, const std::string& grid_name, const Request& r) {
    base_options(r);
    const BorrowedGrid mask_object = borrow_mask(r);
    RunControl rc(r.progress);
    auto out = std::make_shared<MeshResult>();
    run_released(r, rc, [&] {
        const LoadedGrid loaded = is_brick_store(path) ? store_grid(path, grid_name) : read_scalar_grid(path, grid_name);
        mesh_grid(loaded.grid, r, Placement{}, world_mask(r, mask_object), rc, 0.0, *out);
        warn_of_grid_choice(loaded, path, *out);
        out->labels.emplace_back("grid", loaded.grid->getName());
    });
    out->labels.emplace_back("source", "file");
    out->labels.emplace_back("file", path);
    return out;
}

std::shared_ptr<MeshResult> extract_file_to(const std::string& path, const std::string& grid_name, const Request& r,
                                            const StreamRequest& sr) {
    ExtractOptions options = base_options(r);
    if (r.adaptive)
        throw option_error("extract_to_file meshes in uniform mode only (adaptive mode is not streamed); "
                           "use pqdc.extract(..., adaptive=True) and write the mesh");
    BrickOptions bricks;
    bricks.brick_size = sr.brick_size;
    bricks.concurrent_runs = sr.brick_runs;
    validate(bricks);
    MeshWriteOptions wo;
    wo.precision = options.stored_precision;  // base_options: the request's precision
    // Checked as the file will hold it (STL: always float), as the CLI does.
    try {
        options.stored_precision = stored_vertex_precision(mesh_format_from_path(sr.output), wo.precision);
    } catch (const error&) {  // an unknown extension: the writer below says so
    }
    const BorrowedGrid mask_object = borrow_mask(r);
    RunControl rc(r.progress);
    auto out = std::make_shared<MeshResult>();
    run_released(r, rc, [&] {
        options.region.mask = world_mask(r, mask_object);
        options.region.invert_mask = r.invert_mask && options.region.mask;
        options.progress = rc.stage(0.0, 1.0);
        MeshStreamWriter writer(sr.output, wo);
        ExtractStats stats;
        std::string grid;
        if (is_brick_store(path)) {
            const BrickStore store(path);
            grid = store.shell().getName();
            check_store_grid(path, grid, grid_name);
            extract_bricks(store, options, bricks, writer, {}, &stats);
        } else {
            const LoadedGrid loaded = read_scalar_grid(path, grid_name, VolumeLoading::delayed);
            grid = loaded.grid->getName();
            extract_bricks(*loaded.grid, options, bricks, writer, {}, &stats);
            warn_of_grid_choice(loaded, path, *out);
        }
        writer.finish();
        add_stats(stats, *out);
        out->counts.insert(out->counts.end(), {{"points_written", writer.point_count()},
                                               {"triangles_written", writer.triangle_count()},
                                               {"quads_written", writer.quad_count()}});
        for (const std::string& w : stats.warnings) out->warnings.push_back(in_python_names(w));
        out->labels.emplace_back("grid", grid);
        out->labels.emplace_back("interior", stats.interior);
        out->labels.emplace_back("interior_reason", stats.interior_reason);
    });
    out->labels.emplace_back("mode", "uniform, brick by brick");
    out->labels.emplace_back("source", "file");
    out->labels.emplace_back("file", path);
    out->labels.emplace_back("output", sr.output);
    return out;
}

std::pair<std::uint64_t, std::uint64_t> split_file(const std::string& path, const std::string& grid_name,
                                                   const std::string& dir, int brick_size, py::object progress) {
    BrickOptions bricks;
    bricks.brick_size = brick_size;
    validate(bricks);
    RunControl rc(std::move(progress));
    BrickStoreSummary written;
    try {
        py::gil_scoped_release nogil;
        const LoadedGrid loaded = read_scalar_grid(path, grid_name, VolumeLoading::delayed);
        written = write_brick_store(*loaded.grid, dir, bricks, [&rc](double f) { return rc.report(f); });
    } catch (const cancelled_error&) {
        rc.rethrow_pending();
        throw;
    }
    return {written.bricks, written.leaves};
}

}  // namespace pqdc::python
