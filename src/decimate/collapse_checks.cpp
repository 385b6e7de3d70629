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
                            FloatBox* boxes) {
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
            const BoxPair box = triangle_box(points[n][0], points[n][1], points[n][2]);
            boxes[n] = float_box(box);
            all = {component_min(all[0], box[0]), component_max(all[1], box[1])};
            ++n;
        }
    return all;
}

std::size_t created_link(const Candidate& c, const CreatedFaces& created, std::uint32_t* link) {
    if (created.count > kMaxLink) return 0;
    for (std::size_t i = 0; i < created.count; ++i) {
        const Tri& t = created.tris[i];
        const int k = t[0] == c.a ? 0 : (t[1] == c.a ? 1 : 2);
        link[i] = t[(k + 1) % 3];  // each created face (x, w_i, w_i+1) gives one link vertex
    }
    return created.count;
}

// The local disc certificate. After the collapse, D is the closed star of
// the new vertex x and of its link vertices w_i: the created faces and the
// faces at the w_i that do not contain a or b. No w_i is locked, so each
// has one closed, consistently oriented fan in D (the collapse keeps it so),
// and every edge at x or at a w_i is shared by two faces of D in opposite
// directions; D's algebraic boundary is then made of the other edges, those
// of its faces with both ends outside the link ("outer" edges).
// Project along a coordinate axis (dropping one coordinate: no rounding).
// For a point P of the plane off all edges, the number of faces of D above
// P, each counted with its orientation's sign, is the winding number of the
// boundary around P. If every face of D turns counter-clockwise, and every
// outer edge does too as seen from x', and the outer edges cross the ray
// from x' in +u once, then the boundary is one closed curve sweeping
// monotonically once around x' (every closed part of it would sweep a
// positive multiple of a full turn): a simple star-shaped polygon. So every
// point off the edges lies over one face of D or none, the projections of
// two faces share no interior point, and a face cannot even touch another
// away from what they share (a vertex on an edge's interior would put a
// second layer next to it: the vertex's closed fan covers both sides, or,
// for an outer vertex, two outer edges would sweep the same angles). The
// projection is one-to-one on D, hence so is D in 3D: no two faces of D
// meet beyond their common edges and corners, which is what
// faces_intersect() would answer for every pair of created faces and every
// created face against a face of D. Faces whose outer edges meet in
// opposite directions (D not a disc) fail the test, never pass it.
namespace {

/// Marks of one collapse's link vertices, per thread (a stamp per
/// collapse, so nothing is cleared; stamps only grow, so a stale mark of an
/// earlier collapse or run never reads as current).
class LinkMarks {
public:
    void mark(std::size_t vertices, const std::uint32_t* link, std::size_t n) {
        if (stamp_.size() < vertices) stamp_.resize(vertices, 0);
        if (++current_ == 0) {  // wrapped: start over
            std::fill(stamp_.begin(), stamp_.end(), 0);
            current_ = 1;
        }
        for (std::size_t i = 0; i < n; ++i) stamp_[link[i]] = current_;
    }
    bool has(std::uint32_t v) const { return stamp_[v] == current_; }

private:
    std::vector<std::uint32_t> stamp_;
    std::uint32_t current_ = 0;
};

LinkMarks& link_marks() {
    thread_local LinkMarks marks;
    return marks;
}

double coordinate(const vec& p, int axis) { return axis == 0 ? p.x : (axis == 1 ? p.y : p.z); }

/// local_disc_embeds() with the link marked in `in_link`.
bool disc_embeds(const WorkMesh& m, const Candidate& c, const CreatedFaces& created, const std::uint32_t* link,
                 std::size_t link_size, const LinkMarks& in_link) {
    if (link_size == 0) return false;
    for (std::size_t i = 0; i < link_size; ++i)
        if (m.locked[link[i]]) return false;  // a fan that may be open or non-manifold
    // The axis the created faces face most; the other two in the order that
    // makes them turn counter-clockwise.
    vec n{};
    for (std::size_t i = 0; i < created.count; ++i) {
        const std::array<vec, 3>& p = created.points[i];
        n += cross(p[1] - p[0], p[2] - p[0]);
    }
    const double an[3] = {std::fabs(n.x), std::fabs(n.y), std::fabs(n.z)};
    const int k = an[0] >= an[1] && an[0] >= an[2] ? 0 : (an[1] >= an[2] ? 1 : 2);
    const double nk = coordinate(n, k);
    if (!(nk != 0)) return false;
    int iu = (k + 1) % 3, iv = (k + 2) % 3;
    if (nk < 0) std::swap(iu, iv);
    auto ccw = [iu, iv](const vec& p, const vec& q, const vec& r) {
        return exact::orient2d(coordinate(p, iu), coordinate(p, iv), coordinate(q, iu), coordinate(q, iv),
                               coordinate(r, iu), coordinate(r, iv)) > 0;
    };
    for (std::size_t i = 0; i < created.count; ++i) {
        const std::array<vec, 3>& p = created.points[i];
        if (!ccw(p[0], p[1], p[2])) return false;
    }
    // The other faces at each link vertex w, as (w, y, z). A face with two
    // link vertices is tested from both (harmless). The outer edges are the
    // y-z of the faces with one link vertex, so each is seen once.
    const vec& x = c.x;
    const double xv = coordinate(x, iv);
    std::size_t crossings = 0;
    for (std::size_t i = 0; i < link_size; ++i) {
        const std::uint32_t w = link[i];
        const std::uint32_t* fan = m.fan_of(w);
        const vec& pw = m.pos[w];
        for (std::size_t f = 0, nf = m.fan_size(w); f < nf; ++f) {
            const Tri& t = m.tris[fan[f]];
            if (contains(t, c.a) || contains(t, c.b)) continue;  // replaced by created faces
            const int at = t[0] == w ? 0 : (t[1] == w ? 1 : 2);
            const std::uint32_t y = t[(at + 1) % 3], z = t[(at + 2) % 3];
            const vec& py = m.pos[y];
            const vec& pz = m.pos[z];
            if (!ccw(pw, py, pz)) return false;
            if (in_link.has(y) || in_link.has(z)) continue;
            if (!ccw(x, py, pz)) return false;
            if (coordinate(py, iv) < xv && coordinate(pz, iv) >= xv && ++crossings > 1) return false;
        }
    }
    return crossings == 1;
}

}  // namespace

