// Adaptive stage "octree": bottom-up simplification. Eight sibling cells
// merge into their parent when the topology tests, containment, the
// collapse error bound and 2:1 balance all hold (include/pqdc/adaptive.hpp
// spells out each test and the error terms (a)-(d)).
#pragma once

#include "adaptive/field_probe.hpp"
#include "adaptive/octree.hpp"
#include "adaptive/untangle.hpp"
#include "lattice/cell_quadric.hpp"
#include "lattice/cube.hpp"
#include "lattice/interior.hpp"
#include "lattice/region.hpp"
#include "lattice/resources.hpp"
#include "pqdc/adaptive.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <vector>

namespace pqdc::adaptive_detail {

struct MergeCounters {
    std::atomic<std::uint64_t> merges{0}, refused_error{0}, refused_topology{0}, refused_containment{0},
        refused_balance{0}, refused_pinned{0};
};
/// Every counter, for code that treats them alike (sums, a rank's part).
template <class Counters>  // MergeCounters, const or not (the return type picks the overload)
auto counter_fields(Counters& c) -> decltype(std::array{&c.merges, &c.refused_error, &c.refused_topology,
                                                        &c.refused_containment, &c.refused_balance, &c.refused_pinned}) {
    return std::array{&c.merges, &c.refused_error, &c.refused_topology,
                      &c.refused_containment, &c.refused_balance, &c.refused_pinned};
}

/// Ju et al. 2002 §4.2 on the 27 lattice points of a cell of edge 2h:
/// manifold corner configuration, and the middle of every edge, face and of
/// the cube agrees in sign with one of that element's corners.
template <class Accessor>
bool topology_safe(Accessor& acc, const openvdb::Coord& origin, int h, const detail::Signing& signing) {
    bool in[3][3][3];
    for (int k = 0; k < 3; ++k)
        for (int j = 0; j < 3; ++j)
            for (int i = 0; i < 3; ++i)
                in[i][j][k] = signing(double(acc.getValue(origin + openvdb::Coord(i * h, j * h, k * h)))) < 0;
    unsigned mask = 0;
    for (int c = 0; c < 8; ++c)
        if (in[2 * (c & 1)][2 * (c >> 1 & 1)][2 * (c >> 2 & 1)]) mask |= 1u << c;
    if (!detail::manifold_configuration(std::uint8_t(mask))) return false;
    // Every one of the 19 non-corner points: it agrees with some corner of
    // the smallest element (edge, face, cube) that has it as its middle.
    for (int k = 0; k < 3; ++k)
        for (int j = 0; j < 3; ++j)
            for (int i = 0; i < 3; ++i) {
                if (i != 1 && j != 1 && k != 1) continue;  // a corner
                bool agrees = false;
                for (int ck = (k == 1 ? 0 : k); ck <= (k == 1 ? 2 : k) && !agrees; ck += 2)
                    for (int cj = (j == 1 ? 0 : j); cj <= (j == 1 ? 2 : j) && !agrees; cj += 2)
                        for (int ci = (i == 1 ? 0 : i); ci <= (i == 1 ? 2 : i) && !agrees; ci += 2)
                            agrees = in[ci][cj][ck] == in[i][j][k];
                if (!agrees) return false;
            }
    return true;
}

/// Whether the parent with this code may become a leaf without breaking the
/// 2:1 balance of the octree: none of the 56 cells of the children's level
/// around it is subdivided further (internal_children: sorted codes of the
/// children's level's internal nodes). In a balanced octree every leaf edge
/// holds at most one T-junction, so the degenerate dual cells around it form
/// no fans, whose shared edges would be used by more than two polygons.
bool balanced(const std::vector<std::uint64_t>& internal_children, std::uint64_t parent_code);

/// The children [i0, i1) of `level` merged into one cell of edge 2h with
/// vertex x (relative to the parent's origin): the collapse error in voxels,
/// terms (a)-(d) of adaptive.hpp, evaluated only until it reaches the bound.
double collapse_error(const Level& children, std::size_t i0, std::size_t i1, int h, const openvdb::Vec3d& x,
                      const CellQuadrics& sum, const openvdb::Coord& origin, FieldProbe& probe,
                      const AdaptiveOptions& options);

/// Sibling groups per progress report.
constexpr std::size_t kGroupsPerReport = 8192;

/// The parents of `level`'s nodes: merged leaves where every test passes,
/// internal nodes elsewhere; no parent that covers a pinned cell merges,
/// nor one whose vertex would leave `region` (its faces would be cut away,
/// leaving a hole where uniform mode has surface).
/// The span reports (and cancels) between chunks. With `counted`, only the
/// parents whose origin lies in that box are counted (a brick's own, when
/// its halo's parents are built too).
template <class GridT>
Level build_parent_level(const GridT& grid, const FieldSource& field, const Octree& tree, int level,
                         const detail::Signing& signing, const AdaptiveOptions& options, const PinnedCells& pinned,
                         const detail::Region& region, MergeCounters& counters, const detail::ProgressSpan& span,
                         const openvdb::CoordBBox* counted = nullptr) {
    const Level& cur = tree.levels[level];
    std::vector<std::size_t> starts;
    for (std::size_t i = 0; i < cur.size(); ++i)
        if (i == 0 || (cur.code[i] >> 3) != (cur.code[i - 1] >> 3)) starts.push_back(i);
    const std::size_t groups = starts.size();
    Level next;
    next.code.resize(groups);
    next.flags.assign(groups, 0);
    next.child_mask.resize(groups);
    next.first_child.resize(groups);
    next.quadrics.resize(groups);
    next.vertex.resize(groups);
    std::vector<std::uint64_t> internal_children;
    for (std::size_t i = 0; i < cur.size(); ++i)
        if (!(cur.flags[i] & kLeaf)) internal_children.push_back(cur.code[i]);
    const int h = 1 << level;
    const double size = 2.0 * h;
    const bool merging = options.max_error_voxels > 0;
    detail::parallel_ranges(groups, 256, kGroupsPerReport, span, [&](const tbb::blocked_range<std::size_t>& r) {
        auto acc = grid.getConstAccessor();
        auto probe = field.probe();
        detail::Region::Probe in_region(region);
        std::uint64_t merges = 0, refused_error = 0, refused_topology = 0, refused_containment = 0, refused_balance = 0,
                      refused_pinned = 0;
        std::uint64_t uncounted = 0;  // the tallies go here for parents outside `counted`
        for (std::size_t g = r.begin(); g != r.end(); ++g) {
            const std::size_t i0 = starts[g], i1 = g + 1 < groups ? starts[g + 1] : cur.size();
            const std::uint64_t code = cur.code[i0] >> 3;
            next.code[g] = code;
            next.first_child[g] = std::uint32_t(i0);
            unsigned mask = 0;
            bool children_mergeable = true;
            for (std::size_t i = i0; i < i1; ++i) {
                mask |= 1u << (cur.code[i] & 7);
                children_mergeable = children_mergeable && cur.flags[i] == (kLeaf | kManifold);
            }
            next.child_mask[g] = std::uint8_t(mask);
            if (!merging || !children_mergeable) continue;
            const openvdb::Coord origin = tree.origin(level + 1, code);
            const bool count = !counted || counted->isInside(origin);
            auto tally = [&](std::uint64_t& n) -> std::uint64_t& { return count ? n : uncounted; };
            if (pinned.covers(level + 1, code)) {
                ++tally(refused_pinned);
                continue;
            }
            if (!topology_safe(acc, origin, h, signing)) {
                ++tally(refused_topology);
                continue;
            }
            CellQuadrics sum;
            for (std::size_t i = i0; i < i1; ++i) {
                const unsigned o = unsigned(cur.code[i] & 7);
                sum += cur.quadrics[i].relative_to({-double((o & 1) * h), -double((o >> 1 & 1) * h), -double((o >> 2 & 1) * h)});
            }
            const detail::CellVertex v = detail::solve_cell_vertex(sum, size, options.base, detail::Clamp::none);
            const openvdb::Vec3d x(v.local.x, v.local.y, v.local.z);
            const double tol = 1e-9 * size;
            if (v.fallback || !(x.x() >= -tol && x.y() >= -tol && x.z() >= -tol && x.x() <= size + tol &&
                                x.y() <= size + tol && x.z() <= size + tol) ||
                !in_region.contains_point(origin.asVec3d() + x)) {
                ++tally(refused_containment);
                continue;
            }
            if (!(collapse_error(cur, i0, i1, h, x, sum, origin, *probe, options) < options.max_error_voxels)) {
                ++tally(refused_error);
                continue;
            }
            if (!balanced(internal_children, code)) {
                ++tally(refused_balance);
                continue;
            }
            next.flags[g] = kLeaf | kManifold;
            next.quadrics[g] = sum;
            next.vertex[g] = origin.asVec3d() + x;
            ++tally(merges);
        }
        counters.merges += merges;
        counters.refused_error += refused_error;
        counters.refused_topology += refused_topology;
        counters.refused_containment += refused_containment;
        counters.refused_balance += refused_balance;
        counters.refused_pinned += refused_pinned;
    });
    return next;
}

}  // namespace pqdc::adaptive_detail
