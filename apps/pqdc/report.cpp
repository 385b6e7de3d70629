#include "report.hpp"

#include "../cli_util.hpp"

#include <cmath>
#include <sstream>

namespace pqdc_app {
namespace {

using json = nlohmann::ordered_json;
using pqdc_cli::json_real;

json adaptive_json(const CliOptions& o, const pqdc::AdaptiveStats& a) {
    json by_size = json::object();
    for (std::size_t level = 0; level < a.leaves_per_level.size(); ++level)
        if (a.leaves_per_level[level]) by_size[std::to_string(1u << level)] = a.leaves_per_level[level];
    return {{"max_cell_size_voxels", o.max_cell_size_voxels},
            {"surface_leaves", a.surface_leaves},
            {"empty_leaves", a.empty_leaves},
            {"merges", a.merges},
            {"refused",
             {{"error", a.refused_error},
              {"topology", a.refused_topology},
              {"containment", a.refused_containment},
              {"balance", a.refused_balance},
              {"pinned", a.refused_pinned}}},
            {"surface_leaves_by_size_voxels", by_size},
            {"dual_cells", a.dual_cells},
            {"filled_pockets", a.filled_pockets},
            {"undefined_leaves_inside", a.undefined_leaves_inside},
            {"collapsed_vertices", a.collapsed_vertices},
            {"added_vertices", a.added_vertices},
            {"separated_vertices", a.separated_vertices},
            {"relaxed_vertices", a.relaxed_vertices},
            {"angle_flips", a.angle_flips},
            {"bridges", {{"found", a.bridges_found}, {"pinned_cells", a.bridge_pinned_cells}}},
            {"untangle", {{"pinned_cells", a.untangle_pinned_cells}, {"unresolved", a.untangle_unresolved},
                          {"fallback_to_uniform", a.untangle_fallback},
                          {"flips_dropped", a.untangle_flips_dropped}}}};
}

/// Every pipeline stage's wall time by name, in order, then their total;
/// then reading the volume and writing the mesh, which "total" leaves out.
json stage_seconds(const MeshReport& r) {
    const pqdc::ExtractStats& s = r.stats;
    json j = json::object();
    for (const pqdc::StageTime& stage : s.stages) j[stage.name] = json_real(stage.seconds);
    j["total"] = json_real(s.seconds_total);
    if (r.read_seconds >= 0) j["read"] = json_real(r.read_seconds);
    if (r.decimation) j["decimate"] = json_real(r.decimation->seconds);
    if (r.write_seconds >= 0) j["write"] = json_real(r.write_seconds);
    return j;
}

/// --bbox and --mask as given; null when the whole grid is meshed.
json region_json(const CliOptions& o) {
    const pqdc::MeshRegion& r = o.extract.region;
    if (!r.bbox && o.mask_path.empty()) return nullptr;
    json j = json::object();
    if (r.bbox) {
        const openvdb::BBoxd& b = *r.bbox;
        j["bbox_world"] = {b.min().x(), b.min().y(), b.min().z(), b.max().x(), b.max().y(), b.max().z()};
    } else {
        j["bbox_world"] = nullptr;
    }
    j["mask"] = o.mask_path.empty() ? json(nullptr) : json(o.mask_path + (o.mask_grid.empty() ? "" : ":" + o.mask_grid));
    j["invert_mask"] = o.invert_mask;
    return j;
}

const char* quadric_kind(double sigma_n) {
    if (std::isinf(sigma_n)) return "mass point";
    return sigma_n == 0 ? "classical" : "probabilistic";
}

}  // namespace

std::string summary_line(const CliOptions& o, const MeshReport& r) {
    const pqdc::ExtractStats& s = r.stats;
    std::ostringstream line;
    line << s.active_cells << " active cells -> " << s.vertices << " vertices, ";
    // Adaptive quad meshes have triangles where cells of different sizes meet.
    if (s.quads == 0) line << s.triangles << " triangles";
    else if (s.triangles == 0) line << s.quads << " quads";
    else line << s.triangles << " triangles and " << s.quads << " quads";
    line << " in " << s.seconds_total << " s";
    if (s.clamped_vertices) line << ", " << s.clamped_vertices << " clamped";
    if (s.fallback_vertices) line << ", " << s.fallback_vertices << " fallbacks";
    if (s.untangle_moved) line << ", " << s.untangle_moved << " moved to untangle " << s.untangle_found << " intersections";
    if (s.degenerate_normals) line << ", " << s.degenerate_normals << " zero-gradient crossings";
    if (s.non_finite_values) line << ", " << s.non_finite_values << " NaN/Inf voxels skipped";
    if (s.boundary_crossings)
        line << ", open where the surface leaves the active region"
             << (o.extract.region.bbox || !o.mask_path.empty() ? " or the --bbox/--mask region" : "") << " ("
             << s.boundary_crossings << " crossings)";
    if (!s.interior.empty() && o.procedural.empty())
        line << "; inside " << s.interior << " the isovalue (" << s.interior_reason << ")";
    // The counts above are the extraction's; the file holds the decimated
    // mesh, or quads as triangles where the format has none.
    if (r.decimation)
        line << "; decimated to " << r.decimation->output_faces << " triangles and "
             << r.decimation->output_vertices << " vertices";
    else if (s.quads > 0 && (o.format ? *o.format : pqdc::mesh_format_from_path(r.output)) == pqdc::MeshFormat::stl)
        line << "; the quads written as two triangles each (STL has no quads)";
    line << "; wrote " << (r.output == "-" ? std::string("the mesh to standard output") : "'" + r.output + "'");
    return line.str();
}

std::string stats_json(const CliOptions& o, const MeshReport& r) {
    const pqdc::ExtractStats& s = r.stats;
    const pqdc::ExtractOptions& e = o.extract;
    json j = {
        {"pqdc_version", kVersion},
        {"source", r.source},
        {"grid", r.grid.empty() ? json(nullptr) : json(r.grid)},
        {"output", r.output},
        {"sigma_n", json_real(s.sigma_n)},
        {"sigma_n_requested", e.sigma_n == pqdc::sigma_n_auto ? json("auto") : json_real(e.sigma_n)},
        {"quadric", quadric_kind(s.sigma_n)},
        {"noise_voxels", json_real(s.noise_voxels)},
        {"noise_samples", s.noise_samples},
        {"denoise_radius", s.denoise_radius},
        {"mode", o.adaptive ? "adaptive" : "uniform"},
        {"max_error_voxels", o.adaptive ? json_real(o.max_error_voxels) : json(nullptr)},
        {"isovalue", json_real(e.isovalue)},
        {"interior", s.interior.empty() ? json(nullptr) : json(s.interior)},
        {"interior_reason", s.interior_reason.empty() ? json(nullptr) : json(s.interior_reason)},
        {"region", region_json(o)},
        {"containment", e.containment == pqdc::Containment::clamp_to_cell ? "clamp" : "none"},
        {"gradient", s.gradient},
        {"faces", e.faces == pqdc::FaceType::triangles ? "triangles" : "quads"},
        {"precision", o.precision == pqdc::VertexPrecision::float32 ? "float" : "double"},
        {"vertex_normals", o.vertex_normals},
        {"active_cells", s.active_cells},
        {"crossing_edges", s.crossing_edges},
        {"boundary_crossings", s.boundary_crossings},
        {"degenerate_normals", s.degenerate_normals},
        {"non_finite_values", s.non_finite_values},
        {"vertices", s.vertices},
        {"multi_vertex_cells", s.multi_vertex_cells},
        {"clamped_vertices", s.clamped_vertices},
        {"fallback_vertices", s.fallback_vertices},
        {"triangles", s.triangles},
        {"quads", s.quads},
        {"untangle",
         {{"found", s.untangle_found},
          {"moved_vertices", s.untangle_moved},
          {"snapped_vertices", s.untangle_snapped},
          {"rounds", s.untangle_rounds}}},
        {"warnings", s.warnings},
        {"seconds", stage_seconds(r)}};
    if (o.min_component_voxels > 0) {
        const pqdc::ComponentFilterStats& c = s.components;
        j["components"] = {{"min_diagonal_voxels", json_real(o.min_component_voxels)},
                           {"found", c.components},
                           {"removed", c.removed_components},
                           {"removed_faces", c.removed_faces},
                           {"removed_vertices", c.removed_points},
                           // null when no component was removed / kept, not 0
                           {"largest_removed_diagonal_voxels",
                            c.removed_components ? json_real(c.largest_removed_diagonal_voxels) : json(nullptr)},
                           {"smallest_kept_diagonal_voxels", c.removed_components < c.components
                                                                 ? json_real(c.smallest_kept_diagonal_voxels)
                                                                 : json(nullptr)}};
    }
    if (r.adaptive) j["adaptive"] = adaptive_json(o, *r.adaptive);
    if (r.decimation) j["decimate"] = pqdc_cli::decimation_json(*r.decimation);
    return pqdc_cli::json_text(j);
}

}  // namespace pqdc_app
