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

#include <array>
#include <cstdint>
#include <memory>
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
    std::vector<Tri> tris;               ///< live triangles
    /// Vertex -> incident triangles (CSR), rebuilt each pass.
    std::vector<std::uint32_t> fan_begin, fan;
    vec origin{};
    double voxel = 1;

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
/// Minimizer (curvature: best point on the edge) and cost of merging b into a.
Candidate evaluate_collapse(const WorkMesh& m, std::uint32_t a, std::uint32_t b, DecimateMetric metric);

// noise_estimate.cpp
/// Standard deviation of the movable vertices' noise along their normals,
/// voxels, from their offsets to their one-rings' centroids (0 without any).
double estimate_vertex_noise_voxels(const WorkMesh& m);
/// sigma_position_voxels for sigma_position_auto, from that estimate.
double sigma_position_for_noise(double noise_voxels);

// collapse_checks.cpp
/// Uniform grid over the live triangles' bounding boxes for local queries.
using BoxPair = std::array<vec, 2>;  ///< lo, hi
inline bool boxes_meet(const BoxPair& p, const BoxPair& q) {
    return p[0].x <= q[1].x && q[0].x <= p[1].x && p[0].y <= q[1].y && q[0].y <= p[1].y && p[0].z <= q[1].z &&
           q[0].z <= p[1].z;
}
std::vector<BoxPair> triangle_boxes(const std::vector<vec>& pos, const std::vector<Tri>& tris);
class TriangleGrid {
public:
    explicit TriangleGrid(std::vector<BoxPair> boxes);
    const BoxPair& box(std::uint32_t id) const { return boxes_[id]; }
    /// Ids of the triangles whose boxes meet the box lo-hi (no repeats, in
    /// no particular order).
    void query(const vec& lo, const vec& hi, std::vector<std::uint32_t>& out) const;

private:
    struct Entry {
        std::uint64_t cell;
        std::uint64_t first_cell;  ///< the cell of the face box's lowest corner
        std::uint32_t id;
    };
    std::uint64_t key(const vec& p) const;
    std::uint64_t bucket(std::uint64_t cell) const;
    std::vector<Entry> entries_;
    /// entries_ grouped by bucket(cell): bucket b is
    /// [bucket_begin_[b], bucket_begin_[b + 1]).
    std::vector<std::uint32_t> bucket_begin_;
    std::uint64_t mask_ = 0;
    bool dense_ = false;
    std::array<std::uint64_t, 3> dims_{};
    std::size_t ids_ = 0;
    std::vector<BoxPair> boxes_;
    std::vector<std::uint32_t> oversize_;  ///< faces in too many cells: returned by every query
    vec lo_{};
    double inv_h_ = 1;
};

/// Link condition and valence (cheap, topology only).
bool link_condition_holds(const WorkMesh& m, std::uint32_t a, std::uint32_t b);
/// Normal change and triangle quality of the faces around a and b after the collapse.
Verdict check_shape(const WorkMesh& m, const Candidate& c, const CheckLimits& lim);
/// Buffers of check_intersection_and_distance, one per worker chunk (no
/// allocation per collapse, no thread_local lookups in the shared library).
struct CheckScratch {
    std::vector<exact::plane_filter> planes;
    std::vector<Tri> faces;
    std::vector<std::uint32_t> near;
    std::vector<std::array<vec, 3>> fp;
    std::vector<BoxPair> fb;
};
/// Whether the triangle u (ids, positions) lies certainly strictly on one
/// side of the plane of the face with ids t, apart from the vertices they
/// share: then they cannot meet beyond what they share (a cheap filter in
/// front of faces_intersect; false = undecided).
template <class PlaneFilter>
bool certainly_apart(const PlaneFilter& plane, const Tri& t, const Tri& u, const vec pu[3]) {
    int side = 0;
    for (int k = 0; k < 3; ++k) {
        if (u[k] == t[0] || u[k] == t[1] || u[k] == t[2]) continue;
        const int s = plane.side(pu[k]);
        if (s == 0 || (side != 0 && s != side)) return false;
        side = s;
    }
    return side != 0;
}
/// Exact test of the new faces against every live triangle near them and
/// each other; then the distance limit.
Verdict check_intersection_and_distance(const WorkMesh& m, const TriangleGrid& grid, const Candidate& c,
                                        const CheckLimits& lim, CheckScratch& scratch);
/// The faces the collapse creates, with a standing for x.
void new_faces(const WorkMesh& m, const Candidate& c, std::vector<Tri>& out);
/// Whether triangle t (positions pt) and u (pu) meet beyond shared vertex ids.
bool faces_intersect(const Tri& t, const vec pt[3], const Tri& u, const vec pu[3]);

// pass_scheduler.cpp
struct PassResult {
    std::size_t collapses = 0;
    std::size_t rejected[6] = {};
};
/// One pass: cost every collapsible edge, pick an independent set of the
/// cheapest, check them, apply the survivors. Deterministic. A pass looks at
/// candidates up to 1.5x the cost of the goal-th cheapest, or at all of them
/// when `unlimited` (after a pass whose cheap candidates were all refused).
PassResult run_pass(WorkMesh& m, const DecimateOptions& o, const CheckLimits& lim, std::size_t target_faces,
                    bool unlimited);
void rebuild_fans(WorkMesh& m);

}  // namespace pqdc::decimate_detail
