// Uniform stage "place vertices": the Hermite samples of a leaf's crossed
// cells (each lattice edge sampled once per leaf), their quadrics summed per
// surface patch in cell-local coordinates, and one vertex per patch.
//
// With denoising (QuadricFilter::radius > 0) a single-patch cell minimizes
// instead the weighted sum of its own quadric and those of its 26
// neighbours (moved into its coordinates), each weighted by
//   exp(-|o|^2 / 2) * exp(-(1 - <n, n_cell>) / normal_width),
// o the neighbour's offset in cells, n and n_cell the mean normals of the
// neighbour's and the cell's own samples: a bilateral filter of the
// quadrics (Trettner & Kobbelt 2020, section 5.2, on the lattice).
// Neighbours across a sharp edge have normals far from the cell's and add
// nearly nothing, so edges stay sharp while the noise of ~30 samples
// averages out. Cells with several patches (ambiguous configurations) keep
// their own samples: their patches are too close for a neighbourhood to
// tell apart.
#pragma once

#include "lattice/auto_parameters.hpp"
#include "lattice/cell_quadric.hpp"
#include "lattice/crossings.hpp"
#include "lattice/cube.hpp"
#include "lattice/transform.hpp"
#include "uniform/cell_tree.hpp"
#include "uniform/classify.hpp"

#include <cmath>
#include <cstdint>
#include <vector>

namespace pqdc::detail {

struct VertexCounters {
    std::uint64_t clamped = 0;
    std::uint64_t fallback = 0;
    std::uint64_t multi = 0;       ///< cells with more than one patch
};

/// Per-thread memo of the leaf's crossings: edge start points
/// [-radius, 8 + radius]^3, three axes.
class CrossingCache {
public:
    void next_leaf(int radius) {
        if (radius != radius_) {
            radius_ = radius;
            E_ = kLeafDim + 1 + 2 * radius;
            const std::size_t n = std::size_t(E_) * E_ * E_ * 3;
            crossing_.assign(n, Crossing{});
            stamp_.assign(n, 0u);
            generation_ = 0;
        }
        if (++generation_ == 0) {
            std::fill(stamp_.begin(), stamp_.end(), 0u);
            generation_ = 1;
        }
    }
    /// The crossing on the edge from leaf-local point (x, y, z) along axis,
    /// computed on its first use in this leaf.
    template <class Oracle>
    const Crossing& get(const Oracle& oracle, const DenseBlock& b, int margin, int x, int y, int z, int axis) {
        const int key = (((x + radius_) * E_ + (y + radius_)) * E_ + (z + radius_)) * 3 + axis;
        if (stamp_[key] != generation_) {
            stamp_[key] = generation_;
            crossing_[key] = oracle(b, x + margin, y + margin, z + margin, axis);
            const bool owned = x >= 0 && y >= 0 && z >= 0 && x < kLeafDim && y < kLeafDim && z < kLeafDim;
            if (owned && crossing_[key].normal == vec3<double>{0, 0, 0}) ++degenerate_owned;
        }
        return crossing_[key];
    }
    /// Crossings owned by the leaves seen so far (start point inside the
    /// leaf) whose gradient was zero or non-finite.
    std::uint64_t degenerate_owned = 0;

private:
    int radius_ = -1, E_ = 0;
    std::vector<Crossing> crossing_;
    std::vector<std::uint32_t> stamp_;
    std::uint32_t generation_ = 0;
};

/// The Hermite block's extent for an oracle and a filter: points
/// origin - margin .. origin + 8 + margin.
inline int hermite_margin(int oracle_margin, const QuadricFilter& filter) { return oracle_margin + filter.radius; }

namespace place_detail {

/// R(x) = q(x - o) for a small integer offset o, in double (the filter's
/// offsets are one cell; the long double of quadric::relative_to is not needed).
inline CellQuadric shifted(const CellQuadric& q, const vec3<double>& o) {
    CellQuadric r = q;
    const vec3<double> Ao = q.classical.A * o;
    r.classical.b = q.classical.b + Ao;
    r.classical.c = q.classical.c + 2.0 * dot(q.classical.b, o) + dot(o, Ao);
    r.points.sum = q.points.sum + o * q.points.count;
    r.points.sum_sq = q.points.sum_sq + 2.0 * dot(q.points.sum, o) + q.points.count * dot(o, o);
    return r;
}

/// Per-thread memo of the own quadrics and mean normals of the cells
/// [-1, 8]^3 of a leaf (the filter's neighbourhood of every cell).
class OwnQuadrics {
public:
    static constexpr int D = kLeafDim + 2;
    void next_leaf() {
        if (stamp_.empty()) {
            quadric_.resize(D * D * D);
            normal_.resize(D * D * D);
            stamp_.assign(D * D * D, 0u);
        }
        if (++generation_ == 0) {
            std::fill(stamp_.begin(), stamp_.end(), 0u);
            generation_ = 1;
        }
    }
    /// The own samples of the cell at leaf-local (x, y, z), [-1, 8]^3;
    /// an empty quadric (points.count == 0) when the surface misses it.
    template <class Oracle>
    const CellQuadric& get(const Oracle& oracle, const DenseBlock& b, int margin, int x, int y, int z,
                           CrossingCache& cache, vec3<double>& normal) {
        const int key = ((x + 1) * D + (y + 1)) * D + (z + 1);
        if (stamp_[key] != generation_) {
            stamp_[key] = generation_;
            compute(oracle, b, margin, x, y, z, cache, quadric_[key], normal_[key]);
        }
        normal = normal_[key];
        return quadric_[key];
    }

private:
    template <class Oracle>
    static void compute(const Oracle& oracle, const DenseBlock& b, int margin, int x, int y, int z,
                        CrossingCache& cache, CellQuadric& q, vec3<double>& normal) {
        q = CellQuadric{};
        normal = {0, 0, 0};
        unsigned config = 0, nan = 0;
        for (int c = 0; c < 8; ++c) {
            const int cx = x + margin + (c & 1), cy = y + margin + ((c >> 1) & 1), cz = z + margin + ((c >> 2) & 1);
            config |= ((b.inside_row[cx][cy] >> cz) & 1u) << c;
            nan |= (b.nan_row[cx][cy] >> cz) & 1u;
        }
        if (nan) return;
        vec3<double> sum{0, 0, 0};
        for (unsigned edges = crossing_edges(std::uint8_t(config)); edges; edges &= edges - 1) {
            const int e = __builtin_ctz(edges);
            const int corner = edge_start_corner(e), axis = e >> 2;
            const Crossing& c = cache.get(oracle, b, margin, x + (corner & 1), y + ((corner >> 1) & 1),
                                          z + ((corner >> 2) & 1), axis);
            vec3<double> p{double(corner & 1), double((corner >> 1) & 1), double((corner >> 2) & 1)};
            p[axis] += c.t;
            q.add(p, c.normal);
            sum += c.normal;
        }
        normal = normalized_or_zero(sum);
    }