bool local_disc_embeds(const WorkMesh& m, const Candidate& c, const CreatedFaces& created, const std::uint32_t* link,
                       std::size_t link_size) {
    LinkMarks& marks = link_marks();
    marks.mark(m.pos.size(), link, link_size);
    return disc_embeds(m, c, created, link, link_size, marks);
}

Verdict check_intersection_and_distance(const WorkMesh& m, const TriangleGrid& grid, const Candidate& c,
                                        const CreatedFaces& created, const CheckLimits& lim,
                                        std::vector<exact::plane_filter>& planes, std::vector<std::uint32_t>& near) {
    const Tri* faces = created.tris;
    const std::array<vec, 3>* fp = created.points;
    const FloatBox* fb = created.boxes;
    const std::size_t count = created.count;
    // The created faces' planes, made when a pair needs them (a certified
    // collapse seldom has a face to test).
    planes.clear();
    auto need_planes = [&] {
        if (planes.empty())
            for (std::size_t i = 0; i < count; ++i) planes.emplace_back(fp[i].data());
    };
    std::uint32_t link[kMaxLink];
    const std::size_t link_size = created_link(c, created, link);
    const bool local_ok = local_disc_embeds(m, c, created, link, link_size);
    const LinkMarks& in_link = link_marks();  // this collapse's link, as local_disc_embeds() marked it
    if (!local_ok) {
        need_planes();
        for (std::size_t i = 0; i < count; ++i)
            for (std::size_t j = i + 1; j < count; ++j)
                if (boxes_meet(fb[i], fb[j]) && !certainly_apart(planes[i], faces[i], faces[j], fp[j].data()) &&
                    faces_intersect(faces[i], fp[i].data(), faces[j], fp[j].data()))
                    return Verdict::intersection;
    }
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
        if (local_ok && (in_link.has(u[0]) || in_link.has(u[1]) || in_link.has(u[2])))
            continue;  // a face of the certified disc
        const FloatBox& ub = grid.box(id);
        const vec pu[3] = {m.pos[u[0]], m.pos[u[1]], m.pos[u[2]]};
        need_planes();
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
