// pqdc::decimate, the driver: checks options and input, splits quads,
// marks the vertices that must stay (boundary, non-manifold), builds the
// per-vertex quadrics and runs passes of pass_scheduler.cpp until the face
// target is met or no collapse is admissible. Algorithm and citations:
// quadrics.cpp (Garland & Heckbert 1997; Trettner & Kobbelt 2020, section
// 4.2), collapse_checks.cpp (link condition, shape, exact intersection
// tests; triangle_grid.cpp finds the faces near a collapse) and
// pass_scheduler.cpp (meshoptimizer-style independent passes).

#include "pqdc/decimate.hpp"
#include "pqdc/exceptions.hpp"

#include "decimate_internal.hpp"
#include "geometry/float_rounding.hpp"
#include "lattice/enum_check.hpp"
#include "lattice/resources.hpp"

#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <memory>
#include <sstream>
#include <string>

namespace pqdc {
namespace dd = decimate_detail;
namespace {

std::string num(double v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%g", v);
    return buf;
}

void check_options(const DecimateOptions& o) {
    auto bad = [](const std::string& what) { throw option_error("decimate: " + what); };
    detail::check_enum("decimate: metric", o.metric, DecimateMetric::curvature);
    detail::check_enum("decimate: stored_precision", o.stored_precision, VertexPrecision::float64);
    if (!(o.target_ratio >= 0 && o.target_ratio <= 1)) bad("target_ratio must be in [0, 1], got " + num(o.target_ratio));
    if (!(o.max_distance_voxels >= 0) || std::isinf(o.max_distance_voxels))
        bad("max_distance_voxels must be a finite distance >= 0 (voxels), got " + num(o.max_distance_voxels));
    if (o.target_faces == 0 && o.target_ratio == 0 && o.max_distance_voxels == 0)
        bad("no target: give target_faces, target_ratio or max_distance_voxels");
    if (!(o.voxel_size >= 0) || std::isinf(o.voxel_size)) bad("voxel_size must be >= 0 (0 = mean edge length), got " + num(o.voxel_size));
    if (o.sigma_position_voxels != sigma_position_auto &&
        (!(o.sigma_position_voxels > 0) || std::isinf(o.sigma_position_voxels)))
        bad("sigma_position_voxels must be > 0 and finite (voxels), or sigma_position_auto, got " +
            num(o.sigma_position_voxels));
    if (!(o.sigma_normal > 0) || std::isinf(o.sigma_normal)) bad("sigma_normal must be > 0 and finite, got " + num(o.sigma_normal));
    if (!(o.max_normal_change_degrees > 0 && o.max_normal_change_degrees < 180))
        bad("max_normal_change_degrees must be in (0, 180), got " + num(o.max_normal_change_degrees));
    if (!(o.min_triangle_quality >= 0 && o.min_triangle_quality < 1))
        bad("min_triangle_quality must be in [0, 1), got " + num(o.min_triangle_quality));
    if (o.threads < 0) bad("threads must be >= 0 (0 = all cores), got " + std::to_string(o.threads));
}

/// The input checks of decimate()'s contract (input_error naming the face
/// or point).
void check_input(const Mesh& mesh) {
    const std::size_t n = mesh.points.size();
    if (!mesh.normals.empty() && mesh.normals.size() != n)
        throw input_error("decimate: the mesh has " + std::to_string(mesh.normals.size()) + " vertex normals for " +
                          std::to_string(n) + " points; give one normal per point, or none");
    auto check = [&](const unsigned* idx, int count, const char* kind, std::size_t face) {
        for (int i = 0; i < count; ++i) {
            if (idx[i] >= n)
                throw input_error("decimate: " + std::string(kind) + " " + std::to_string(face) + " refers to point " +
                                  std::to_string(idx[i]) + " but the mesh has " + std::to_string(n) + " points");
            const openvdb::Vec3d& p = mesh.points[idx[i]];
            if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]))
                throw input_error("decimate: point " + std::to_string(idx[i]) + " (used by " + kind + " " +
                                  std::to_string(face) + ") has a NaN or infinite coordinate; fix the point or "
                                  "drop the faces using it");
        }
    };
    for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
        const auto& t = mesh.triangles[f];
        const unsigned idx[3] = {t[0], t[1], t[2]};
        check(idx, 3, "triangle", f);
    }
    for (std::size_t f = 0; f < mesh.quads.size(); ++f) {
        const auto& q = mesh.quads[f];
        const unsigned idx[4] = {q[0], q[1], q[2], q[3]};
        check(idx, 4, "quad", f);
    }
}

