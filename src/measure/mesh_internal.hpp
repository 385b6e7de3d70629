// Internal helpers shared by the mesh measures (src/measure.cpp,
// src/measure/*.cpp): the triangle numbering of meshes with quads, index
// checks, union-find and the bounding-box tree over triangles. Not installed.
#pragma once

#include "pqdc/exceptions.hpp"
#include "pqdc/mesh.hpp"
#include "pqdc/self_intersections.hpp"

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <numeric>
#include <string>
#include <utility>
#include <vector>

namespace pqdc {
namespace detail {

using Vec3d = openvdb::Vec3d;

/// The mesh as triangles 0..T-1, T = triangles + 2 quads: the triangles,
/// then each quad as 0-1-2 and 0-2-3. Triangle-based measures number them so.
inline std::size_t split_triangle_count(const Mesh& mesh) { return mesh.triangles.size() + 2 * mesh.quads.size(); }
inline std::array<unsigned, 3> split_triangle(const Mesh& mesh, std::size_t t) {
    const std::size_t ntri = mesh.triangles.size();
    if (t < ntri) return {mesh.triangles[t][0], mesh.triangles[t][1], mesh.triangles[t][2]};
    const auto& q = mesh.quads[(t - ntri) / 2];
    if ((t - ntri) % 2 == 0) return {q[0], q[1], q[2]};
    return {q[0], q[2], q[3]};
}

/// find_self_intersections of the mesh's faces on `points` in place of its
/// own (the same count): the check at another precision (the untangle
/// stage's float rounding) without copying the faces.
SelfIntersections find_self_intersections_at(const Mesh& mesh, const std::vector<Vec3d>& points,
                                             const SelfIntersectionOptions& options);

/// The split triangles `ids` of `mesh` as a mesh of their own: each corner
/// used becomes one point, point(v) for mesh point v, in order of first use.
/// `remap` (one entry per mesh point, all UINT32_MAX) is used and left as it
/// was found, so a caller checking many subsets allocates it once.
template <class Point>
Mesh split_triangles_mesh(const Mesh& mesh, const std::vector<std::uint32_t>& ids, const Point& point,
                          std::vector<std::uint32_t>& remap) {
    constexpr std::uint32_t kUnused = std::numeric_limits<std::uint32_t>::max();
    Mesh sub;
    std::vector<std::uint32_t> used;
    sub.triangles.reserve(ids.size());
    for (std::uint32_t t : ids) {
        const std::array<unsigned, 3> c = split_triangle(mesh, t);
        openvdb::Vec3I s;
        for (int k = 0; k < 3; ++k) {
            std::uint32_t& r = remap[c[k]];
            if (r == kUnused) {
                r = std::uint32_t(sub.points.size());
                sub.points.push_back(point(c[k]));
                used.push_back(c[k]);
            }
            s[k] = r;
        }
        sub.triangles.push_back(s);
    }
    for (std::uint32_t v : used) remap[v] = kUnused;
    return sub;
}

/// find_self_intersections' cancellation point: throws cancelled_error when
/// options.progress returns false for `fraction` done.
inline void report_progress(const SelfIntersectionOptions& options, double fraction) {
    if (options.progress && !options.progress(fraction))
        throw cancelled_error("self-intersection search cancelled by the caller");
}

/// The pieces of find_self_intersections for callers that find candidate
/// pairs otherwise (uniform/quad_star_check.cpp): how the finder classifies
/// split triangle t (0 usable, 1 degenerate, 2 non-finite: see
/// SelfIntersections), and its exact test of two usable triangles s != t.
int classify_split_triangle(const Mesh& mesh, const std::vector<Vec3d>& points, std::size_t t);
bool split_triangles_intersect(const Mesh& mesh, const std::vector<Vec3d>& points, std::size_t s, std::size_t t);
/// split_triangles_intersect of every pair of the usable split triangles
/// `ids` (ascending), each triangle prepared once: the pairs that meet,
/// appended to `pairs` in (first, second) order of `ids`.
void intersecting_pairs_among(const Mesh& mesh, const std::vector<Vec3d>& points,
                              const std::vector<std::uint32_t>& ids,
                              std::vector<std::pair<std::size_t, std::size_t>>& pairs);

/// Triangles per part of the grid broad phase (see grid_pairs in
/// self_intersections.cpp): bounds the grid's arrays on large meshes.
constexpr std::size_t kGridPartTriangles = std::size_t(1) << 20;

/// The same with parts of `part_triangles` (>= 1) triangles: the result does
/// not depend on it (the tests vary it). `parts_used`, when given, is set to
/// the number of parts the grid ran in (1 when the mesh's order made parts
/// pointless, 0 when the tree ran).
SelfIntersections find_self_intersections_at(const Mesh& mesh, const std::vector<Vec3d>& points,
                                             const SelfIntersectionOptions& options, std::size_t part_triangles,
                                             std::size_t* parts_used = nullptr);

/// `what` names the mesh in the message ("mesh", "reference mesh").
inline void check_indices(const Mesh& mesh, const char* what = "mesh") {
    const std::size_t n = mesh.points.size();
    // The largest index first, in one loop over the flat arrays that the
    // compiler vectorizes; only a mesh that fails is searched for its face.
    static_assert(sizeof(openvdb::Vec3I) == 3 * sizeof(unsigned) && sizeof(openvdb::Vec4I) == 4 * sizeof(unsigned),
                  "faces are packed index arrays");
    unsigned largest = 0;
    const unsigned* t = mesh.triangles.empty() ? nullptr : mesh.triangles[0].asPointer();
    for (std::size_t i = 0; i < 3 * mesh.triangles.size(); ++i) largest = std::max(largest, t[i]);
    const unsigned* q = mesh.quads.empty() ? nullptr : mesh.quads[0].asPointer();
    for (std::size_t i = 0; i < 4 * mesh.quads.size(); ++i) largest = std::max(largest, q[i]);
    if (largest < n || (mesh.triangles.empty() && mesh.quads.empty())) return;
    auto check = [&](std::size_t f, unsigned v) {
        if (v >= n)
            throw input_error(std::string(what) + " face " + std::to_string(f) + " refers to vertex " +
                              std::to_string(v) + " but the mesh has only " + std::to_string(n) + " points");
    };
    for (std::size_t f = 0; f < mesh.triangles.size(); ++f)
        for (int k = 0; k < 3; ++k) check(f, mesh.triangles[f][k]);
    for (std::size_t q = 0; q < mesh.quads.size(); ++q)
        for (int k = 0; k < 4; ++k) check(mesh.triangles.size() + q, mesh.quads[q][k]);
}

struct UnionFind {
    std::vector<std::uint32_t> parent;
    explicit UnionFind(std::size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0u); }
    std::uint32_t find(std::uint32_t x) {
        while (parent[x] != x) {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        return x;
    }
    void unite(std::uint32_t a, std::uint32_t b) {
        a = find(a);
        b = find(b);
        if (a == b) return;
        if (a < b) std::swap(a, b);
        parent[a] = b;  // smaller root wins: structure independent of call order details
    }
};

/// A node of the bounding-box hierarchy. Interior nodes' first child is the
/// next node in the array.
struct BoxNode {
    Vec3d lo, hi;
    std::uint32_t second_child_or_first_triangle;
    std::uint32_t triangle_count;  // 0 for interior nodes
};

/// Median splits along the longest axis of the triangles' box centers.
/// Serial, so the tree (and the order of equal-distance candidates) is the
/// same for any thread count.
class BoxTreeBuilder {
public:
    BoxTreeBuilder(const std::vector<std::array<Vec3d, 3>>& corners, int leaf_triangles)
        : corners_(corners), leaf_(std::size_t(leaf_triangles)), order_(corners.size()), centers_(corners.size()) {
        std::iota(order_.begin(), order_.end(), 0u);
        for (std::size_t t = 0; t < corners.size(); ++t) {
            Vec3d lo, hi;
            bounds(corners[t], lo, hi);
            centers_[t] = (lo + hi) * 0.5;
        }
    }

