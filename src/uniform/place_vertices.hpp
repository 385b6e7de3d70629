// Uniform stage "place vertices": the Hermite samples of a leaf's crossed
// cells (each lattice edge sampled once per leaf), their quadrics summed per
// surface patch in cell-local coordinates, and one vertex per patch.
#pragma once

#include "lattice/cell_quadric.hpp"
#include "lattice/crossings.hpp"
#include "lattice/cube.hpp"
#include "lattice/transform.hpp"
#include "uniform/cell_tree.hpp"
#include "uniform/classify.hpp"

#include <cstdint>
#include <vector>

namespace pqdc::detail {

struct VertexCounters {
    std::uint64_t degenerate = 0;  ///< owned crossings without a usable normal
    std::uint64_t clamped = 0;
    std::uint64_t fallback = 0;
    std::uint64_t multi = 0;       ///< cells with more than one patch
};

/// Per-thread memo of the leaf's crossings: edge start points [0, 8]^3, three axes.
struct CrossingCache {
    static constexpr int E = kLeafDim + 1;
    std::vector<Crossing> crossing = std::vector<Crossing>(E * E * E * 3);
    std::vector<std::uint32_t> stamp = std::vector<std::uint32_t>(E * E * E * 3, 0);
    std::uint32_t generation = 0;

    void next_leaf() {
        if (++generation == 0) {
            std::fill(stamp.begin(), stamp.end(), 0u);
            generation = 1;
        }
    }
};

/// Appends the world-space vertices of every cell in `cells` to `points`
/// (patch order within a cell) and returns, per cell, its first vertex's
/// index in `points`. `hermite_block` holds the leaf's points with
/// Oracle::kMargin points of margin below its first cell.
template <class Oracle>
void place_leaf_vertices(const Oracle& oracle, const DenseBlock& hermite_block, const LeafCells& leaf,
                         const openvdb::Coord& origin, const LatticeTransform& xf, const ExtractOptions& options,
                         CrossingCache& cache, std::vector<openvdb::Vec3d>& points,
                         std::vector<std::uint32_t>& first_vertex, VertexCounters& counters) {
    constexpr int E = CrossingCache::E;
    constexpr int m = Oracle::kMargin;
    const Clamp clamp = options.containment == Containment::clamp_to_cell ? Clamp::inside_cell : Clamp::none;
    cache.next_leaf();
    first_vertex.clear();
    for (const ClassifiedCell& cell : leaf.cells) {
        const EdgeGroups groups = cell.joined ? edge_groups(cell.config, cell.joined) : plain_edge_groups()[cell.config];
        CellQuadric sums[4];
        for (unsigned edges = crossing_edges(cell.config); edges; edges &= edges - 1) {
            const int e = __builtin_ctz(edges);
            const int corner = edge_start_corner(e), axis = e >> 2;
            const int ex = cell.local.x() + (corner & 1), ey = cell.local.y() + ((corner >> 1) & 1),
                      ez = cell.local.z() + ((corner >> 2) & 1);
            const int key = ((ex * E + ey) * E + ez) * 3 + axis;
            if (cache.stamp[key] != cache.generation) {
                cache.stamp[key] = cache.generation;
                cache.crossing[key] = oracle(hermite_block, ex + m, ey + m, ez + m, axis);
                const bool owned = ex < kLeafDim && ey < kLeafDim && ez < kLeafDim;
                if (owned && cache.crossing[key].normal == vec3<double>{0, 0, 0}) ++counters.degenerate;
            }
            const Crossing& c = cache.crossing[key];
            vec3<double> p{double(corner & 1), double((corner >> 1) & 1), double((corner >> 2) & 1)};
            p[axis] += c.t;
            sums[groups.group[e]].add(p, c.normal);
        }
        if (groups.count > 1) ++counters.multi;
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
