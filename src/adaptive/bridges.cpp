#include "adaptive/bridges.hpp"

#include "adaptive/repair.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>

namespace pqdc::adaptive_detail {

namespace {

using Edge = std::pair<std::uint32_t, std::uint32_t>;

/// Outward normals at a bridge's ends are more than 120 degrees apart.
constexpr double kFacingCosine = -0.5;

/// Every edge of the faces once, smaller index first, sorted.
std::vector<Edge> unique_edges(const Mesh& mesh) {
    std::vector<Edge> edges;
    edges.reserve(3 * mesh.triangles.size() + 4 * mesh.quads.size());
    for_each_face(mesh, [&](const std::uint32_t* f, int k) {
        for (int i = 0; i < k; ++i) {
            const std::uint32_t a = f[i], b = f[(i + 1) % k];
            edges.emplace_back(std::min(a, b), std::max(a, b));
        }
    });
    std::sort(edges.begin(), edges.end());
    edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
    return edges;
}

}  // namespace

double bridge_limit_voxels(double max_error_voxels) {
    if (!(max_error_voxels > 0)) return std::numeric_limits<double>::infinity();
    return std::min(1.0 + max_error_voxels, 2.0);
}

std::vector<openvdb::Vec3d> bridge_ends(const Mesh& mesh, const FieldSource& field, double max_error_voxels) {
    const double limit_voxels = bridge_limit_voxels(max_error_voxels);
    if (!(limit_voxels < std::numeric_limits<double>::infinity())) return {};
    const std::vector<Edge> edges = unique_edges(mesh);
    std::vector<std::uint8_t> bridge(edges.size(), 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, edges.size(), 4096), [&](const auto& r) {
        const auto probe = field.probe();
        for (std::size_t e = r.begin(); e != r.end(); ++e) {
            const openvdb::Vec3d &a = mesh.points[edges[e].first], &b = mesh.points[edges[e].second];
            const openvdb::Vec3d mid = 0.5 * (a + b);
            // Inside (or on) the surface: no gap here. Only then the gradient (six probes).
            if (!(probe->value(mid) > 0.0)) continue;
            // The ends lie within about the merge error of the surface, so the
            // middle lies within half the edge beyond it: the first-order
            // estimate, inflated where gradients cancel (between two close
            // sheets), is capped by that.
            const double reach = 0.5 * (b - a).length() + max_error_voxels;
            const double distance = field_distance_voxels(*probe, mid, field_gradient_length(*probe, mid));
            if (!(std::min(distance, reach) > limit_voxels)) continue;
            // Across a gap the two sheets face each other; the air wedge of a
            // concave crease (faces at 90 degrees, say) is outside as well,
            // but its faces do not: only nearly opposite outward normals count.
            const openvdb::Vec3d na = field_gradient(*probe, a, 0.5), nb = field_gradient(*probe, b, 0.5);
            const double la = na.length(), lb = nb.length();
            // Where the field is flat at the middle (a level set's clamped
            // background: no surface within its band) or at an end (a vertex
            // off in it, as with an unbounded merge error), the distance
            // decides alone.
            const bool normals = la > 0 && lb > 0 && std::isfinite(la * lb);
            bridge[e] = !std::isfinite(distance) || !normals ||
                        (na.dot(nb) < kFacingCosine * la * lb && na.dot(b - a) > 0 && nb.dot(a - b) > 0);
        }
    });
    std::vector<openvdb::Vec3d> ends;
    for (std::size_t e = 0; e < edges.size(); ++e)
        if (bridge[e]) {
            ends.push_back(mesh.points[edges[e].first]);
            ends.push_back(mesh.points[edges[e].second]);
        }
    return ends;
}

Mesh refine_bridges(Mesh mesh, const Rebuild& rebuild, const FieldSource& field, const Octree& frame,
                    double max_error_voxels, PinnedCells& pinned, const detail::ProgressSpan& span,
                    AdaptiveStats& stats) {
    std::vector<openvdb::Vec3d> ends = bridge_ends(mesh, field, max_error_voxels);
    stats.bridges_found = ends.size() / 2;
    double from = 0.0;
    while (!ends.empty() && pinned.pin_around(frame, ends) > 0) {
        const double to = from + (1.0 - from) / 2;
        AdaptiveStats round;
        mesh = rebuild(pinned, ShapeLimits{}, span.part(from, to), round);
        from = to;
        take_rebuild_counters(std::move(round), stats);
        ends = bridge_ends(mesh, field, max_error_voxels);
    }
    stats.bridge_pinned_cells = pinned.size();
    span.report(1.0);
    return mesh;
}

}  // namespace pqdc::adaptive_detail