    std::vector<CellQuadric> quadric_;
    std::vector<vec3<double>> normal_;
    std::vector<std::uint32_t> stamp_;
    std::uint32_t generation_ = 0;
};

/// The filtered quadric of the single-patch cell at leaf-local `cell` with
/// mean normal `n_cell`, in its local coordinates (see the file comment).
template <class Oracle>
CellQuadric filtered_quadric(const Oracle& oracle, const DenseBlock& b, int margin, const openvdb::Coord& cell,
                             const vec3<double>& n_cell, const QuadricFilter& filter, CrossingCache& cache,
                             OwnQuadrics& own) {
    static const double spatial[4] = {1.0, std::exp(-0.5), std::exp(-1.0), std::exp(-1.5)};
    const double inv_h = 1.0 / filter.normal_width;
    vec3<double> n_self;
    const CellQuadric& self = own.get(oracle, b, margin, cell.x(), cell.y(), cell.z(), cache, n_self);
    const vec3<double> c_self = self.points.sum / self.points.count;
    CellQuadric sum;
    double weight = 0;  // sum of w * sample count
    for (int i = -1; i <= 1; ++i)
        for (int j = -1; j <= 1; ++j)
            for (int k = -1; k <= 1; ++k) {
                vec3<double> n;
                const CellQuadric& q = own.get(oracle, b, margin, cell.x() + i, cell.y() + j, cell.z() + k, cache, n);
                if (q.points.count == 0) continue;
                double w = spatial[i * i + j * j + k * k];
                if (!(n == vec3<double>{0, 0, 0})) w *= std::exp(-(1.0 - dot(n, n_cell)) * inv_h);
                if (!(i | j | k)) {
                    sum.classical += q.classical * w;
                    weight += w * q.points.count;
                    continue;
                }
                // A neighbour's tangent planes miss a curved surface at this
                // cell by half its normal curvature times the squared offset,
                // so their plain sum pushes the vertex off the surface
                // (outwards where it is convex: the denoised Armadillo at 128
                // cells sat 0.038 voxel outside on average, 0.013 without the
                // filter). To second order, with S the shape operator,
                //   n_q . (x - c_q) = -1/2 (x - c_q)^T S (x - c_q) and
                //   (n_cell - n_q) . (c_cell - c_q) = (c_cell - c_q)^T S (c_cell - c_q),
                // so the neighbour's planes moved by -delta n_q, delta half the
                // latter, pass through this cell's patch. Only where the normals
                // agree within the filter's normal width: beyond it the two cells
                // sit on either side of a crease, not on one curved sheet, and
                // the correction would pull the other face's planes in
                // (feature error +7% on the noisy box with it everywhere).
                const vec3<double> o{double(i), double(j), double(k)};
                const vec3<double> c_q = q.points.sum / q.points.count + o;
                const double delta =
                    1.0 - dot(n, n_cell) < filter.normal_width ? 0.5 * dot(n_cell - n, c_self - c_q) : 0.0;
                sum.classical += shifted(q, o - delta * n).classical * w;
                weight += w * q.points.count;
            }
    // The point term stays the cell's own, scaled to the filtered weight:
    // the neighbourhood's mass point lies wherever the surface crosses the
    // 3x3x3 block, often outside the cell (a cell the surface clips at a
    // corner), while the cell's own keeps the vertex over its own patch.
    const double scale = weight / self.points.count;
    sum.points.count = self.points.count * scale;
    sum.points.sum = self.points.sum * scale;
    sum.points.sum_sq = self.points.sum_sq * scale;
    return sum;
}

}  // namespace place_detail

/// Appends the world-space vertices of every cell in `cells` to `points`
/// (patch order within a cell) and returns, per cell, its first vertex's
/// index in `points`. `hermite_block` holds the leaf's points with
/// hermite_margin(Oracle::kMargin, filter) points of margin below its first cell.
template <class Oracle>
void place_leaf_vertices(const Oracle& oracle, const DenseBlock& hermite_block, const LeafCells& leaf,
                         const openvdb::Coord& origin, const LatticeTransform& xf, const ExtractOptions& options,
                         const QuadricFilter& filter, CrossingCache& cache, place_detail::OwnQuadrics& own,
                         std::vector<openvdb::Vec3d>& points,
                         std::vector<std::uint32_t>& first_vertex, VertexCounters& counters) {
    const int m = hermite_margin(Oracle::kMargin, filter);
    const Clamp clamp = options.containment == Containment::clamp_to_cell ? Clamp::inside_cell : Clamp::none;
    cache.next_leaf(filter.radius);
    if (filter.radius > 0) own.next_leaf();
    first_vertex.clear();
    // One allocation of the exact size: growing by push_back cost the cells
    // stage about a fifth of its time in glibc's malloc (sorting the freed
    // smaller blocks) and in first-touch faults of the copies.
    std::size_t vertices = 0;
    for (const ClassifiedCell& cell : leaf.cells)
        vertices += cell.joined ? edge_groups(cell.config, cell.joined).count : plain_edge_groups()[cell.config].count;
    points.reserve(points.size() + vertices);
    for (const ClassifiedCell& cell : leaf.cells) {
        const EdgeGroups groups = cell.joined ? edge_groups(cell.config, cell.joined) : plain_edge_groups()[cell.config];
        CellQuadric sums[4];
        vec3<double> normal_sum{0, 0, 0};
        for (unsigned edges = crossing_edges(cell.config); edges; edges &= edges - 1) {
            const int e = __builtin_ctz(edges);
            const int corner = edge_start_corner(e), axis = e >> 2;
            const int ex = cell.local.x() + (corner & 1), ey = cell.local.y() + ((corner >> 1) & 1),
                      ez = cell.local.z() + ((corner >> 2) & 1);
            const Crossing& c = cache.get(oracle, hermite_block, m, ex, ey, ez, axis);
            vec3<double> p{double(corner & 1), double((corner >> 1) & 1), double((corner >> 2) & 1)};
            p[axis] += c.t;
            sums[groups.group[e]].add(p, c.normal);
            normal_sum += c.normal;
        }
        if (groups.count > 1) ++counters.multi;
        if (filter.radius > 0 && groups.count == 1) {
            const vec3<double> n = normalized_or_zero(normal_sum);
            if (!(n == vec3<double>{0, 0, 0}))
                sums[0] = place_detail::filtered_quadric(oracle, hermite_block, m, cell.local, n, filter, cache, own);
        }
        const openvdb::Vec3d cell_min = (origin + cell.local).asVec3d();
        first_vertex.push_back(std::uint32_t(points.size()));
        for (int g = 0; g < groups.count; ++g) {
            const CellVertex v = solve_cell_vertex(sums[g], 1.0, options, clamp);
            counters.clamped += v.clamped;
            counters.fallback += v.fallback;
            points.push_back(xf.to_world(cell_min + openvdb::Vec3d(v.local.x, v.local.y, v.local.z)));
        }
    }
}

}  // namespace pqdc::detail
