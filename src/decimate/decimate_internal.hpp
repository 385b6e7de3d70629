// Shared state of the decimation stages (internal to src/decimate/).
// The working mesh keeps world-space positions (the exact intersection
// tests run on the coordinates that are written out) and per-vertex
// quadrics in local voxel units (relative to the input's centre, divided by
// the voxel size), where the sigmas are stated and doubles keep their digits.
#pragma once

#include "pqdc/decimate.hpp"
#include "pqdc/measure.hpp"
#include "pqdc/quadric.hpp"

#include "exact_predicates.hpp"
#include "geometry/float_rounding.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <limits>
#include <memory>
#include <utility>
#include <vector>

namespace pqdc::decimate_detail {

using vec = vec3<double>;
using Quadric = quadric<double>;
using Tri = std::array<std::uint32_t, 3>;

/// Algebraic sphere S(x) = u0 + u . x + u4 |x|^2 (local voxel units), the
/// curvature metric's per-vertex primitive; a plane when u4 == 0.
struct Sphere {
    double u0 = 0;
    vec u{};
    double u4 = 0;
    double operator()(const vec& x) const { return u0 + dot(u, x) + u4 * dot(x, x); }
    Sphere lerp(const Sphere& o, double t) const {
        return {u0 + (o.u0 - u0) * t, u + (o.u - u) * t, u4 + (o.u4 - u4) * t};
    }
};

struct WorkMesh {
    std::vector<vec> pos;                ///< world space
    std::vector<Quadric> quadrics;       ///< local voxel units
    std::vector<Sphere> spheres;         ///< curvature metric only
    std::vector<std::uint8_t> locked;    ///< 1: never moves, never removed
    /// For the normal transfer only (else empty): the vertex each removed
    /// vertex merged into (b -> a), max() while alive.
    std::vector<std::uint32_t> merged_into;
    std::vector<Tri> tris;               ///< live triangles
    /// Vertex -> incident triangles (CSR), rebuilt each pass.
    std::vector<std::uint32_t> fan_begin, fan;
    vec origin{};
    double voxel = 1;
    /// DecimateOptions::stored_precision is float32: every position is a
    /// float (the input's rounded, each collapse's rounded before it is
    /// checked), so the checks see the coordinates the file will hold.
    bool float_positions = false;

