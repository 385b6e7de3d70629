// Adaptive stage "hermite": the finest octree level, one node per lattice
// cell the surface crosses (an active corner, all corners finite), with the
// cell's Hermite data summed as a CellQuadric and its vertex. Count, prefix
// sum, fill (the OpenVDB pattern): the level is written once, in place, at
// its exact size, in Morton order.
#pragma once

#include "adaptive/octree.hpp"
#include "lattice/cell_quadric.hpp"
#include "lattice/crossings.hpp"
#include "lattice/cube.hpp"
#include "lattice/region.hpp"
#include "lattice/resources.hpp"
#include "lattice/value_block.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <memory>
#include <vector>

namespace pqdc::adaptive_detail {

struct FinestCounters {
    /// Crossing edges and those with a degenerate normal, each counted by
    /// the block that owns its start point (an edge on a block face is
    /// computed in both blocks).
    std::atomic<std::uint64_t> crossings{0}, degenerate{0};
    std::atomic<std::uint64_t> clamped{0}, fallback{0};
    std::atomic<std::uint64_t> cells{0};       ///< finest surface cells
    std::atomic<std::uint64_t> non_finite{0};  ///< active NaN points of the blocks that may hold surface
    /// Crossing edges (counted as `crossings`) lacking one of their four
    /// cells: outside the region, without an active corner or with a NaN
    /// one. The mesh is open there (ExtractStats::boundary_crossings).
    std::atomic<std::uint64_t> open{0};
};
/// Every counter, for code that treats them alike (sums, a rank's part).
template <class Counters>  // FinestCounters, const or not (the return type picks the overload)
auto counter_fields(Counters& c)
    -> decltype(std::array{&c.crossings, &c.degenerate, &c.clamped, &c.fallback, &c.cells, &c.non_finite, &c.open}) {
    return std::array{&c.crossings, &c.degenerate, &c.clamped, &c.fallback, &c.cells, &c.non_finite, &c.open};
}

/// The lattice values around one 8^3 block and a memo of its crossings.
struct BlockScratch {
    static constexpr int N = 11;
    detail::DenseBlock dense;  // lattice points block - 1 .. block + 9
    detail::DenseBlock wide;   // block - 2 .. block + 10, for oracles with kMargin == 2
    struct Memo {
        detail::Crossing crossing;
        std::uint32_t stamp = 0;
        bool open = false;  // BlockDomain::open_edge
    };
    Memo cache[3 * 9 * 9 * 9];
    std::uint32_t stamp = 0;

    void next_block() {
        if (++stamp == 0) {
            for (auto& c : cache) c.stamp = 0;
            stamp = 1;
        }
    }
};

struct SurfaceCell {
    std::uint64_t code;
    std::uint8_t flags;
    CellQuadrics q;
    openvdb::Vec3d vertex;  // index space
};

/// Which cells around one 8^3 block take part (block-local cells -1..8,
/// read from BlockScratch::dense): a corner active, none NaN (the domain of
/// extract(); infinities are values), the origin in the region.
struct BlockDomain {
    const detail::DenseBlock& dense;  // lattice points block - 1 .. block + 9
    openvdb::Coord block;
    detail::Region::Probe& region;

