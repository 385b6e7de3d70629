// Adaptive stage "repair": what the collapses could not merge or left flat.
#pragma once

#include "lattice/resources.hpp"
#include "pqdc/mesh.hpp"
#include "pqdc/stats.hpp"

#include <openvdb/openvdb.h>

#include <cstdint>
#include <vector>

namespace pqdc::adaptive_detail {

/// visit(corners, count) for every face: the triangles, then the quads.
template <class Visit>
void for_each_face(const Mesh& mesh, Visit&& visit) {
    for (const auto& t : mesh.triangles) {
        const std::uint32_t f[3] = {t[0], t[1], t[2]};
        visit(f, 3);
    }
    for (const auto& q : mesh.quads) {
        const std::uint32_t f[4] = {q[0], q[1], q[2], q[3]};
        visit(f, 4);
    }
}

/// Vertices the collapse had to keep apart although they coincide (a fold
/// of the surface through one leaf vertex, where merging them would make an
/// edge non-manifold) are moved a hair (1e-4 of the way towards the centroid
/// of their other neighbours) so that no face has zero area. The first vertex
/// of each coincident group stays. Counts them in stats.separated_vertices.
/// The span reports (and cancels) after the sort.
void separate_coincident_vertices(Mesh& mesh, AdaptiveStats& stats, const detail::ProgressSpan& span);

/// Triangles whose corners are collinear (three leaf vertices on one
/// straight feature line, e.g. sigma_n = 0 on a box edge) are removed by
/// flipping their longest edge: with b on segment ac, the triangles (a,b,c)
/// and (a,c,d) become (a,b,d) and (b,c,d), which tile the same area. Skipped
/// when the new edge bd already exists (the flip would make it non-manifold).
/// Flipped triangles are marked in `changed`.
void flip_collinear_triangles(const std::vector<openvdb::Vec3d>& points, std::vector<openvdb::Vec3I>& tris,
                              const std::vector<std::uint8_t>& alive, std::vector<std::uint8_t>& changed);

}  // namespace pqdc::adaptive_detail
