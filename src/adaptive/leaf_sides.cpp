#include "adaptive/leaf_sides.hpp"

#include "measure/mesh_internal.hpp"

#include <tbb/blocked_range.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace pqdc::adaptive_detail {
namespace {

using openvdb::Vec3d;

constexpr std::size_t kItemsPerReport = 1 << 17;  // leaves

/// Step 1. Surface leaves' vertices lie on the surface (up to the merge
/// error), so the sign of the field there is noise: classifying them by it
/// splits the surface into slivers and bubbles. They count as inside (a
/// symbolic perturbation of the field there towards the inside), empty leaves
/// by the field's sign at a lattice point inside them.
LeafVertices leaf_vertices(const Octree& tree, const LeafNumbering& numbering, const FieldSource& field,
                           AdaptiveStats& stats, const detail::ProgressSpan& span) {
    const std::size_t n_leaves = numbering.count;
    LeafVertices v;
    v.position.resize(n_leaves);
    v.value.assign(n_leaves, 0.0);
    v.is_surface.assign(n_leaves, 0);
    // Nodes below a merged leaf keep their own kLeaf flag: the leaves of the
    // octree are the flagged nodes whose parent is internal (or roots).
    std::vector<std::uint8_t> internal, below;  // of the level above, of this level
    for (int level = tree.top; level >= 0; --level) {
        const Level& lv = tree.levels[level];
        const std::size_t first = numbering.node_first[level];
        below.assign(lv.size(), level == tree.top ? 1 : 0);
        if (level < tree.top) {
            const Level& up = tree.levels[level + 1];
            for (std::size_t p = 0; p < up.size(); ++p)
                if (internal[p]) std::fill_n(below.begin() + up.first_child[p], popcount8(up.child_mask[p]), 1);
        }
        std::uint64_t leaves = 0;
        internal.assign(lv.size(), 0);
        for (std::size_t i = 0; i < lv.size(); ++i) {
            if (!below[i]) continue;
            if (!(lv.flags[i] & kLeaf)) {
                internal[i] = 1;
                continue;
            }
            v.position[first + i] = lv.vertex[i];
            v.is_surface[first + i] = 1;
            ++leaves;
        }
        stats.leaves_per_level[level] += leaves;
        stats.surface_leaves += leaves;
    }
    const std::size_t empty_first = numbering.empty_first_id;
    stats.empty_leaves = n_leaves - empty_first;
    detail::parallel_ranges(n_leaves - empty_first, 1024, kItemsPerReport, span,
                            [&](const tbb::blocked_range<std::size_t>& r) {
        auto probe = field.probe();
        for (std::size_t i = empty_first + r.begin(); i != empty_first + r.end(); ++i) {
            const std::uint64_t key = numbering.empty_key[i - empty_first];
            const int level = key_level(key);
            // A lattice point inside the leaf (its center, or its lowest
            // corner for a single cell): every lattice point of an empty
            // leaf has the same sign, which the field between lattice
            // points (noise finer than a voxel) need not keep.
            // In 64 bits, converted back modulo 2^32 as Octree::origin does: a
            // missing root beside a root at code 0 has a wrapped origin near
            // the int range's end, where a 32-bit Coord sum would overflow.
            const std::int64_t half = level > 0 ? std::int64_t(1) << (level - 1) : 0;
            const openvdb::Coord origin = tree.origin(level, key_code(key));
            auto axis = [&](int a) { return double(int(std::int64_t(origin[a]) + half)); };
            v.position[i] = openvdb::Vec3d(axis(0), axis(1), axis(2));
            v.value[i] = probe->value(v.position[i]);
        }
    });
    v.inside.resize(n_leaves);
    for (std::size_t i = 0; i < n_leaves; ++i) v.inside[i] = v.is_surface[i] || (i >= empty_first && v.value[i] < 0);
    return v;
}

/// Step 1a. Empty leaves where the field has no value (NaN at the probed
/// point: a NaN background, or no value beyond an array's end) were taken
/// as outside, which cut holes where they lie inside: the NaN core of a
/// level set copied into a NaN-background grid. Face-adjacent empty leaves
/// have one side (the lattice points on their shared face are corners of
/// both, and neither holds a crossing), so each connected group of
/// undefined leaves takes the side of the defined empty leaves it touches
/// along dual edges: inside only when every one it touches is inside.
/// Outside wins a conflict, as before, so the undefined space beyond an
/// array that the surface reaches stays outside. Returns the leaves set inside.
std::uint64_t settle_undefined_leaves(const std::vector<DualCell>& cells, const LeafNumbering& numbering,
                                      LeafVertices& leaves) {
    const std::size_t n = leaves.inside.size(), first = numbering.empty_first_id;
    auto undefined = [&](std::uint32_t i) { return i >= first && std::isnan(leaves.value[i]); };
    bool any = false;
    for (std::size_t i = first; i < n && !any; ++i) any = std::isnan(leaves.value[i]);
    if (!any) return 0;
    detail::UnionFind groups(n);
    constexpr std::uint8_t kTouchesOutside = 1, kTouchesInside = 2;
    std::vector<std::uint8_t> touches(n, 0);
    auto meet = [&](std::uint32_t a, std::uint32_t b) {
        if (undefined(b) && a >= first && !undefined(a))
            touches[b] |= leaves.inside[a] ? kTouchesInside : kTouchesOutside;
    };
    for (const DualCell& cell : cells) {
        for (int i = 0; i < 8; ++i) {
            for (int bit = 1; bit < 8; bit <<= 1) {
                if (i & bit) continue;
                const std::uint32_t a = cell[i], b = cell[i | bit];
                if (undefined(a) && undefined(b)) {
                    groups.unite(a, b);
                } else {
                    meet(a, b);
                    meet(b, a);
                }
            }
        }
    }
    std::vector<std::uint8_t> group_touches(n, 0);
    for (std::size_t i = first; i < n; ++i)
        if (undefined(std::uint32_t(i))) group_touches[groups.find(std::uint32_t(i))] |= touches[i];
    std::uint64_t settled = 0;
    for (std::size_t i = first; i < n; ++i) {
        if (!undefined(std::uint32_t(i)) || group_touches[groups.find(std::uint32_t(i))] != kTouchesInside) continue;
        leaves.inside[i] = 1;
        ++settled;
    }
    return settled;
}

/// Step 1b. Surface leaves count as inside, so merged surface leaves can
/// wall in empty outside leaves that on the lattice reach the rest of the
/// outside through them (a thin air wedge at a concave crease). Such a pocket
/// would become a closed, inside-out bubble of a few triangles. Outside
/// leaves are grouped as the dual cells' triangles connect them; a group of
/// at most kPocketVoxels voxels, every leaf of it a corner of at least 8
/// dual cells (surrounded), is set inside, as thinner outside features are.
/// A real cavity that small is lost with it (the uniform extractor keeps it).
constexpr std::uint64_t kPocketVoxels = 8;

std::uint64_t fill_outside_pockets(const std::vector<DualCell>& cells, const LeafNumbering& numbering,
                                   LeafVertices& leaves) {
    const std::size_t n = leaves.inside.size();
    detail::UnionFind groups(n);
    std::vector<std::uint32_t> uses(n, 0);
    for (const DualCell& cell : cells) {
        for (int i = 0; i < 8; ++i) {
            if (leaves.inside[cell[i]]) continue;
            ++uses[cell[i]];
            // Outside corners along a cube edge or a face diagonal share the
            // outside in the cell's triangles (ambiguous faces separate the
            // inside corners); across the body diagonal they need not.
            for (int j = i + 1; j < 8; ++j) {
                if (!leaves.inside[cell[j]] && (i ^ j) != 7) groups.unite(cell[i], cell[j]);
            }
        }
    }
    // Per group: its volume in voxels, or "too large" once it is not a pocket.
    constexpr std::uint64_t kNotPocket = std::numeric_limits<std::uint64_t>::max();
    std::vector<std::uint64_t> voxels(n, 0);
    const std::size_t empty_first = numbering.empty_first_id;
    for (std::size_t i = empty_first; i < n; ++i) {
        if (leaves.inside[i]) continue;
        std::uint64_t& group = voxels[groups.find(std::uint32_t(i))];
        const int level = key_level(numbering.empty_key[i - empty_first]);
        const std::uint64_t size = level < 21 ? std::uint64_t(1) << (3 * level) : kNotPocket;
        const bool pocket = group != kNotPocket && uses[i] >= 8 && size <= kPocketVoxels &&
                            group + size <= kPocketVoxels;
        group = pocket ? group + size : kNotPocket;
    }
    std::uint64_t filled = 0;
    for (std::size_t i = empty_first; i < n; ++i) {
        if (leaves.inside[i] || voxels[groups.find(std::uint32_t(i))] == kNotPocket) continue;
        leaves.inside[i] = 1;
        ++filled;
    }
    return filled;
}

}  // namespace

LeafVertices leaf_sides(const Octree& tree, const LeafNumbering& numbering, const std::vector<DualCell>& cells,
                        const FieldSource& field, AdaptiveStats& stats, const detail::ProgressSpan& span) {
    LeafVertices leaves = leaf_vertices(tree, numbering, field, stats, span);
    stats.undefined_leaves_inside = settle_undefined_leaves(cells, numbering, leaves);
    stats.filled_pockets = fill_outside_pockets(cells, numbering, leaves);
    return leaves;
}

}  // namespace pqdc::adaptive_detail