/// Triangles of a checked input: its triangles, then its quads split along
/// the shorter diagonal, unless that diagonal lies outside the quad (a
/// concave quad: its two triangles face opposite ways, overlapping) and the
/// other does not. Faces that repeat a point (the needles STL welding makes
/// of facets with two equal corners) are left out and counted in `dropped`;
/// a quad with one corner repeated next to itself is the triangle of the
/// other three.
std::vector<dd::Tri> input_triangles(const Mesh& mesh, std::size_t* dropped = nullptr) {
    std::vector<dd::Tri> tris;
    detail::reserve_large(tris, mesh.triangles.size() + 2 * mesh.quads.size());
    std::size_t left_out = 0;
    for (const auto& t : mesh.triangles) {
        if (t[0] == t[1] || t[1] == t[2] || t[2] == t[0]) ++left_out;
        else tris.push_back({t[0], t[1], t[2]});
    }
    const std::vector<openvdb::Vec3d>& p = mesh.points;
    auto same_side = [&](unsigned a, unsigned b, unsigned c, unsigned d, unsigned e, unsigned f) {
        return (p[b] - p[a]).cross(p[c] - p[a]).dot((p[e] - p[d]).cross(p[f] - p[d])) > 0;
    };
    for (const auto& quad : mesh.quads) {
        unsigned corners[4], n = 0;
        for (int k = 0; k < 4; ++k)
            if (quad[k] != quad[(k + 3) % 4]) corners[n++] = quad[k];  // cyclic runs of one point kept once
        if (n == 3 && corners[0] != corners[2]) {
            tris.push_back({corners[0], corners[1], corners[2]});
            continue;
        }
        if (n != 4 || corners[0] == corners[2] || corners[1] == corners[3]) {
            ++left_out;
            continue;
        }
        const openvdb::Vec4I q(corners[0], corners[1], corners[2], corners[3]);
        const double d02 = (p[q[0]] - p[q[2]]).lengthSqr();
        const double d13 = (p[q[1]] - p[q[3]]).lengthSqr();
        const bool inside02 = same_side(q[0], q[1], q[2], q[0], q[2], q[3]);
        const bool inside13 = same_side(q[0], q[1], q[3], q[1], q[2], q[3]);
        if (inside02 != inside13 ? inside02 : d02 <= d13) {
            tris.push_back({q[0], q[1], q[2]});
            tris.push_back({q[0], q[2], q[3]});
        } else {
            tris.push_back({q[0], q[1], q[3]});
            tris.push_back({q[1], q[2], q[3]});
        }
    }
    if (dropped) *dropped = left_out;
    return tris;
}

/// A vertex may move iff its faces form one closed fan in which every edge
/// from it is used by exactly two faces in opposite directions.
bool closed_manifold_fan(const dd::WorkMesh& m, std::uint32_t v) {
    const std::size_t n = m.fan_size(v);
    if (n < 3 || n > 64) return false;
    std::uint32_t next[64], prev[64];
    for (std::size_t i = 0; i < n; ++i) {
        const dd::Tri& t = m.tris[m.fan_of(v)[i]];
        const int k = t[0] == v ? 0 : (t[1] == v ? 1 : 2);
        next[i] = t[(k + 1) % 3];
        prev[i] = t[(k + 2) % 3];
    }
    // Walk face -> the face whose prev is this face's next; one cycle of n.
    std::size_t at = 0;
    for (std::size_t steps = 0; steps < n; ++steps) {
        std::size_t found = n;
        for (std::size_t j = 0; j < n; ++j)
            if (prev[j] == next[at]) {
                if (found != n) return false;  // the edge has more than two faces
                found = j;
            }
        if (found == n) return false;  // boundary or inconsistent orientation
        at = found;
        if (at == 0 && steps + 1 < n) return false;  // several fans (non-manifold vertex)
    }
    if (at != 0) return false;
    for (std::size_t i = 0; i < n; ++i)
        for (std::size_t j = i + 1; j < n; ++j)
            if (next[i] == next[j]) return false;
    return true;
}

double mean_edge_length(const std::vector<openvdb::Vec3d>& p, const std::vector<dd::Tri>& tris) {
    double sum = 0;
    for (const dd::Tri& t : tris)
        for (int k = 0; k < 3; ++k) sum += (p[t[k]] - p[t[(k + 1) % 3]]).length();
    return tris.empty() ? 0 : sum / double(3 * tris.size());
}

