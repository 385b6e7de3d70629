#include "adaptive/repair.hpp"

#include <tbb/parallel_sort.h>

#include <algorithm>
#include <numeric>
#include <unordered_map>

namespace pqdc::adaptive_detail {

void separate_coincident_vertices(Mesh& mesh, AdaptiveStats& stats, const detail::ProgressSpan& span) {
    using openvdb::Vec3d;
    const std::size_t n = mesh.points.size();
    std::vector<std::uint32_t> order(n);
    std::iota(order.begin(), order.end(), 0u);
    auto less = [&](std::uint32_t a, std::uint32_t b) {
        const Vec3d &p = mesh.points[a], &q = mesh.points[b];
        if (p.x() != q.x()) return p.x() < q.x();
        if (p.y() != q.y()) return p.y() < q.y();
        if (p.z() != q.z()) return p.z() < q.z();
        return a < b;
    };
    tbb::parallel_sort(order.begin(), order.end(), less);
    span.report(0.5);
    std::vector<std::uint32_t> moving;
    for (std::size_t i = 1; i < n; ++i)
        if (mesh.points[order[i]] == mesh.points[order[i - 1]]) moving.push_back(order[i]);
    if (moving.empty()) return;
    std::sort(moving.begin(), moving.end());
    std::vector<Vec3d> sum(moving.size(), Vec3d(0.0));
    std::vector<int> count(moving.size(), 0);
    auto visit = [&](const std::uint32_t* f, int k) {
        for (int i = 0; i < k; ++i) {
            const auto it = std::lower_bound(moving.begin(), moving.end(), f[i]);
            if (it == moving.end() || *it != f[i]) continue;
            const std::size_t m = std::size_t(it - moving.begin());
            for (int j = 0; j < k; ++j)
                if (mesh.points[f[j]] != mesh.points[f[i]]) {
                    sum[m] += mesh.points[f[j]];
                    ++count[m];
                }
        }
    };
    for_each_face(mesh, visit);
    for (std::size_t m = 0; m < moving.size(); ++m) {
        if (!count[m]) continue;
        Vec3d& p = mesh.points[moving[m]];
        p += (sum[m] / double(count[m]) - p) * 1e-4;
        ++stats.separated_vertices;
    }
}

void flip_collinear_triangles(const std::vector<openvdb::Vec3d>& points, std::vector<openvdb::Vec3I>& tris,
                              const std::vector<std::uint8_t>& alive, std::vector<std::uint8_t>& changed) {
    auto flat = [&](const openvdb::Vec3I& t) {
        const openvdb::Vec3d &a = points[t[0]], &b = points[t[1]], &c = points[t[2]];
        const double side2 = std::max({(b - a).lengthSqr(), (c - b).lengthSqr(), (a - c).lengthSqr()});
        return (b - a).cross(c - a).length() <= 1e-10 * side2;
    };
    std::vector<std::uint32_t> bad;
    for (std::uint32_t t = 0; t < tris.size(); ++t)
        if (alive[t] && flat(tris[t])) bad.push_back(t);
    changed.assign(tris.size(), 0);
    if (bad.empty()) return;
    // Directed edge -> triangle, for the triangles around the flat ones
    // (all a flip looks at: the neighbour across an edge of a flat triangle
    // and the edges at its vertices).
    std::vector<std::uint8_t> near(points.size(), 0);
    for (std::uint32_t t : bad)
        for (int k = 0; k < 3; ++k) near[tris[t][k]] = 1;
    std::unordered_map<std::uint64_t, std::uint32_t> owner;
    auto directed = [](std::uint32_t a, std::uint32_t b) { return std::uint64_t(a) << 32 | b; };
    for (std::uint32_t t = 0; t < tris.size(); ++t)
        if (alive[t] && (near[tris[t][0]] || near[tris[t][1]] || near[tris[t][2]]))
            for (int k = 0; k < 3; ++k) owner[directed(tris[t][k], tris[t][(k + 1) % 3])] = t;
    for (int pass = 0; pass < 3 && !bad.empty(); ++pass) {
        std::vector<std::uint32_t> left;
        for (std::uint32_t t : bad) {
            if (!flat(tris[t])) continue;
            // Rotate so that the longest edge is c -> a.
            openvdb::Vec3I v = tris[t];
            int k = 0;
            double longest = -1;
            for (int i = 0; i < 3; ++i) {
                const double l = (points[v[(i + 1) % 3]] - points[v[i]]).lengthSqr();
                if (l > longest) {
                    longest = l;
                    k = i;
                }
            }
            // Edge v[k] -> v[k+1] is longest: c = v[k], a = v[k+1], b = v[k+2].
            const std::uint32_t c = v[k], a = v[(k + 1) % 3], b = v[(k + 2) % 3];
            const auto it = owner.find(directed(a, c));
            if (it == owner.end()) {
                left.push_back(t);
                continue;
            }
            const std::uint32_t u = it->second;
            std::uint32_t d = 0;
            for (int i = 0; i < 3; ++i)
                if (tris[u][i] != a && tris[u][i] != c) d = tris[u][i];
            if (d == b || owner.count(directed(b, d)) || owner.count(directed(d, b))) {
                left.push_back(t);
                continue;
            }
            for (std::uint32_t x : {t, u})
                for (int i = 0; i < 3; ++i) owner.erase(directed(tris[x][i], tris[x][(i + 1) % 3]));
            tris[t] = openvdb::Vec3I(a, b, d);
            tris[u] = openvdb::Vec3I(b, c, d);
            for (std::uint32_t x : {t, u}) {
                for (int i = 0; i < 3; ++i) owner[directed(tris[x][i], tris[x][(i + 1) % 3])] = x;
                changed[x] = 1;
            }
            if (flat(tris[t])) left.push_back(t);
            if (flat(tris[u])) left.push_back(u);
        }
        bad.swap(left);
    }
}

}  // namespace pqdc::adaptive_detail