    bool takes_part(int i, int j, int k) {
        bool any_active = false;
        for (int c = 0; c < 8; ++c) {
            const int ci = i + 1 + (c & 1), cj = j + 1 + (c >> 1 & 1), ck = k + 1 + (c >> 2 & 1);
            if (std::isnan(dense.at(ci, cj, ck))) return false;
            any_active = any_active || dense.on(ci, cj, ck);
        }
        return any_active && region.contains(block + openvdb::Coord(i, j, k));
    }
    /// Whether crossing edge (i, j, k) along `axis` lacks one of its four cells.
    bool open_edge(int i, int j, int k, int axis) {
        const int p = axis == 0 ? 1 : 0, q = axis == 2 ? 1 : 2;
        for (int c = 0; c < 4; ++c) {
            int at[3] = {i, j, k};
            at[p] -= c & 1;
            at[q] -= c >> 1;
            if (!takes_part(at[0], at[1], at[2])) return true;
        }
        return false;
    }
    /// Whether any crossing of the block may lack a cell: only where the
    /// region ends or a point around the block is inactive or NaN (most
    /// blocks of a level set have neither).
    bool may_open() const {
        if (!region.unbounded()) return true;
        constexpr unsigned all = (1u << BlockScratch::N) - 1;
        for (int x = 0; x < BlockScratch::N; ++x)
            for (int y = 0; y < BlockScratch::N; ++y)
                if (dense.nan_row[x][y] != 0 || (dense.active_row[x][y] & all) != all) return true;
        return false;
    }
};

/// The surface cells of one 8^3 block: with `out`, their Hermite data and
/// vertices are appended to it; without, they are only counted (the count
/// pass). Returns the count.
template <class AccessorT, class Oracle>
std::size_t block_surface_cells(const openvdb::Coord& block, const AccessorT& acc, const detail::Signing& signing,
                                const Oracle& oracle, const ExtractOptions& options, const openvdb::Coord& offset,
                                detail::Region::Probe& region, BlockScratch& s, std::vector<SurfaceCell>* out,
                                FinestCounters& counters) {
    using openvdb::Coord;
    // Most candidate blocks of a narrow band lie on one side of the surface:
    // decide that from the source values before converting any.
    if (!detail::corners_may_cross(acc, block, signing)) return 0;
    // The Hermite pass of a two-point stencil reads the wider block; the
    // classification's block is copied out of it.
    if (Oracle::kMargin == 2 && out) {
        detail::fetch_block(acc, block - Coord(2), BlockScratch::N + 2, signing, s.wide);
        detail::copy_sub_block(s.wide, 1, BlockScratch::N, s.dense);
    } else {
        detail::fetch_block(acc, block - Coord(1), BlockScratch::N, signing, s.dense);
    }
    const detail::DenseBlock& hermite_block = Oracle::kMargin == 2 ? s.wide : s.dense;
    const detail::Clamp clamp =
        options.containment == Containment::clamp_to_cell ? detail::Clamp::inside_cell : detail::Clamp::none;
    s.next_block();
    std::size_t count = 0;
    std::uint64_t n_crossings = 0, n_degenerate = 0, n_clamped = 0, n_fallback = 0, n_non_finite = 0, n_open = 0;
    const auto& in_row = s.dense.inside_row;
    if (!out)  // counted in the count pass, which sees blocks without surface cells too; own points are 1..8
        for (int x = 1; x <= 8; ++x)
            for (int y = 1; y <= 8; ++y)
                n_non_finite += unsigned(
                    __builtin_popcount(unsigned(s.dense.nan_row[x][y] & s.dense.active_row[x][y]) & 0x1feu));
    auto g = [&](int i, int j, int k) { return s.dense.at(i + 1, j + 1, k + 1); };
    BlockDomain domain{s.dense, block, region};
    const bool may_open = out && domain.may_open();
    for (int i = 0; i < 8; ++i)
        for (int j = 0; j < 8; ++j) {
            // Cells (i, j, 0..7) whose corners are not all on one side, 8 at a
            // time from the inside bits (block point p sits at bit p + 1).
            const unsigned all = unsigned(in_row[i + 1][j + 1] & in_row[i + 2][j + 1] & in_row[i + 1][j + 2] &
                                          in_row[i + 2][j + 2]),
                           any = unsigned(in_row[i + 1][j + 1] | in_row[i + 2][j + 1] | in_row[i + 1][j + 2] |
                                          in_row[i + 2][j + 2]);
            unsigned crossed = (((any | (any >> 1)) & ~(all & (all >> 1))) >> 1) & 0xffu;
            while (crossed) {
                const int k = __builtin_ctz(crossed);
                crossed &= crossed - 1;
                unsigned mask = 0;
                for (int c = 0; c < 8; ++c)
                    if (g(i + (c & 1), j + (c >> 1 & 1), k + (c >> 2 & 1)) < 0) mask |= 1u << c;
                if (mask == 0 || mask == 255 || !domain.takes_part(i, j, k)) continue;
                const Coord origin = block + Coord(i, j, k);
                ++count;
                if (!out) continue;
                SurfaceCell cell;
                bool open_cell = false;
                for (unsigned edges = detail::crossing_edges(std::uint8_t(mask)); edges; edges &= edges - 1) {
                    const int e = __builtin_ctz(edges);
                    const int corner = detail::edge_start_corner(e), axis = e >> 2;
                    const int li = i + (corner & 1), lj = j + (corner >> 1 & 1), lk = k + (corner >> 2 & 1);
                    BlockScratch::Memo& x = s.cache[axis * 729 + li + 9 * (lj + 9 * lk)];
                    if (x.stamp != s.stamp) {
                        constexpr int m = Oracle::kMargin;
                        x.crossing = oracle(hermite_block, li + m, lj + m, lk + m, axis);
                        x.stamp = s.stamp;
                        x.open = may_open && domain.open_edge(li, lj, lk, axis);
                        if (li < 8 && lj < 8 && lk < 8) {  // owned: the next block computes it again
                            ++n_crossings;
                            if (x.crossing.normal == vec3<double>(0, 0, 0)) ++n_degenerate;
                            n_open += x.open;
                        }
                    }
                    open_cell = open_cell || x.open;
                    vec3<double> q{double(corner & 1), double(corner >> 1 & 1), double(corner >> 2 & 1)};
                    q[axis] += x.crossing.t;
                    cell.q.add(q, x.crossing.normal);
                }
                // A cell at an edge of the mesh (the region's end, a hole,
                // the active band's end) does not merge: merged, its
                // surface was taken for closed there, and the mesh got a
                // wall across the region or ended voxels short of it.
                const bool mergeable = detail::manifold_configuration(std::uint8_t(mask)) && !open_cell;
                cell.flags = std::uint8_t(kLeaf | (mergeable ? kManifold : 0));
                const detail::CellVertex v = detail::solve_cell_vertex(cell.q, 1.0, options, clamp);
                n_fallback += v.fallback;
                n_clamped += v.clamped;
                cell.vertex = origin.asVec3d() + openvdb::Vec3d(v.local.x, v.local.y, v.local.z);
                const Coord rel = origin - offset;
                cell.code = morton(std::uint32_t(rel.x()), std::uint32_t(rel.y()), std::uint32_t(rel.z()));
                out->push_back(cell);
            }
        }
    counters.crossings += n_crossings;
    counters.degenerate += n_degenerate;
    counters.clamped += n_clamped;
    counters.fallback += n_fallback;
    counters.non_finite += n_non_finite;
    counters.open += n_open;
    return count;
}

/// Bytes per finest surface cell the whole adaptive pipeline needs: octree
/// levels (~1.2x the finest level), leaf ids (up to ~1.5 per cell: vertex,
/// value and two flags), dual cells (~4 per leaf: 8 ids and a sign mask) and
/// the mesh.
constexpr double kBytesPerSurfaceCell = 1.2 * (sizeof(SurfaceCell) + 16) + 1.5 * 34 + 4 * 33 + 64;

/// Blocks per progress report (a few ms each on one thread).
constexpr std::size_t kBlocksPerReport = 256;

/// Builds tree.levels[0] from the candidate blocks. Throws resource_error
/// (before allocating the level) when the whole pipeline's estimate exceeds
/// the memory limit, cancelled_error when the span's progress says stop.
/// Only the blocks inside `counted` are counted (a brick's own: its ring's
/// blocks are built too, and counted in their own brick).
template <class GridT, class Oracle>
void build_finest_level(const GridT& grid, std::vector<openvdb::Coord> blocks, const detail::Signing& signing,
                        const Oracle& oracle, const ExtractOptions& options, const detail::Region& region,
                        Octree& tree, FinestCounters& counters, const detail::ProgressSpan& span,
                        const openvdb::CoordBBox& counted) {
    // With an 8-aligned code origin the cells of one 8^3 block occupy one run
    // of 512 codes: blocks in code order, each block's cells in code order,
    // is all cells in code order, without a global sort or a copy.
    const bool block_runs = ((tree.offset.x() | tree.offset.y() | tree.offset.z()) & 7) == 0;
    auto block_code = [&](const openvdb::Coord& b) {
        const openvdb::Coord rel = b - tree.offset;
        return morton(std::uint32_t(rel.x()), std::uint32_t(rel.y()), std::uint32_t(rel.z()));
    };
    if (block_runs)
        tbb::parallel_sort(blocks.begin(), blocks.end(),
                           [&](const openvdb::Coord& a, const openvdb::Coord& b) { return block_code(a) < block_code(b); });
    std::vector<std::size_t> block_start(blocks.size() + 1, 0);
    {
        FinestCounters uncounted;  // the count pass tallies only non_finite
        detail::parallel_ranges(blocks.size(), 4, kBlocksPerReport, span.part(0.0, 0.4),
                                [&](const tbb::blocked_range<std::size_t>& r) {
            auto acc = grid.getConstAccessor();
            auto scratch = std::make_unique<BlockScratch>();
            detail::Region::Probe in_region(region);
            for (std::size_t b = r.begin(); b != r.end(); ++b)
                block_start[b + 1] =
                    block_surface_cells(blocks[b], acc, signing, oracle, options, tree.offset, in_region, *scratch,
                                        nullptr, counted.isInside(blocks[b]) ? counters : uncounted);
        });
    }
    for (std::size_t b = 0; b < blocks.size(); ++b) block_start[b + 1] += block_start[b];
    const std::size_t n_cells = block_start.back();
    detail::check_memory(double(n_cells) * kBytesPerSurfaceCell, options, "adaptive octree");
    Level& l0 = tree.levels[0];
    l0.code.resize(n_cells);
    l0.flags.resize(n_cells);
    // child_mask and first_child describe internal nodes: none at level 0.
    l0.quadrics.resize(n_cells);
    l0.vertex.resize(n_cells);
    auto put = [&l0](std::size_t i, const SurfaceCell& c) {
        l0.code[i] = c.code;
        l0.flags[i] = c.flags;
        l0.quadrics[i] = c.q;
        l0.vertex[i] = c.vertex;
    };
    // Cell sizes below 8 voxels: the codes of one block are not one run,
    // so the cells are gathered first and put in code order after.
    std::vector<SurfaceCell> gathered(block_runs ? 0 : n_cells);
    detail::parallel_ranges(blocks.size(), 4, kBlocksPerReport, span.part(0.4, 1.0),
                            [&](const tbb::blocked_range<std::size_t>& r) {
        auto acc = grid.getConstAccessor();
        auto scratch = std::make_unique<BlockScratch>();
        detail::Region::Probe in_region(region);
        std::vector<SurfaceCell> cells;
        cells.reserve(512);
        FinestCounters uncounted;
        for (std::size_t b = r.begin(); b != r.end(); ++b) {
            if (block_start[b + 1] == block_start[b]) continue;
            cells.clear();
            FinestCounters& tally = counted.isInside(blocks[b]) ? counters : uncounted;
            block_surface_cells(blocks[b], acc, signing, oracle, options, tree.offset, in_region, *scratch, &cells,
                                tally);
            tally.cells += cells.size();
            if (block_runs) {
                std::sort(cells.begin(), cells.end(), [](const SurfaceCell& x, const SurfaceCell& y) { return x.code < y.code; });
                for (std::size_t i = 0; i < cells.size(); ++i) put(block_start[b] + i, cells[i]);
            } else {
                std::copy(cells.begin(), cells.end(), gathered.begin() + std::ptrdiff_t(block_start[b]));
            }
        }
    });
    if (!block_runs) {
        std::vector<std::pair<std::uint64_t, std::size_t>> order(n_cells);  // (code, index into gathered)
        for (std::size_t i = 0; i < n_cells; ++i) order[i] = {gathered[i].code, i};
        tbb::parallel_sort(order.begin(), order.end());
        tbb::parallel_for(std::size_t(0), n_cells, [&](std::size_t k) { put(k, gathered[order[k].second]); });
    }
}

}  // namespace pqdc::adaptive_detail