/// options.progress behind a clamp and the cancellation rule.
class Reporter {
public:
    explicit Reporter(const DecimateOptions& o) : callback_(o.progress) {}
    void operator()(double fraction) const {
        if (callback_ && !callback_(std::clamp(fraction, 0.0, 1.0)))
            throw cancelled_error("decimation cancelled by the caller");
    }

private:
    const std::function<bool(double)>& callback_;
};

/// Passes until the face target is met or no collapse is admissible (a
/// pass that refused all its cheap candidates is followed by one that looks
/// at all of them). The passes' buffers are freed on return.
void run_passes(dd::WorkMesh& m, const DecimateOptions& chosen, const dd::CheckLimits& lim, std::size_t target,
                const Reporter& report, DecimateStats& st) {
    bool unlimited = false;
    dd::PassBuffers buffers;
    // The finished fraction of the faces to remove, never reported lower
    // than before. Within a pass: the faces removed before it plus the
    // pass's share of the work done times the faces it will remove, 2 per
    // planned collapse once chosen, before that the previous pass's share
    // of its faces (the first pass: the usual 13%, 1-ring locks allowing
    // no more).
    const double to_remove = double(st.input_faces) - double(std::min(target, st.input_faces));
    double shown = 0, pass_share_of_faces = 0.13;
    auto removed = [&] { return double(st.input_faces) - double(m.tris.size()); };
    auto show = [&](double faces_removed) {
        if (to_remove > 0) shown = std::max(shown, std::min(faces_removed / to_remove, 1.0));
        report(shown);
    };
    while (m.tris.size() > target) {
        const double before = removed(), faces = double(m.tris.size());
        const double left = faces - double(target);
        show(before);
        const dd::PassCheckpoint checkpoint = [&](double share, std::size_t planned) {
            const double pass = planned > 0 ? 2.0 * double(planned) : pass_share_of_faces * faces;
            show(before + share * std::min(pass, left));
        };
        const dd::PassResult r = dd::run_pass(m, chosen, lim, target, unlimited, buffers, checkpoint);
        pass_share_of_faces = (removed() - before) / faces;
        ++st.passes;
        st.collapses += r.collapses;
        st.rejected_link += r.rejected[int(dd::Verdict::link)];
        st.rejected_flip += r.rejected[int(dd::Verdict::flip)];
        st.rejected_quality += r.rejected[int(dd::Verdict::quality)];
        st.rejected_intersection += r.rejected[int(dd::Verdict::intersection)];
        st.rejected_distance += r.rejected[int(dd::Verdict::distance)];
        if (r.collapses == 0 && unlimited) break;
        unlimited = r.collapses == 0;
    }
}

