// Small-component removal (include/pqdc/components.hpp). Serial: one
// union-find pass and one compaction pass, linear in the mesh size.
#include "pqdc/components.hpp"

#include "pqdc/exceptions.hpp"
#include "measure/mesh_internal.hpp"
#include "postprocess/component_rule.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

namespace pqdc {

namespace {

constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();

void validate(double voxel_size, const ComponentFilterOptions& options) {
    if (!(voxel_size > 0.0) || !std::isfinite(voxel_size))
        throw option_error("remove_small_components: voxel_size = " + std::to_string(voxel_size) +
                           " must be a positive finite world length (the grid's voxel size)");
    if (!(options.min_diagonal_voxels >= 0.0))
        throw option_error("ComponentFilterOptions::min_diagonal_voxels must be >= 0 voxels (0 keeps everything)");
}

/// Component root of every referenced point (kNone for unreferenced ones).
std::vector<std::uint32_t> component_roots(const Mesh& mesh) {
    detail::UnionFind sets(mesh.points.size());
    std::vector<char> used(mesh.points.size(), 0);
    for (const auto& t : mesh.triangles) {
        for (int k = 0; k < 3; ++k) used[t[k]] = 1;
        sets.unite(t[0], t[1]);
        sets.unite(t[0], t[2]);
    }
    for (const auto& q : mesh.quads) {
        for (int k = 0; k < 4; ++k) used[q[k]] = 1;
        for (int k = 1; k < 4; ++k) sets.unite(q[0], q[k]);
    }
    std::vector<std::uint32_t> root(mesh.points.size(), kNone);
    for (std::size_t v = 0; v < mesh.points.size(); ++v)
        if (used[v]) root[v] = sets.find(std::uint32_t(v));
    return root;
}

}  // namespace

Mesh remove_small_components(const Mesh& mesh, double voxel_size, const ComponentFilterOptions& options,
                             ComponentFilterStats* stats) {
    validate(voxel_size, options);
    detail::check_indices(mesh);
    const std::size_t n = mesh.points.size();
    if (!mesh.normals.empty() && mesh.normals.size() != n)
        throw input_error("remove_small_components: the mesh has " + std::to_string(mesh.normals.size()) +
                          " vertex normals for " + std::to_string(n) + " points; give one normal per point, or none");
    const std::vector<std::uint32_t> root = component_roots(mesh);

    // A number per root (in vertex order) and a box per component; the rule
    // is shared with the streamed filter (detail::ComponentRule).
    std::vector<std::uint32_t> number(n, kNone);
    std::uint32_t count = 0;
    for (std::size_t v = 0; v < n; ++v)
        if (root[v] == v) number[v] = count++;
    std::vector<detail::ComponentBox> boxes(count);
    for (std::size_t v = 0; v < n; ++v)
        if (root[v] != kNone) boxes[number[root[v]]].add(mesh.points[v]);
    detail::ComponentRule rule{voxel_size, options.min_diagonal_voxels, {}, false};
    std::vector<char> remove(n, 0);
    for (std::size_t v = 0; v < n; ++v)
        if (root[v] == v) remove[v] = rule.remove(boxes[number[v]]);
    ComponentFilterStats s = rule.stats;

    Mesh out;
    std::vector<std::uint32_t> new_index(n, kNone);
    for (std::size_t v = 0; v < n; ++v) {
        if (root[v] != kNone && remove[root[v]]) {
            ++s.removed_points;
            continue;
        }
        new_index[v] = std::uint32_t(out.points.size());
        out.points.push_back(mesh.points[v]);
        if (mesh.normals.size() == n) out.normals.push_back(mesh.normals[v]);
    }
    for (const auto& t : mesh.triangles) {
        if (remove[root[t[0]]]) continue;
        out.triangles.emplace_back(new_index[t[0]], new_index[t[1]], new_index[t[2]]);
    }
    for (const auto& q : mesh.quads) {
        if (remove[root[q[0]]]) continue;
        out.quads.emplace_back(new_index[q[0]], new_index[q[1]], new_index[q[2]], new_index[q[3]]);
    }
    s.removed_faces = mesh.face_count() - out.face_count();
    if (stats) *stats = s;
    return out;
}

}  // namespace pqdc