    vec local(const vec& world) const { return (world - origin) / voxel; }
    vec world(const vec& local_point) const { return origin + local_point * voxel; }
    std::size_t fan_size(std::uint32_t v) const { return fan_begin[v + 1] - fan_begin[v]; }
    const std::uint32_t* fan_of(std::uint32_t v) const { return fan.data() + fan_begin[v]; }
};

/// One candidate collapse: b merges into a (a < b), which moves to x.
struct Candidate {
    std::uint32_t a = 0, b = 0;
    vec x{};       ///< world space
    double cost = 0;
};

enum class Verdict : std::uint8_t { ok, link, flip, quality, intersection, distance };

struct CheckLimits {
    double min_cos_normal_change = 0;
    double min_quality = 0;
    double max_distance = 0;  ///< world units; 0 = none
    const MeshDistance* input_surface = nullptr;
};

// quadrics.cpp
/// Unit area-weighted normal of v's fan (zero when the fan has no area).
vec vertex_normal(const WorkMesh& m, std::uint32_t v);
void build_vertex_quadrics(WorkMesh& m, const DecimateOptions& o);
void build_vertex_spheres(WorkMesh& m);
/// Minimizer (curvature: best point on the edge) and cost of merging b into
/// a; the position rounded to float when m.float_positions.
Candidate evaluate_collapse(const WorkMesh& m, std::uint32_t a, std::uint32_t b, DecimateMetric metric);

// noise_estimate.cpp
/// Standard deviation of the movable vertices' noise along their normals,
/// voxels, from their offsets to their one-rings' centroids (0 without any).
double estimate_vertex_noise_voxels(const WorkMesh& m);
/// sigma_position_voxels for sigma_position_auto, from that estimate.
double sigma_position_for_noise(double noise_voxels);

// triangle_grid.cpp
using BoxPair = std::array<vec, 2>;  ///< lo, hi
inline bool boxes_meet(const BoxPair& p, const BoxPair& q) {
    return p[0].x <= q[1].x && q[0].x <= p[1].x && p[0].y <= q[1].y && q[0].y <= p[1].y && p[0].z <= q[1].z &&
           q[0].z <= p[1].z;
}
inline vec component_min(const vec& p, const vec& q) {
    return {std::min(p.x, q.x), std::min(p.y, q.y), std::min(p.z, q.z)};
}
inline vec component_max(const vec& p, const vec& q) {
    return {std::max(p.x, q.x), std::max(p.y, q.y), std::max(p.z, q.z)};
}
inline BoxPair triangle_box(const vec& p, const vec& q, const vec& r) {
    return {component_min(component_min(p, q), r), component_max(component_max(p, q), r)};
}
/// A box in float, rounded outwards: it contains the double box it was made
/// from. The per-face boxes (of the live faces and of the created ones) are
/// only filters in front of exact tests, so a box larger by a float rounding
/// changes no verdict, and it takes 24 bytes instead of 48.
struct FloatBox {
    float lo[3], hi[3];
};
/// A float at most v and one at least v (v finite), at most one float step
/// from it: the nearest float, or its neighbour when rounding went up
/// (moved through the bits, which read as an integer of the float's sign
/// are ordered as its magnitude; -0 steps to the negative subnormal).
/// Without branches: the rounding direction is a coin toss.
inline float float_below(double v) {
    const float f = detail::nearest_float(v);
    std::int32_t bits;
    std::memcpy(&bits, &f, sizeof bits);
    const std::int32_t up = double(f) > v;
    bits += bits < 0 ? up : -up;
    float g;
    std::memcpy(&g, &bits, sizeof g);
    return g;
}
inline float float_above(double v) { return -float_below(-v); }
inline FloatBox float_box(const BoxPair& b) {
    return {{float_below(b[0].x), float_below(b[0].y), float_below(b[0].z)},
            {float_above(b[1].x), float_above(b[1].y), float_above(b[1].z)}};
}
inline bool boxes_meet(const FloatBox& p, const FloatBox& q) {
    return p.lo[0] <= q.hi[0] && q.lo[0] <= p.hi[0] && p.lo[1] <= q.hi[1] && q.lo[1] <= p.hi[1] &&
           p.lo[2] <= q.hi[2] && q.lo[2] <= p.hi[2];
}
inline bool boxes_meet(const FloatBox& p, const BoxPair& q) {
    return p.lo[0] <= q[1].x && q[0].x <= p.hi[0] && p.lo[1] <= q[1].y && q[0].y <= p.hi[1] && p.lo[2] <= q[1].z &&
           q[0].z <= p.hi[2];
}
/// f(begin, end) over [0, n) in parallel chunks of about `grain`.
template <class F>
void parallel_ranges(std::size_t n, std::size_t grain, F&& f) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, grain), [&](const auto& r) { f(r.begin(), r.end()); });
}
/// Bounding boxes of the triangles, into `boxes` (resized).
void triangle_boxes(const std::vector<vec>& pos, const std::vector<Tri>& tris, std::vector<FloatBox>& boxes);
/// Loose multi-level grid over boxes for local box queries (see
/// triangle_grid.cpp). Built again each pass; its buffers are reused.
class TriangleGrid {
public:
    /// Takes the boxes by swapping with `boxes` (which gets what the grid
    /// held: nothing after take_boxes()).
    void build(std::vector<FloatBox>& boxes);
    /// The last build's boxes, handed back so that the next build's boxes
    /// fill the same buffer (one array of boxes alive instead of two). The
    /// grid answers no query until it is built again.
    std::vector<FloatBox> take_boxes() { return std::move(boxes_); }
    const FloatBox& box(std::uint32_t id) const { return boxes_[id]; }
    /// Ids of the boxes that meet the box lo-hi rounded outwards to float,
    /// each once, in grid order: every box whose double original meets
    /// lo-hi, and possibly a few within a float rounding of it.
    void query(const vec& lo, const vec& hi, std::vector<std::uint32_t>& out) const;

private:
    struct Level {
        double inv_h = 1;
        std::uint32_t nx = 1, ny = 1, nz = 1;
        std::vector<std::uint32_t> row_begin;  ///< (x, y) row -> first entry; nx * ny + 2 (the last unused)
        std::vector<std::uint32_t> z, id;      ///< entries sorted by (row, z, id)
        std::uint32_t cell(double v, double lo, std::uint32_t n) const {
            const double c = std::floor((v - lo) * inv_h);
            return c >= 0 ? std::uint32_t(std::min(c, double(n - 1))) : 0u;  // NaN -> 0
        }
        bool fits(const FloatBox& b, const vec& lo) const;
    };
    void fill_levels();
    void sort_rows_by_z(Level& level);
    std::vector<Level> levels_;          ///< every candidate level, kept for their buffers
    std::vector<std::uint8_t> active_;   ///< the levels that list boxes, finest first
    std::vector<FloatBox> boxes_;
    vec lo_{};
    std::vector<double> scratch_extent_;
    std::vector<std::uint8_t> scratch_level_;
    std::vector<std::uint32_t> scratch_row_, scratch_z_;
    std::vector<std::uint64_t> scratch_keys_;
};

