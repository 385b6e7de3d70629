// Vertex normals of the decimated mesh, from the input's (a mesh read from a
// file with normals, or one whose caller computed them): decimation moves
// vertices, so the input's normals no longer sit where they were given.
// A vertex that did not move keeps its normal bit for bit. A moved vertex
// takes the input normals interpolated (barycentric weights) at its nearest
// point on the input faces around the input vertices it absorbed, its
// cluster, normalized. The cluster is the part of the input the vertex
// stands for, so a thin sheet's far side is never picked, and the search
// costs one look at each input face per cluster touching it. Neither
// averaging the cluster's normals (smooths across the whole cluster) nor
// the output's face normals (a coarse mesh's facets) keeps the input's own
// shading.

#include "decimate_internal.hpp"
#include "measure/closest_point.hpp"

#include <limits>
#include <numeric>

namespace pqdc::decimate_detail {
namespace {

constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();

/// CSR lists: list `k` is items[begin[k] .. begin[k + 1]).
struct Lists {
    std::vector<std::uint32_t> begin, items;
    const std::uint32_t* first(std::size_t k) const { return items.data() + begin[k]; }
    const std::uint32_t* last(std::size_t k) const { return items.data() + begin[k + 1]; }
};

/// Each output vertex's cluster: the input vertices merged into it, itself
/// included (merged_into[b] = a for every collapse, a < b, so one pass in
/// index order resolves the chains).
Lists clusters(const std::vector<std::uint32_t>& merged_into, const std::vector<std::uint32_t>& output_index,
               std::size_t outputs) {
    std::vector<std::uint32_t> root(merged_into.size());
    Lists l;
    l.begin.assign(outputs + 1, 0);
    for (std::size_t v = 0; v < root.size(); ++v) {
        root[v] = merged_into[v] == kNone ? std::uint32_t(v) : root[merged_into[v]];
        if (output_index[root[v]] != kNone) ++l.begin[output_index[root[v]] + 1];
    }
    std::partial_sum(l.begin.begin(), l.begin.end(), l.begin.begin());
    l.items.resize(l.begin.back());
    std::vector<std::uint32_t> fill(l.begin.begin(), l.begin.end() - 1);
    for (std::size_t v = 0; v < root.size(); ++v)
        if (output_index[root[v]] != kNone) l.items[fill[output_index[root[v]]]++] = std::uint32_t(v);
    return l;
}

}  // namespace

std::vector<openvdb::Vec3d> transfer_vertex_normals(const Mesh& input, const std::vector<Tri>& input_tris,
                                                    const std::vector<std::uint32_t>& merged_into,
                                                    const std::vector<std::uint32_t>& output_index,
                                                    const std::vector<openvdb::Vec3d>& points) {
    namespace cp = closest_point;
    const Lists cluster = clusters(merged_into, output_index, points.size());
    Lists fan;  // input vertex -> its input triangles
    build_fans(input_tris, input.points.size(), fan.begin, fan.items);
    std::vector<openvdb::Vec3d> normals(points.size());
    parallel_ranges(points.size(), 256, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
            const openvdb::Vec3d& p = points[i];
            // The cluster's smallest index is the output vertex itself (a < b).
            const std::uint32_t self = *cluster.first(i);
            if (p == input.points[self]) {
                normals[i] = input.normals[self];
                continue;
            }
            // The nearest point, ties to the lowest face index: the same for any thread count.
            double best_d2 = std::numeric_limits<double>::infinity();
            std::uint32_t best_face = kNone;
            openvdb::Vec3d weights(0.0);
            for (const std::uint32_t* u = cluster.first(i); u != cluster.last(i); ++u)
                for (const std::uint32_t* f = fan.first(*u); f != fan.last(*u); ++f) {
                    const Tri& t = input_tris[*f];
                    const openvdb::Vec3d &a = input.points[t[0]], &b = input.points[t[1]], &c = input.points[t[2]];
                    const cp::ClosestPoint q = cp::closest_on_any_triangle(p, a, b, c);
                    const double d2 = (q.point - p).lengthSqr();
                    if (d2 < best_d2 || (d2 == best_d2 && *f < best_face)) {
                        best_d2 = d2;
                        best_face = *f;
                        weights = cp::barycentric_weights(a, b, c, q);
                    }
                }
            openvdb::Vec3d n(0.0);
            if (best_face != kNone)
                for (int k = 0; k < 3; ++k) {
                    const openvdb::Vec3d& nk = input.normals[input_tris[best_face][std::size_t(k)]];
                    if (weights[k] > 0 && std::isfinite(nk[0]) && std::isfinite(nk[1]) && std::isfinite(nk[2]))
                        n += nk * weights[k];
                }
            const double length = n.length();
            if (length > 0 && std::isfinite(length)) {
                normals[i] = n / length;
                continue;
            }
            // Opposed or missing input normals cancel: the nearest face's own normal.
            if (best_face != kNone) {
                const Tri& t = input_tris[best_face];
                const openvdb::Vec3d f = (input.points[t[1]] - input.points[t[0]]).cross(input.points[t[2]] - input.points[t[0]]);
                const double fl = f.length();
                normals[i] = fl > 0 && std::isfinite(fl) ? f / fl : openvdb::Vec3d(0.0);
            }
        }
    });
    return normals;
}

}  // namespace pqdc::decimate_detail