void run(Mesh& mesh, const DecimateOptions& o, DecimateStats& st) {
    // The set-up reports 0 between its steps: cancellation points before the first pass.
    const Reporter report(o);
    report(0.0);
    check_input(mesh);
    std::vector<dd::Tri> tris = input_triangles(mesh, &st.dropped_faces);
    st.input_faces = tris.size();
    dd::WorkMesh m;
    detail::reserve_large(m.pos, mesh.points.size());
    m.pos.resize(mesh.points.size());
    for (std::size_t i = 0; i < mesh.points.size(); ++i) m.pos[i] = {mesh.points[i][0], mesh.points[i][1], mesh.points[i][2]};
    // Checked in double, then rounded by a float writer, collapses made
    // intersections and broke the distance bound far from the origin.
    m.float_positions = o.stored_precision == VertexPrecision::float32;
    if (m.float_positions)
        for (dd::vec& p : m.pos) p = detail::rounded_to_float(p);
    m.voxel = o.voxel_size > 0 ? o.voxel_size : mean_edge_length(mesh.points, tris);
    if (!(m.voxel > 0)) m.voxel = 1;
    st.voxel_size = m.voxel;
    vec3<double> lo{std::numeric_limits<double>::infinity(), 0, 0}, hi{};
    for (const dd::Tri& t : tris)
        for (std::uint32_t v : t) {
            const dd::vec& p = m.pos[v];
            if (!(lo.x <= hi.x)) lo = hi = p;
            lo = dd::component_min(lo, p);
            hi = dd::component_max(hi, p);
        }
    if (!tris.empty()) m.origin = (lo + hi) * 0.5;

    std::unique_ptr<MeshDistance> surface;
    dd::CheckLimits lim;
    lim.min_cos_normal_change = std::cos(o.max_normal_change_degrees * M_PI / 180);
    lim.min_quality = o.min_triangle_quality;
    if (o.max_distance_voxels > 0 && !tris.empty()) {
        Mesh input;
        input.points = mesh.points;
        for (const dd::Tri& t : tris) input.triangles.emplace_back(t[0], t[1], t[2]);
        surface = std::make_unique<MeshDistance>(input);
        lim.input_surface = surface.get();
        lim.max_distance = o.max_distance_voxels * m.voxel;
    }
    m.tris = std::move(tris);
    dd::rebuild_fans(m);
    m.locked.assign(m.pos.size(), 0);
    if (!mesh.normals.empty()) m.merged_into.assign(m.pos.size(), std::numeric_limits<std::uint32_t>::max());
    dd::parallel_ranges(m.pos.size(), 4096, [&](std::size_t begin, std::size_t end) {
        for (std::size_t v = begin; v < end; ++v)
            m.locked[v] = m.fan_size(std::uint32_t(v)) > 0 && !closed_manifold_fan(m, std::uint32_t(v));
    });
    st.locked_vertices = std::size_t(std::count(m.locked.begin(), m.locked.end(), 1));
    report(0.0);
    DecimateOptions chosen = o;
    if (o.sigma_position_voxels == sigma_position_auto) {
        st.noise_voxels = dd::estimate_vertex_noise_voxels(m);
        chosen.sigma_position_voxels = dd::sigma_position_for_noise(st.noise_voxels);
    }
    st.sigma_position_voxels = chosen.sigma_position_voxels;
    dd::build_vertex_quadrics(m, chosen);
    if (o.metric == DecimateMetric::curvature) dd::build_vertex_spheres(m);

    std::size_t target = o.target_faces;
    // At most ratio x input faces (ceil stopped one face above it: 6420 for
    // 0.12345 x 52000); the slack keeps 0.29 x 100 at 29, not 28.
    if (o.target_ratio > 0)
        target = std::max({target, std::size_t(1),
                           std::size_t(std::floor(o.target_ratio * double(st.input_faces) + 1e-9))});
    report(0.0);
    run_passes(m, chosen, lim, target, report, st);
    // The output needs the positions and faces only.
    std::vector<dd::Quadric>().swap(m.quadrics);
    std::vector<std::uint32_t>().swap(m.fan);

    // Output: used points in their input order, unmoved ones bit-identical.
    std::vector<std::uint32_t> remap(m.pos.size(), std::numeric_limits<std::uint32_t>::max());
    for (const dd::Tri& t : m.tris)
        for (std::uint32_t v : t) remap[v] = 0;
    Mesh out;
    for (std::size_t v = 0; v < m.pos.size(); ++v)
        if (remap[v] == 0) {
            remap[v] = std::uint32_t(out.points.size());
            out.points.emplace_back(m.pos[v].x, m.pos[v].y, m.pos[v].z);
        }
    out.triangles.reserve(m.tris.size());
    for (const dd::Tri& t : m.tris) out.triangles.emplace_back(remap[t[0]], remap[t[1]], remap[t[2]]);
    st.output_faces = out.triangles.size();
    st.output_vertices = out.points.size();
    if (!mesh.normals.empty())
        out.normals = dd::transfer_vertex_normals(mesh, input_triangles(mesh), m.merged_into, remap, out.points);
    report(1.0);
    mesh = std::move(out);
}

}  // namespace

void check_decimate_memory(std::size_t triangles, const DecimateOptions& o) {
    const std::size_t limit = o.memory_limit_bytes > 0 ? o.memory_limit_bytes : detail::default_memory_limit();
    const double needed = double(triangles) * double(kDecimateBytesPerTriangle);
    if (needed <= double(limit)) return;
    std::ostringstream s;
    s << "decimate: " << triangles << " triangles would need about " << detail::byte_size_text(needed) << " ("
      << kDecimateBytesPerTriangle << " bytes each), more than the " << detail::byte_size_text(double(limit))
      << " allowed; decimate a smaller mesh (a coarser grid or a region), or raise the memory limit";
    throw resource_error(s.str());
}

void validate(const DecimateOptions& options) { check_options(options); }

void decimate(Mesh& mesh, const DecimateOptions& options, DecimateStats* stats) {
    const auto start = std::chrono::steady_clock::now();
    check_options(options);
    // Before anything is allocated: an OOM kill leaves the user no message.
    check_decimate_memory(mesh.triangles.size() + 2 * mesh.quads.size(), options);
    DecimateStats st;
    if (options.threads > 0) {
        // More than TBB's worker limit (the cores) would make TBB print a
        // warning to stderr; the result does not depend on the count.
        const int most = int(tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
        tbb::task_arena arena(std::min(options.threads, std::max(most, 1)));
        arena.execute([&] { run(mesh, options, st); });
    } else {
        run(mesh, options, st);
    }
    st.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (stats) *stats = st;
}

}  // namespace pqdc