// collapse_checks.cpp
/// Link condition and valence (cheap, topology only).
bool link_condition_holds(const WorkMesh& m, std::uint32_t a, std::uint32_t b);
/// Normal change and triangle quality of the faces around a and b after the collapse.
Verdict check_shape(const WorkMesh& m, const Candidate& c, const CheckLimits& lim);
/// The faces one collapse creates (ids with a standing for the moved
/// vertex, corner positions, boxes), a view into PassBuffers.
struct CreatedFaces {
    const Tri* tris = nullptr;
    const std::array<vec, 3>* points = nullptr;
    const FloatBox* boxes = nullptr;
    std::size_t count = 0;
    BoxPair all{};  ///< the box of all of them
};
/// Number of faces write_created_faces() gives for a collapse that passed the link
/// condition: the fans of a and b without the two faces they share.
inline std::size_t created_face_count(const WorkMesh& m, const Candidate& c) {
    return m.fan_size(c.a) + m.fan_size(c.b) - 4;
}
/// Writes the created faces of c into tris/points/boxes (created_face_count
/// entries each) and returns the box of all of them.
BoxPair write_created_faces(const WorkMesh& m, const Candidate& c, Tri* tris, std::array<vec, 3>* points,
                            FloatBox* boxes);
/// Whether the triangle u (ids, positions) lies certainly strictly on one
/// side of the plane of the face with ids t, apart from the vertices they
/// share: then they cannot meet beyond what they share (a cheap filter in
/// front of faces_intersect; false = undecided).
template <class PlaneFilter>
[[gnu::always_inline]] inline bool certainly_apart(const PlaneFilter& plane, const Tri& t, const Tri& u, const vec pu[3]) {
    int side = 0;
    for (int k = 0; k < 3; ++k) {
        if (u[k] == t[0] || u[k] == t[1] || u[k] == t[2]) continue;
        const int s = plane.side(pu[k]);
        if (s == 0 || (side != 0 && s != side)) return false;
        side = s;
    }
    return side != 0;
}
/// The link of the collapse (the new vertex's neighbours, in fan order),
/// read from its created faces; at most kMaxLink of them.
constexpr std::size_t kMaxLink = 128;
std::size_t created_link(const Candidate& c, const CreatedFaces& created, std::uint32_t* link);
/// Whether the local disc of a collapse, D = the created faces and every
/// other face at the link vertices (the faces the new vertex's link touches
/// after the collapse), is certainly free of intersections: projected onto
/// one coordinate plane, every face of D keeps one orientation and D's
/// outer boundary is star-shaped around the new vertex, winding once
/// (collapse_checks.cpp gives the argument). Exact (2D signs of input
/// coordinates); false = not certified, test pair by pair.
bool local_disc_embeds(const WorkMesh& m, const Candidate& c, const CreatedFaces& created, const std::uint32_t* link,
                       std::size_t link_size);
/// Exact test of the new faces against every live triangle near them and
/// each other; then the distance limit. Pairs inside the local disc are
/// skipped when local_disc_embeds() certifies it (the verdict is the same).
/// `planes` and `near` are the caller's buffers (one per worker chunk).
Verdict check_intersection_and_distance(const WorkMesh& m, const TriangleGrid& grid, const Candidate& c,
                                        const CreatedFaces& created, const CheckLimits& lim,
                                        std::vector<exact::plane_filter>& planes, std::vector<std::uint32_t>& near);
