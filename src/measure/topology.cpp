// Topology of a mesh: boundary, manifoldness, orientation, components.
#include "pqdc/measure.hpp"

#include "measure/measure_common.hpp"
#include "pqdc/exceptions.hpp"

#include <tbb/combinable.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <string>
#include <utility>
#include <vector>

namespace pqdc {

using namespace measure_detail;

namespace {

struct HalfEdge {
    std::uint64_t key;    // (lo << 32) | hi
    std::uint32_t face;
    bool forward;         // traversed lo -> hi
    bool operator<(const HalfEdge& o) const { return key != o.key ? key < o.key : face < o.face; }
};

/// Faces with a repeated index, which everything below leaves out; counts
/// them and the zero-area ones (relative to their size, so rounding in
/// nearly collinear corners still counts) into r. Zero-area faces stay in
/// the combinatorics.
std::vector<char> excluded_faces(const FaceView& faces, TopologyReport& r) {
    const std::size_t nf = faces.size();
    std::vector<char> excluded(nf, 0);
    tbb::combinable<std::size_t> degenerate([] { return std::size_t(0); });
    parallel_indices(nf, [&](std::size_t f) {
        if (faces.has_repeated_vertex(f)) {
            excluded[f] = 1;
            ++degenerate.local();
            return;
        }
        const double area2 = faces.area_vector2(f).length();
        const double side = faces.longest_side(f);
        if (area2 <= 1e-12 * side * side) ++degenerate.local();
    });
    r.degenerate_face_count = degenerate.combine(std::plus<std::size_t>());
    return excluded;
}

/// Undirected edges by sorting half-edges: edge, boundary, inconsistently
/// oriented and non-manifold edge counts into r.
void count_edges(const FaceView& faces, const std::vector<char>& excluded, TopologyReport& r) {
    const std::size_t nf = faces.size();
    std::vector<std::size_t> first_half_edge(nf + 1, 0);
    for (std::size_t f = 0; f < nf; ++f) first_half_edge[f + 1] = first_half_edge[f] + (excluded[f] ? 0 : faces.corners(f));
    std::vector<HalfEdge> half_edges(first_half_edge[nf]);
    parallel_indices(nf, [&](std::size_t f) {
        if (excluded[f]) return;
        const int n = faces.corners(f);
        for (int k = 0; k < n; ++k) {
            const std::uint32_t a = faces.vertex(f, k), b = faces.vertex(f, (k + 1) % n);
            const std::uint32_t lo = std::min(a, b), hi = std::max(a, b);
            half_edges[first_half_edge[f] + std::size_t(k)] =
                HalfEdge{(std::uint64_t(lo) << 32) | hi, std::uint32_t(f), a < b};
        }
    });
    tbb::parallel_sort(half_edges.begin(), half_edges.end());
    for (std::size_t i = 0; i < half_edges.size();) {
        std::size_t j = i + 1;
        while (j < half_edges.size() && half_edges[j].key == half_edges[i].key) ++j;
        const std::size_t uses = j - i;
        ++r.edge_count;
        if (uses == 1) ++r.boundary_edge_count;
        else if (uses == 2 && half_edges[i].forward == half_edges[i + 1].forward) ++r.inconsistent_edge_count;
        else if (uses > 2) ++r.non_manifold_edge_count;
        i = j;
    }
}

/// A face corner as its vertex sees it: the previous and next vertex.
struct Corner {
    std::uint32_t prev, next;
};

/// Corners grouped by vertex: vertex v's are corners[first[v], first[v + 1]).
struct VertexCorners {
    std::vector<std::size_t> first;
    std::vector<Corner> corners;
};

VertexCorners corners_by_vertex(const FaceView& faces, const std::vector<char>& excluded, std::size_t nv) {
    const std::size_t nf = faces.size();
    VertexCorners vc;
    vc.first.assign(nv + 1, 0);
    for (std::size_t f = 0; f < nf; ++f)
        if (!excluded[f])
            for (int k = 0; k < faces.corners(f); ++k) ++vc.first[faces.vertex(f, k) + 1];
    for (std::size_t v = 0; v < nv; ++v) vc.first[v + 1] += vc.first[v];
    vc.corners.resize(vc.first[nv]);
    std::vector<std::size_t> fill(vc.first.begin(), vc.first.end() - 1);
    for (std::size_t f = 0; f < nf; ++f) {
        if (excluded[f]) continue;
        const int n = faces.corners(f);
        for (int k = 0; k < n; ++k)
            vc.corners[fill[faces.vertex(f, k)]++] = Corner{faces.vertex(f, (k + n - 1) % n), faces.vertex(f, (k + 1) % n)};
    }
    return vc;
}

/// Non-manifold and unreferenced vertex counts into r. A vertex is manifold
/// when its faces are connected through the edges they share at the vertex
/// (one fan, open or closed).
void count_vertex_fans(const VertexCorners& vc, std::size_t nv, TopologyReport& r) {
    tbb::combinable<std::size_t> non_manifold_vertices([] { return std::size_t(0); });
    tbb::combinable<std::size_t> unreferenced([] { return std::size_t(0); });
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 2048), [&](const tbb::blocked_range<std::size_t>& range) {
        std::vector<std::pair<std::uint32_t, std::uint32_t>> spokes;  // (other vertex, local face)
        std::vector<std::uint32_t> parent;
        for (std::size_t v = range.begin(); v != range.end(); ++v) {
            const std::size_t b = vc.first[v], e = vc.first[v + 1];
            if (b == e) {
                ++unreferenced.local();
                continue;
            }
            if (e - b == 1) continue;
            spokes.clear();
            for (std::size_t c = b; c < e; ++c) {
                spokes.emplace_back(vc.corners[c].prev, std::uint32_t(c - b));
                spokes.emplace_back(vc.corners[c].next, std::uint32_t(c - b));
            }
            std::sort(spokes.begin(), spokes.end());
            parent.resize(e - b);
            std::iota(parent.begin(), parent.end(), 0u);
            auto find = [&](std::uint32_t x) {
                while (parent[x] != x) x = parent[x] = parent[parent[x]];
                return x;
            };
            std::size_t components = e - b;
            for (std::size_t i = 1; i < spokes.size(); ++i) {
                if (spokes[i].first != spokes[i - 1].first) continue;
                const std::uint32_t x = find(spokes[i].second), y = find(spokes[i - 1].second);
                if (x != y) {
                    parent[std::max(x, y)] = std::min(x, y);
                    --components;
                }
            }
            if (components > 1) ++non_manifold_vertices.local();
        }
    });
    r.non_manifold_vertex_count = non_manifold_vertices.combine(std::plus<std::size_t>());
    r.unreferenced_vertex_count = unreferenced.combine(std::plus<std::size_t>());
}

