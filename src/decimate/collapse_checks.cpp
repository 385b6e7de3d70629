// Safety checks of one edge collapse, all evaluated on the mesh as it was at
// the start of the pass (the scheduler makes the collapses of a pass
// independent, so each check stays valid when the others are applied).
//
// Link condition: Dey, Edelsbrunner, Guha & Nekhayev, "Topology Preserving
// Edge Contraction" (1999): for an interior edge a-b of a closed 2-manifold,
// the contraction preserves the topology iff the common neighbours of a and
// b are exactly the two vertices opposite the edge. Together with "no vertex
// drops below valence 3" (which rules out collapsing a tetrahedron) this
// keeps a closed manifold closed, manifold and of the same genus.
// Normal flips and the quality bound follow pmp-library's decimation.cpp
// (normal deviation, aspect ratio) with the quality measure of
// 4 sqrt(3) area / sum of squared sides.
// Self-intersection: the created faces are tested with the exact predicates
// of exact_predicates.hpp against every live triangle whose grid cells meet
// their bounding box, and against each other.

#include "decimate_internal.hpp"
#include "exact_predicates.hpp"

#include <algorithm>
#include <cmath>

namespace pqdc::decimate_detail {
namespace {

constexpr std::size_t kMaxValence = 64;  // larger fans are refused (never met on sane meshes)

double quality(const vec& p, const vec& q, const vec& r) {
    const double len = length(cross(q - p, r - p));
    const double sides = length_sqr(q - p) + length_sqr(r - q) + length_sqr(p - r);
    return sides > 0 ? 2 * std::sqrt(3.0) * len / sides : 0.0;
}

bool contains(const Tri& t, std::uint32_t v) { return t[0] == v || t[1] == v || t[2] == v; }

}  // namespace

// ------------------------------------------------------------------ checks

bool link_condition_holds(const WorkMesh& m, std::uint32_t a, std::uint32_t b) {
    const std::size_t na = m.fan_size(a), nb = m.fan_size(b);
    if (na > kMaxValence || nb > kMaxValence || na + nb < 7) return false;  // merged valence na + nb - 4 >= 3
    std::uint32_t ring_a[kMaxValence], opposite[2];
    std::size_t ra = 0, shared_faces = 0;
    for (std::size_t i = 0; i < na; ++i) {
        const Tri& t = m.tris[m.fan_of(a)[i]];
        for (int k = 0; k < 3; ++k)
            if (t[k] == a) ring_a[ra++] = t[(k + 1) % 3];  // closed fan: each neighbour once
        if (contains(t, b)) {
            if (shared_faces == 2) return false;
            for (int k = 0; k < 3; ++k)
                if (t[k] != a && t[k] != b) opposite[shared_faces] = t[k];
            ++shared_faces;
        }
    }
    if (shared_faces != 2 || opposite[0] == opposite[1]) return false;
    if (m.fan_size(opposite[0]) < 4 || m.fan_size(opposite[1]) < 4) return false;
    std::size_t common = 0;
    for (std::size_t i = 0; i < nb; ++i) {
        const Tri& t = m.tris[m.fan_of(b)[i]];
        for (int k = 0; k < 3; ++k) {
            if (t[k] != b) continue;
            const std::uint32_t w = t[(k + 1) % 3];
            if (std::find(ring_a, ring_a + ra, w) != ring_a + ra) {
                if (w != opposite[0] && w != opposite[1]) return false;
                ++common;
            }
        }
    }
    return common == 2;
}

Verdict check_shape(const WorkMesh& m, const Candidate& c, const CheckLimits& lim) {
    // The old faces' quality matters only when a new face falls below the
    // bound (rare), so it is computed then; each face's cross products serve
    // both the normal test and the quality (same expressions as quality()).
    double worst_new = 1;
    for (std::uint32_t v : {c.a, c.b}) {
        for (std::size_t i = 0; i < m.fan_size(v); ++i) {
            const Tri& t = m.tris[m.fan_of(v)[i]];
            if (contains(t, c.a) && contains(t, c.b)) continue;
            const vec p[3] = {m.pos[t[0]], m.pos[t[1]], m.pos[t[2]]};
            vec q[3] = {p[0], p[1], p[2]};
            for (int k = 0; k < 3; ++k)
                if (t[k] == v) q[k] = c.x;
            const vec n0 = cross(p[1] - p[0], p[2] - p[0]), n1 = cross(q[1] - q[0], q[2] - q[0]);
            const double old_len = length(n0), new_len = length(n1);
            const double sides = length_sqr(q[1] - q[0]) + length_sqr(q[2] - q[1]) + length_sqr(q[0] - q[2]);
            worst_new = std::min(worst_new, sides > 0 ? 2 * std::sqrt(3.0) * new_len / sides : 0.0);
            if (!(new_len > 0) || !(dot(n0, n1) >= lim.min_cos_normal_change * old_len * new_len))
                return Verdict::flip;
        }
    }
    if (worst_new >= lim.min_quality) return Verdict::ok;
    double worst_old = 1;
    for (std::uint32_t v : {c.a, c.b})
        for (std::size_t i = 0; i < m.fan_size(v); ++i) {
            const Tri& t = m.tris[m.fan_of(v)[i]];
            worst_old = std::min(worst_old, quality(m.pos[t[0]], m.pos[t[1]], m.pos[t[2]]));
        }
    return worst_new < std::min(lim.min_quality, worst_old) ? Verdict::quality : Verdict::ok;
}

bool faces_intersect(const Tri& t, const vec pt[3], const Tri& u, const vec pu[3]) {
    int ti[3], ui[3], shared = 0;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            if (t[i] == u[j]) {
                ti[shared] = i;
                ui[shared] = j;
                ++shared;
            }
    if (shared == 0) return exact::triangles_intersect(pt, pu);
    if (shared == 3) return true;
    if (shared == 2) {
        const int ta = 3 - ti[0] - ti[1], uc = 3 - ui[0] - ui[1];
        return exact::triangles_overlap_sharing_edge(pt[ti[0]], pt[ti[1]], pt[ta], pu[uc]);
    }
    const int s = ti[0], r = ui[0];
    return exact::triangles_intersect_sharing_vertex(pt[s], pt[(s + 1) % 3], pt[(s + 2) % 3], pu[(r + 1) % 3],
                                                     pu[(r + 2) % 3]);
}

BoxPair write_created_faces(const WorkMesh& m, const Candidate& c, Tri* tris, std::array<vec, 3>* points,
                            BoxPair* boxes) {
    BoxPair all{c.x, c.x};
    std::size_t n = 0;
    for (std::uint32_t v : {c.a, c.b})
        for (std::size_t i = 0; i < m.fan_size(v); ++i) {
            Tri t = m.tris[m.fan_of(v)[i]];
            if (contains(t, c.a) && contains(t, c.b)) continue;
            for (int k = 0; k < 3; ++k) {
                if (t[k] == c.b) t[k] = c.a;
                points[n][k] = t[k] == c.a ? c.x : m.pos[t[k]];
            }
            tris[n] = t;
            boxes[n] = triangle_box(points[n][0], points[n][1], points[n][2]);
            all = {component_min(all[0], boxes[n][0]), component_max(all[1], boxes[n][1])};
            ++n;
        }
    return all;
}

Verdict check_intersection_and_distance(const WorkMesh& m, const TriangleGrid& grid, const Candidate& c,
                                        const CreatedFaces& created, const CheckLimits& lim,
                                        std::vector<exact::plane_filter>& planes, std::vector<std::uint32_t>& near) {
    const Tri* faces = created.tris;
    const std::array<vec, 3>* fp = created.points;
    const BoxPair* fb = created.boxes;
    const std::size_t count = created.count;
    planes.clear();
    for (std::size_t i = 0; i < count; ++i) planes.emplace_back(fp[i].data());
    for (std::size_t i = 0; i < count; ++i)
        for (std::size_t j = i + 1; j < count; ++j)
            if (boxes_meet(fb[i], fb[j]) && !certainly_apart(planes[i], faces[i], faces[j], fp[j].data()) &&
                faces_intersect(faces[i], fp[i].data(), faces[j], fp[j].data()))
                return Verdict::intersection;
    // A face that already crossed one of the faces being replaced was an
    // intersection of the input (none arise otherwise): meeting it again is
    // tolerated, so decimation does not stall around input defects.
    auto crossed_before = [&](const Tri& u, const vec pu[3]) {
        for (std::uint32_t v : {c.a, c.b})
            for (std::size_t k = 0; k < m.fan_size(v); ++k) {
                const Tri& t = m.tris[m.fan_of(v)[k]];
                const vec pt[3] = {m.pos[t[0]], m.pos[t[1]], m.pos[t[2]]};
                if (faces_intersect(t, pt, u, pu)) return true;
            }
        return false;
    };
    grid.query(created.all[0], created.all[1], near);
    for (std::uint32_t id : near) {
        const Tri& u = m.tris[id];
        if (contains(u, c.a) || contains(u, c.b)) continue;  // replaced by the new faces
        const BoxPair& ub = grid.box(id);
        const vec pu[3] = {m.pos[u[0]], m.pos[u[1]], m.pos[u[2]]};
        for (std::size_t i = 0; i < count; ++i)
            if (boxes_meet(fb[i], ub) && !certainly_apart(planes[i], faces[i], u, pu) &&
                faces_intersect(faces[i], fp[i].data(), u, pu)) {
                if (crossed_before(u, pu)) break;
                return Verdict::intersection;
            }
    }
    if (lim.input_surface) {
        // The vertex is the bound; the midpoints of its new edges and the
        // new faces' centroids are checked too, so a face cannot cut far
        // across the input between its corners (still a sampled estimate).
        auto far = [&](const vec& p) { return (*lim.input_surface)(openvdb::Vec3d(p.x, p.y, p.z)) > lim.max_distance; };
        if (far(c.x)) return Verdict::distance;
        for (std::size_t i = 0; i < count; ++i) {
            const std::array<vec, 3>& p = fp[i];
            if (far((p[0] + p[1] + p[2]) / 3.0)) return Verdict::distance;
            for (int k = 0; k < 3; ++k)
                if ((p[k] == c.x) && far((p[k] + p[(k + 1) % 3]) * 0.5)) return Verdict::distance;
        }
    }
    return Verdict::ok;
}

}  // namespace pqdc::decimate_detail