    /// Fills nodes; order()[i] is then the triangle id at leaf position i.
    void build(std::vector<BoxNode>& nodes) {
        nodes.clear();
        nodes.reserve(2 * (corners_.size() / leaf_ + 1));
        build(nodes, 0, corners_.size());
    }
    const std::vector<std::uint32_t>& order() const { return order_; }

private:
    static void bounds(const std::array<Vec3d, 3>& c, Vec3d& lo, Vec3d& hi) {
        lo = hi = c[0];
        for (int i = 1; i < 3; ++i)
            for (int k = 0; k < 3; ++k) {
                lo[k] = std::min(lo[k], c[i][k]);
                hi[k] = std::max(hi[k], c[i][k]);
            }
    }

    std::uint32_t build(std::vector<BoxNode>& nodes, std::size_t begin, std::size_t end) {
        const std::uint32_t index = std::uint32_t(nodes.size());
        nodes.emplace_back();
        Vec3d lo, hi, center_lo = centers_[order_[begin]], center_hi = center_lo;
        bounds(corners_[order_[begin]], lo, hi);
        for (std::size_t i = begin; i < end; ++i) {
            Vec3d tlo, thi;
            bounds(corners_[order_[i]], tlo, thi);
            const Vec3d& c = centers_[order_[i]];
            for (int k = 0; k < 3; ++k) {
                lo[k] = std::min(lo[k], tlo[k]);
                hi[k] = std::max(hi[k], thi[k]);
                center_lo[k] = std::min(center_lo[k], c[k]);
                center_hi[k] = std::max(center_hi[k], c[k]);
            }
        }
        nodes[index].lo = lo;
        nodes[index].hi = hi;
        if (end - begin <= leaf_) {
            nodes[index].second_child_or_first_triangle = std::uint32_t(begin);
            nodes[index].triangle_count = std::uint32_t(end - begin);
            return index;
        }
        const Vec3d extent = center_hi - center_lo;
        const int axis = extent[0] >= extent[1] ? (extent[0] >= extent[2] ? 0 : 2) : (extent[1] >= extent[2] ? 1 : 2);
        const std::size_t mid = begin + (end - begin) / 2;
        // Ties broken by id: a strict total order, so the split is reproducible.
        std::nth_element(order_.begin() + std::ptrdiff_t(begin), order_.begin() + std::ptrdiff_t(mid),
                         order_.begin() + std::ptrdiff_t(end), [&](std::uint32_t a, std::uint32_t b) {
                             const double ca = centers_[a][axis], cb = centers_[b][axis];
                             return ca < cb || (ca == cb && a < b);
                         });
        build(nodes, begin, mid);
        const std::uint32_t second = build(nodes, mid, end);
        nodes[index].second_child_or_first_triangle = second;
        nodes[index].triangle_count = 0;
        return index;
    }

    const std::vector<std::array<Vec3d, 3>>& corners_;
    std::size_t leaf_;
    std::vector<std::uint32_t> order_;
    std::vector<Vec3d> centers_;
};

}  // namespace detail
}  // namespace pqdc