/// Whether triangle t (positions pt) and u (pu) meet beyond shared vertex ids.
bool faces_intersect(const Tri& t, const vec pt[3], const Tri& u, const vec pu[3]);

// transfer_normals.cpp
/// Unit normals for `points`, the output (point i is input vertex v with
/// output_index[v] == i), from input.normals (one per input point): the
/// input normal where the point did not move, else the input normals
/// interpolated at the nearest point of the input triangles around its
/// cluster (the input vertices merged into it: merged_into[b] = a per
/// collapse, kNone-free entries only), normalized.
std::vector<openvdb::Vec3d> transfer_vertex_normals(const Mesh& input, const std::vector<Tri>& input_tris,
                                                    const std::vector<std::uint32_t>& merged_into,
                                                    const std::vector<std::uint32_t>& output_index,
                                                    const std::vector<openvdb::Vec3d>& points);

// pass_scheduler.cpp
struct PassResult {
    std::size_t collapses = 0;
    std::size_t rejected[6] = {};
};
/// Working memory of the passes, kept from one pass to the next: fresh
/// buffers each pass cost about a fifth of the run in page faults.
struct PassBuffers {
    std::vector<std::array<std::uint32_t, 2>> edges;
    std::vector<std::uint64_t> order, order_tmp;  ///< (float cost bits << 32 | edge)
    std::vector<std::array<std::uint32_t, 2>> ends;  ///< the edges of order's prefix, in that order
    std::vector<std::uint32_t> free_list;            ///< a block's candidates free at its start
    std::vector<std::uint8_t> busy;
    std::vector<Verdict> block_verdict;
    std::vector<std::uint8_t> block_known;   ///< block_verdict is set
    std::vector<Candidate> block_candidate;  ///< where block_verdict is set
    std::vector<std::uint32_t> want, marked;  ///< a block's tentative picks and the locks they set
    std::vector<Candidate> accepted;       ///< selected in cost order, then kept in vertex (space) order
    std::vector<std::uint32_t> rank;       ///< accepted[k]'s position in cost order
    std::vector<Candidate> scratch;
    std::vector<Verdict> verdict;
    // Created faces of the accepted collapses, CSR by accepted index.
    std::vector<std::uint32_t> created_begin;
    std::vector<Tri> created_tris;
    std::vector<std::array<vec, 3>> created_points;
    std::vector<FloatBox> created_boxes;
    /// The faces grid's boxes (and its previous build's, swapped back), and
    /// the created grid's own, one per collapse: sharing one buffer passed
    /// a faces-sized one on to the created grid, three of them alive.
    std::vector<FloatBox> boxes, collapse_boxes;
    std::vector<BoxPair> created_all;
    TriangleGrid faces_grid, created_grid;
    std::vector<std::uint8_t> conflict;
};
/// One pass: cost every collapsible edge, pick an independent set of the
/// cheapest, check them, apply the survivors. Deterministic. A pass looks at
/// candidates up to 1.5x the cost of the goal-th cheapest, or at all of them
/// when `unlimited` (after a pass whose cheap candidates were all refused).
/// `checkpoint(share, planned)` is called from the calling thread between
/// its stages and inside its long ones (the selection's walk, the mesh and
/// conflict checks, in slices), with the share of the pass's work done so
/// far (in [0, 1], by the stages' typical cost) and the collapses the pass
/// plans (0 until the selection has chosen them). The mesh is as it was at
/// the pass's start; it may throw to cancel.
using PassCheckpoint = std::function<void(double share, std::size_t planned_collapses)>;
PassResult run_pass(WorkMesh& m, const DecimateOptions& o, const CheckLimits& lim, std::size_t target_faces,
                    bool unlimited, PassBuffers& buffers, const PassCheckpoint& checkpoint);
/// Vertex -> incident triangles as CSR lists (fan[begin[v] .. begin[v + 1]),
/// ascending triangle ids), for `vertices` vertices.
void build_fans(const std::vector<Tri>& tris, std::size_t vertices, std::vector<std::uint32_t>& begin,
                std::vector<std::uint32_t>& fan);
/// m.fan_begin and m.fan from m.tris.
void rebuild_fans(WorkMesh& m);

}  // namespace pqdc::decimate_detail