/// Connected components (through shared vertices) and the Euler
/// characteristic of the referenced vertices, the edges and the used faces.
void count_components(const FaceView& faces, const std::vector<char>& excluded, const VertexCorners& vc,
                      std::size_t nv, TopologyReport& r) {
    UnionFind components(nv);
    std::size_t used_faces = 0;
    for (std::size_t f = 0; f < faces.size(); ++f) {
        if (excluded[f]) continue;
        ++used_faces;
        for (int k = 1; k < faces.corners(f); ++k) components.unite(faces.vertex(f, 0), faces.vertex(f, k));
    }
    for (std::size_t v = 0; v < nv; ++v)
        if (vc.first[v] != vc.first[v + 1] && components.find(std::uint32_t(v)) == v) ++r.connected_component_count;
    r.euler_characteristic = static_cast<long long>(nv - r.unreferenced_vertex_count) -
                             static_cast<long long>(r.edge_count) + static_cast<long long>(used_faces);
}

}  // namespace

TopologyReport measure_topology(const Mesh& mesh) {
    check_indices(mesh);
    TopologyReport r;
    const FaceView faces(mesh);
    const std::size_t nv = mesh.points.size();
    r.vertex_count = nv;
    r.triangle_count = mesh.triangles.size();
    r.quad_count = mesh.quads.size();
    for (const Vec3d& p : mesh.points)
        if (!finite(p)) ++r.non_finite_point_count;
    const std::vector<char> excluded = excluded_faces(faces, r);
    count_edges(faces, excluded, r);
    const VertexCorners corners = corners_by_vertex(faces, excluded, nv);
    count_vertex_fans(corners, nv, r);
    count_components(faces, excluded, corners, nv, r);
    return r;
}

}  // namespace pqdc
