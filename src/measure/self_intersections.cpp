// Exact self-intersection tests (include/pqdc/self_intersections.hpp).
//
// Every geometric decision is an exact orientation sign, so the tests below
// are exact set-membership statements about closed triangles:
//  - no shared index: two non-coplanar triangles meet iff an edge of one
//    meets the other (the intersection is a segment of the planes' common
//    line whose end points lie on the triangles' boundaries); coplanar ones
//    meet iff two edges cross or a corner of one lies in the other.
//  - one shared corner v: they meet elsewhere iff the side opposite v of one
//    meets the other (the ray from v through any other common point leaves
//    each triangle through its opposite side; the nearer exit lies in both).
//  - a shared side pq: non-coplanar triangles meet only on the line pq,
//    i.e. on pq itself; coplanar ones overlap iff the other corners lie on
//    the same side of pq.
//  - three shared corners: a duplicated face, always reported.
#include "pqdc/self_intersections.hpp"

#include "pqdc/exceptions.hpp"
#include "measure/box_grid.hpp"
#include "measure/default_init.hpp"
#include "measure/flat_stars.hpp"
#include "geometry/exact_predicates.hpp"
#include "geometry/float_rounding.hpp"
#include "measure/mesh_internal.hpp"

#include <nlohmann/json.hpp>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>
#include <vector>

namespace pqdc {

namespace {

using detail::orient2d;
using detail::orient3d;
using Vec3d = openvdb::Vec3d;
using Corners = std::array<Vec3d, 3>;

/// Projection onto the coordinate plane of axes (i, j).
struct Plane2 {
    int i, j;
    int orient(const Vec3d& a, const Vec3d& b, const Vec3d& c) const {
        return orient2d(a[i], a[j], b[i], b[j], c[i], c[j]);
    }
};

constexpr std::array<Plane2, 3> kPlanes{{{0, 1}, {1, 2}, {2, 0}}};
static_assert(kPlanes[0].i == 0 && kPlanes[1].i == 1 && kPlanes[2].i == 2, "a plane's number is its first axis");

/// A coordinate plane onto which the triangle projects with non-zero area:
/// an affine bijection of its plane, so every 2D sign there is the sign in
/// the triangle's own plane (up to one fixed flip). False when there is none:
/// the corners are collinear.
bool find_projection(const Corners& t, Plane2& plane) {
    for (const Plane2& p : kPlanes)
        if (p.orient(t[0], t[1], t[2]) != 0) {
            plane = p;
            return true;
        }
    return false;
}

/// find_projection for a triangle known to be non-degenerate.
Plane2 projection_for(const Corners& t) {
    Plane2 plane = kPlanes[0];
    find_projection(t, plane);
    return plane;
}

/// c collinear with a and b: does it lie on the closed segment ab?
bool within(const Plane2& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    return std::min(a[p.i], b[p.i]) <= c[p.i] && c[p.i] <= std::max(a[p.i], b[p.i]) &&
           std::min(a[p.j], b[p.j]) <= c[p.j] && c[p.j] <= std::max(a[p.j], b[p.j]);
}

bool segments_meet_2d(const Plane2& p, const Vec3d& a, const Vec3d& b, const Vec3d& c, const Vec3d& d) {
    const int o1 = p.orient(a, b, c), o2 = p.orient(a, b, d), o3 = p.orient(c, d, a), o4 = p.orient(c, d, b);
    if (o1 * o2 < 0 && o3 * o4 < 0) return true;
    return (o1 == 0 && within(p, a, b, c)) || (o2 == 0 && within(p, a, b, d)) || (o3 == 0 && within(p, c, d, a)) ||
           (o4 == 0 && within(p, c, d, b));
}

bool point_in_triangle_2d(const Plane2& p, const Vec3d& x, const Corners& t) {
    const int o1 = p.orient(t[0], t[1], x), o2 = p.orient(t[1], t[2], x), o3 = p.orient(t[2], t[0], x);
    return !((o1 > 0 || o2 > 0 || o3 > 0) && (o1 < 0 || o2 < 0 || o3 < 0));
}

bool segment_meets_triangle_2d(const Plane2& p, const Vec3d& a, const Vec3d& b, const Corners& t) {
    if (point_in_triangle_2d(p, a, t) || point_in_triangle_2d(p, b, t)) return true;
    for (int k = 0; k < 3; ++k)
        if (segments_meet_2d(p, a, b, t[k], t[(k + 1) % 3])) return true;
    return false;
}

bool triangles_meet_2d(const Plane2& p, const Corners& s, const Corners& t) {
    for (int k = 0; k < 3; ++k)
        for (int l = 0; l < 3; ++l)
            if (segments_meet_2d(p, s[k], s[(k + 1) % 3], t[l], t[(l + 1) % 3])) return true;
    return point_in_triangle_2d(p, s[0], t) || point_in_triangle_2d(p, t[0], s);
}

/// Segment ab against triangle t, given the signs of a and b against t's plane.
bool segment_meets_triangle(const Vec3d& a, const Vec3d& b, int sa, int sb, const Corners& t) {
    if (sa * sb > 0) return false;
    if (sa == 0 && sb == 0) return segment_meets_triangle_2d(projection_for(t), a, b, t);
    // The line ab meets t's plane in one point, on the segment: it lies in
    // the closed triangle iff the line passes no side of t on the wrong side.
    const int o1 = orient3d(a, b, t[0], t[1]), o2 = orient3d(a, b, t[1], t[2]), o3 = orient3d(a, b, t[2], t[0]);
    return !((o1 > 0 || o2 > 0 || o3 > 0) && (o1 < 0 || o2 < 0 || o3 < 0));
}

bool segment_meets_triangle(const Vec3d& a, const Vec3d& b, const Corners& t) {
    return segment_meets_triangle(a, b, orient3d(t[0], t[1], t[2], a), orient3d(t[0], t[1], t[2], b), t);
}

bool triangles_meet(const Corners& s, const Corners& t) {
    std::array<int, 3> ts{}, st{};
    for (int k = 0; k < 3; ++k) ts[k] = orient3d(s[0], s[1], s[2], t[k]);
    if (ts[0] * ts[1] > 0 && ts[1] * ts[2] > 0) return false;  // t strictly on one side of s's plane
    if (ts[0] == 0 && ts[1] == 0 && ts[2] == 0) return triangles_meet_2d(projection_for(s), s, t);
    for (int k = 0; k < 3; ++k) st[k] = orient3d(t[0], t[1], t[2], s[k]);
    if (st[0] * st[1] > 0 && st[1] * st[2] > 0) return false;
    for (int k = 0; k < 3; ++k) {
        const int l = (k + 1) % 3;
        if (segment_meets_triangle(t[k], t[l], ts[k], ts[l], s)) return true;
        if (segment_meets_triangle(s[k], s[l], st[k], st[l], t)) return true;
    }
    return false;
}

/// Triangles (v, a1, a2) and (v, b1, b2), both non-degenerate in projection
/// p, whose projected angular sectors at v are disjoint but for v: then the
/// projections meet only at v, and as the projection is injective on each
/// triangle, so do the triangles. Cheap 2D signs that spare the exact 3D
/// ones on nearly flat neighbourhoods; false means "undecided".
bool sectors_apart_2d(const Plane2& p, const Vec3d& v, const Vec3d& a1, const Vec3d& a2, const Vec3d& b1,
                      const Vec3d& b2) {
    const int oa = p.orient(v, a1, a2), ob = p.orient(v, b1, b2);
    if (oa == 0 || ob == 0) return false;
    // Sectors are narrower than a half turn: x lies in (y1, y2) iff it is
    // on the inner side of both rays.
    auto within_sector = [&](const Vec3d& x, const Vec3d& y1, const Vec3d& y2, int o) {
        return p.orient(v, y1, x) * o >= 0 && p.orient(v, x, y2) * o >= 0;
    };
    return !within_sector(b1, a1, a2, oa) && !within_sector(b2, a1, a2, oa) && !within_sector(a1, b1, b2, ob) &&
           !within_sector(a2, b1, b2, ob);
}

struct Triangle {
    std::array<unsigned, 3> index;
    Corners corner;
    Plane2 plane = kPlanes[0];  ///< projection_for(corner), computed once
};

/// Both triangles non-degenerate.
bool intersect(const Triangle& s, const Triangle& t) {
    int shared = 0, si = -1, ti = -1;
    std::array<bool, 3> s_shared{}, t_shared{};
    for (int k = 0; k < 3; ++k)
        for (int l = 0; l < 3; ++l)
            if (s.index[k] == t.index[l]) {
                ++shared;
                s_shared[k] = t_shared[l] = true;
                si = k;
                ti = l;
            }
    if (shared == 3) return true;
    if (shared == 0) return triangles_meet(s.corner, t.corner);
    if (shared == 1) {
        const Vec3d &v = s.corner[si], &a1 = s.corner[(si + 1) % 3], &a2 = s.corner[(si + 2) % 3];
        const Vec3d &b1 = t.corner[(ti + 1) % 3], &b2 = t.corner[(ti + 2) % 3];
        // The other triangle strictly on one side of this one's plane (but
        // for v), by the floating-point stage alone: the common case on
        // curved surfaces, two signs instead of the sector test's ten.
        const int o1 = detail::orient3d_if_certain(v, a1, a2, b1), o2 = detail::orient3d_if_certain(v, a1, a2, b2);
        if (o1 != 2 && o1 != 0 && o1 == o2) return false;
        const int o3 = detail::orient3d_if_certain(v, b1, b2, a1), o4 = detail::orient3d_if_certain(v, b1, b2, a2);
        if (o3 != 2 && o3 != 0 && o3 == o4) return false;
        if (sectors_apart_2d(s.plane, v, a1, a2, b1, b2)) return false;
        return segment_meets_triangle(a1, a2, t.corner) || segment_meets_triangle(b1, b2, s.corner);
    }
    const int r = int(std::find(s_shared.begin(), s_shared.end(), false) - s_shared.begin());
    const int w = int(std::find(t_shared.begin(), t_shared.end(), false) - t_shared.begin());
    const Vec3d& p = s.corner[(r + 1) % 3];
    const Vec3d& q = s.corner[(r + 2) % 3];
    // Opposite sides of pq in a projection that keeps s non-degenerate: no
    // overlap if coplanar (the projection is then a bijection of the plane),
    // and none if not. Decided by 2D signs, which stay cheap on the nearly
    // flat pairs where the 3D sign needs exact arithmetic.
    const Plane2& plane = s.plane;
    const int side_s = plane.orient(p, q, s.corner[r]), side_t = plane.orient(p, q, t.corner[w]);
    if (side_s * side_t < 0) return false;
    if (orient3d(p, q, s.corner[r], t.corner[w]) != 0) return false;
    return side_s == side_t;
}

/// They share one corner or one side, at a flat vertex (measure/flat_stars.hpp):
/// then they meet only there, without looking at the corners.
bool settled_by_flat_vertex(const std::array<unsigned, 3>& s, const std::array<unsigned, 3>& t,
                            const std::vector<std::uint8_t>& flat) {
    int shared = 0;
    bool at_flat = false;
    for (int k = 0; k < 3; ++k)
        for (int l = 0; l < 3; ++l)
            if (s[k] == t[l]) {
                ++shared;
                at_flat = at_flat || flat[s[k]];
            }
    return at_flat && shared < 3;
}

void validate(const SelfIntersectionOptions& options) {
    if (options.leaf_triangles < 1 || options.leaf_triangles > 64)
        throw option_error("SelfIntersectionOptions::leaf_triangles = " + std::to_string(options.leaf_triangles) +
                           " is outside [1, 64]");
    if (options.stored_precision != VertexPrecision::float32 && options.stored_precision != VertexPrecision::float64)
        throw option_error("SelfIntersectionOptions::stored_precision = " +
                           std::to_string(int(options.stored_precision)) + " is neither float32 nor float64");
    if (options.broad_phase == BroadPhase::grid)
        throw option_error("SelfIntersectionOptions::broad_phase = grid is not an option: use automatic (the grid "
                           "where it suits the mesh) or tree");
}

/// The mesh's triangles as indices and projection planes; corners are read
/// from the mesh when a triangle is looked at, and indices from its faces
/// (quads split on the fly), not copied: 84 bytes per triangle less, which
/// on meshes of tens of millions of faces is gigabytes.
class Triangles {
public:
    Triangles(const Mesh& mesh, const std::vector<Vec3d>& points) : mesh_(mesh), points_(points) {}
    std::size_t size() const { return plane.size(); }
    std::array<unsigned, 3> index(std::size_t t) const { return detail::split_triangle(mesh_, t); }
    const Vec3d& point(unsigned v) const { return points_[v]; }
    Triangle operator[](std::size_t t) const {
        Triangle view;
        view.index = index(t);
        for (int k = 0; k < 3; ++k) view.corner[k] = points_[view.index[k]];
        view.plane = kPlanes[plane[t]];
        return view;
    }
    detail::UninitializedVector<std::uint8_t> plane;  ///< index into kPlanes (1 byte, not 8)

private:
    const Mesh& mesh_;
    const std::vector<Vec3d>& points_;
};

Triangles gather_triangles(const Mesh& mesh, const std::vector<Vec3d>& points) {
    detail::check_indices(mesh);
    const std::size_t count = detail::split_triangle_count(mesh);
    const std::size_t max_count = std::numeric_limits<std::uint32_t>::max() / 2;  // 32-bit tree indices
    if (count > max_count)
        throw input_error("mesh has " + std::to_string(count) + " triangles (quads count 2); at most " +
                          std::to_string(max_count) + " are supported");
    Triangles triangles(mesh, points);
    triangles.plane.assign(count, 0);  // kPlanes[0] until the degeneracy pass finds the projection
    return triangles;
}

bool finite(const Triangle& t) {
    for (const Vec3d& p : t.corner)
        if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) return false;
    return true;
}

/// A repeated index or collinear corners; else `plane` is its projection.
bool degenerate(const Triangle& t, Plane2& plane) {
    const auto& i = t.index;
    return i[0] == i[1] || i[1] == i[2] || i[2] == i[0] || !find_projection(t.corner, plane);
}


using Pair = std::pair<std::size_t, std::size_t>;

/// Reports the fraction done: the cancellation point.
void report(const SelfIntersectionOptions& options, double fraction) { detail::report_progress(options, fraction); }

/// A cancellation point between the set-up steps (reports 0 done).
void checkpoint(const SelfIntersectionOptions& options) { report(options, 0.0); }

/// Runs body(first, last) over [0, n) in about `batches` consecutive
/// batches, reporting between them (the cancellation points); one batch
/// without a progress hook. Each batch is one parallel loop, so a batch
/// needs several chunks to keep the threads busy.
template <class Body>
void in_batches(std::size_t n, const SelfIntersectionOptions& options, const Body& body, std::size_t batches = 64) {
    const std::size_t step =
        options.progress ? std::max<std::size_t>(1, (n + batches - 1) / batches) : std::max<std::size_t>(n, 1);
    for (std::size_t first = 0; first < n; first += step) {
        body(first, std::min(n, first + step));
        report(options, double(std::min(n, first + step)) / double(n));
    }
}

/// The triangles u > t, not skipped, whose tree leaves' boxes meet t's box.
void tree_candidates(const std::vector<detail::BoxNode>& nodes, const std::vector<std::uint32_t>& order,
                     const std::vector<detail::Box>& boxes, const std::vector<char>& skip, std::size_t t,
                     std::vector<std::uint32_t>& candidates) {
    candidates.clear();
    std::array<std::uint32_t, 64> stack;  // depth <= 33 for 2^32 triangles, one pending sibling per level
    int top = 0;
    stack[top++] = 0;
    while (top > 0) {
        const detail::BoxNode& node = nodes[stack[--top]];
        if (!detail::boxes_overlap(boxes[t], node.lo, node.hi)) continue;
        if (node.triangle_count == 0) {
            stack[top++] = std::uint32_t(&node - nodes.data()) + 1;
            stack[top++] = node.second_child_or_first_triangle;
            continue;
        }
        const std::uint32_t first = node.second_child_or_first_triangle;
        for (std::uint32_t i = first; i < first + node.triangle_count; ++i) {
            const std::uint32_t u = order[i];
            if (u > t && !skip[u]) candidates.push_back(u);
        }
    }
}

/// Overlapping pairs from the box tree, tested exactly: fixed blocks of
/// first triangles, each listing its pairs in (first, second) order, so the
/// joined lists are sorted whatever the thread schedule.
void tree_pairs(const Triangles& triangles, const std::vector<detail::Box>& boxes, const std::vector<char>& skip,
                const std::vector<std::uint8_t>& flat, const SelfIntersectionOptions& options,
                SelfIntersections& result) {
    const std::size_t count = triangles.size();
    std::vector<Corners> corners(count);
    for (std::size_t t = 0; t < count; ++t) {
        corners[t] = triangles[t].corner;
        if (skip[t] == 2) corners[t].fill(Vec3d(0.0));  // NaN boxes would poison the tree
    }
    std::vector<detail::BoxNode> nodes;
    detail::BoxTreeBuilder builder(corners, options.leaf_triangles);
    builder.build(nodes);
    const std::vector<std::uint32_t>& order = builder.order();

    constexpr std::size_t kBlock = 512;
    const std::size_t blocks = (count + kBlock - 1) / kBlock;
    std::vector<std::vector<Pair>> found(blocks);
    std::vector<std::size_t> found_count(blocks, 0);
    in_batches(blocks, options, [&](std::size_t first_block, std::size_t last_block) {
        tbb::parallel_for(tbb::blocked_range<std::size_t>(first_block, last_block, 1), [&](const auto& r) {
            std::vector<std::uint32_t> candidates;
            for (std::size_t b = r.begin(); b != r.end(); ++b) {
                for (std::size_t t = b * kBlock; t < std::min(count, (b + 1) * kBlock); ++t) {
                    if (skip[t]) continue;
                    tree_candidates(nodes, order, boxes, skip, t, candidates);
                    std::sort(candidates.begin(), candidates.end());
                    for (const std::uint32_t u : candidates) {
                        if (!detail::boxes_overlap(boxes[t], boxes[u])) continue;
                        if (settled_by_flat_vertex(triangles.index(t), triangles.index(u), flat) ||
                            !intersect(triangles[t], triangles[u]))
                            continue;
                        if (found[b].size() < options.max_pairs) found[b].emplace_back(t, u);
                        ++found_count[b];
                    }
                }
            }
        });
    });
    for (std::size_t b = 0; b < blocks; ++b) {
        result.pair_count += found_count[b];
        for (const auto& pair : found[b]) {
            if (result.pairs.size() >= options.max_pairs) break;
            result.pairs.push_back(pair);
        }
    }
}

detail::Box box_of(const Triangles& triangles, std::size_t t) {
    const std::array<unsigned, 3> i = triangles.index(t);
    return detail::bounding_box(triangles.point(i[0]), triangles.point(i[1]), triangles.point(i[2]));
}

/// A run of consecutive triangles [begin, end) and the bounds of those not
/// skipped (empty when all are): the unit in which parts look for nearby
/// triangles.
struct Block {
    std::size_t begin = 0, end = 0;
    bool empty = true;
    detail::Box box;
};

bool blocks_meet(const Block& a, const Block& b) { return !a.empty && !b.empty && detail::boxes_overlap(a.box, b.box); }

std::vector<Block> split_into_blocks(const Triangles& triangles, const std::vector<char>& skip,
                                     std::size_t block_triangles) {
    const std::size_t count = triangles.size();
    std::vector<Block> blocks((count + block_triangles - 1) / block_triangles);
    tbb::parallel_for(std::size_t(0), blocks.size(), [&](std::size_t k) {
        Block& block = blocks[k];
        block.begin = k * block_triangles;
        block.end = std::min(count, block.begin + block_triangles);
        for (std::size_t t = block.begin; t < block.end; ++t) {
            if (skip[t]) continue;
            const detail::Box box = box_of(triangles, t);
            if (block.empty) block.box = box;
            block.empty = false;
            block.box.lo = openvdb::math::minComponent(block.box.lo, box.lo);
            block.box.hi = openvdb::math::maxComponent(block.box.hi, box.hi);
        }
    });
    return blocks;
}

/// One part: its own blocks [first, last), and each later block whose box
/// meets some of them, with the own blocks it meets.
struct Part {
    std::size_t first = 0, last = 0;
    std::vector<std::pair<std::size_t, std::vector<std::uint32_t>>> near;
    std::size_t scanned = 0;  ///< triangles in the near blocks
};

Part plan_part(const std::vector<Block>& blocks, std::size_t first, std::size_t last) {
    Part part;
    part.first = first;
    part.last = last;
    for (std::size_t j = last; j < blocks.size(); ++j) {
        std::vector<std::uint32_t> own;
        for (std::size_t o = first; o < last; ++o)
            if (blocks_meet(blocks[o], blocks[j])) own.push_back(std::uint32_t(o));
        if (own.empty()) continue;
        part.scanned += blocks[j].end - blocks[j].begin;
        part.near.emplace_back(j, std::move(own));
    }
    return part;
}

/// Parts of `blocks_per_part` blocks; one part when parts do not pay: in an
/// order that is not spatially coherent (a shuffled soup) every part meets
/// most later blocks, and parts would only repeat the scans.
std::vector<Part> plan_parts(const std::vector<Block>& blocks, std::size_t blocks_per_part, std::size_t count) {
    std::vector<Part> parts;
    std::size_t scanned = 0;
    for (std::size_t first = 0; first < blocks.size() && scanned <= 2 * count; first += blocks_per_part) {
        parts.push_back(plan_part(blocks, first, std::min(blocks.size(), first + blocks_per_part)));
        scanned += parts.back().scanned;
    }
    if (scanned > 2 * count) return {plan_part(blocks, 0, blocks.size())};
    return parts;
}

/// The triangles of one part's grid, ascending, and their boxes. Reused
/// from part to part (fresh arrays per part fragment the heap).
struct Members {
    std::vector<std::uint32_t> id;
    std::vector<detail::Box> box;
    std::vector<std::size_t> first;  ///< per scanned block: its first member
};

/// The part's own triangles (not skipped), then those of its near blocks
/// whose boxes meet one of the own blocks they were listed for: all later
/// triangles that can meet one of the part's. Boxes are computed here, part
/// by part, rather than kept for the whole mesh (24 bytes per triangle):
/// counted per block, then written at each block's offset, so the order
/// does not depend on the threads.
void part_members(const std::vector<Block>& blocks, const Part& part, const Triangles& triangles,
                  const std::vector<char>& skip, Members& members) {
    struct Scan {
        const Block* block;
        const std::vector<std::uint32_t>* own;  ///< null: the part's own block
    };
    std::vector<Scan> scans;
    for (std::size_t o = part.first; o < part.last; ++o) scans.push_back({&blocks[o], nullptr});
    for (const auto& near : part.near) scans.push_back({&blocks[near.first], &near.second});
    // A near triangle is taken when its box meets one of the own blocks it
    // was listed for; own triangles are taken unless skipped.
    auto near_taken = [&](const Scan& scan, std::size_t t) {
        if (skip[t]) return false;
        const detail::Box box = box_of(triangles, t);
        for (std::uint32_t o : *scan.own)
            if (detail::boxes_overlap(box, blocks[o].box)) return true;
        return false;
    };
    members.first.assign(scans.size() + 1, 0);
    tbb::parallel_for(std::size_t(0), scans.size(), [&](std::size_t b) {
        std::size_t n = 0;
        for (std::size_t t = scans[b].block->begin; t < scans[b].block->end; ++t)
            n += scans[b].own ? near_taken(scans[b], t) : !skip[t];
        members.first[b + 1] = n;
    });
    std::partial_sum(members.first.begin(), members.first.end(), members.first.begin());
    members.id.resize(members.first.back());
    members.box.resize(members.first.back());
    tbb::parallel_for(std::size_t(0), scans.size(), [&](std::size_t b) {
        std::size_t m = members.first[b];
        for (std::size_t t = scans[b].block->begin; t < scans[b].block->end; ++t)
            if (scans[b].own ? near_taken(scans[b], t) : !skip[t]) {
                members.id[m] = std::uint32_t(t);
                members.box[m++] = box_of(triangles, t);
            }
    });
}

/// Triangles per block (see Block).
constexpr std::size_t kBlockTriangles = 1 << 14;

/// The pairs from the uniform grid (measure/box_grid.hpp), part by part:
/// consecutive runs of `part_triangles` triangles, each with a grid of its
/// own triangles and the later ones near it, reporting the pairs whose
/// first triangle is its own. Pairs are sorted at the end, so the result
/// does not depend on the parts. On meshes in spatial order (every mesh pqdc
/// extracts: leaf order) the grid's arrays then scale with the part, not the
/// mesh. False when a grid does not suit its boxes (use the tree).
bool grid_pairs(const Triangles& triangles, const std::vector<char>& skip, const std::vector<std::uint8_t>& flat,
                const SelfIntersectionOptions& options, std::size_t part_triangles, SelfIntersections& result,
                std::size_t& parts_used) {
    const std::size_t block_triangles = std::min(kBlockTriangles, part_triangles);
    const std::vector<Block> blocks = split_into_blocks(triangles, skip, block_triangles);
    const std::vector<Part> parts =
        plan_parts(blocks, (part_triangles + block_triangles - 1) / block_triangles, triangles.size());
    parts_used = parts.size();
    std::vector<Pair> all;
    Members members;
    detail::BoxGrid grid;
    for (std::size_t k = 0; k < parts.size(); ++k) {
        SelfIntersectionOptions part_options = options;  // progress of the whole, not of the part
        if (options.progress) {
            const double n = double(parts.size());
            part_options.progress = [&options, k, n](double f) { return options.progress((double(k) + f) / n); };
        }
        part_members(blocks, parts[k], triangles, skip, members);
        if (members.id.empty()) continue;
        if (!grid.build(members.box, [&] { checkpoint(part_options); })) return false;
        const std::size_t own_end = blocks[parts[k].last - 1].end;
        std::vector<std::vector<Pair>> found(grid.chunk_count());
        const std::size_t batches = std::max<std::size_t>(1, 64 / parts.size());  // about 64 reports in all
        in_batches(grid.chunk_count(), part_options, [&](std::size_t first, std::size_t last) {
            // Only the corner indices are loaded per cell: most pairs are
            // settled by a flat vertex, and only the rest fetch their corners.
            const auto load = [&](std::uint32_t m) { return triangles.index(members.id[m]); };
            using Index = std::array<unsigned, 3>;
            // Member numbers ascend with triangle numbers: a < b.
            grid.for_each_pair(members.box, first, last, load,
                               [&](std::size_t chunk, std::uint32_t i, std::uint32_t j, const Index& ia, const Index& ib) {
                                   const std::uint32_t a = members.id[i], b = members.id[j];
                                   if (a < own_end && !settled_by_flat_vertex(ia, ib, flat) &&
                                       intersect(triangles[a], triangles[b]))
                                       found[chunk].emplace_back(a, b);
                               });
        }, batches);
        for (const auto& f : found) all.insert(all.end(), f.begin(), f.end());
    }
    tbb::parallel_sort(all.begin(), all.end());
    result.pair_count = all.size();
    if (all.size() > options.max_pairs) all.resize(options.max_pairs);
    result.pairs = std::move(all);
    result.broad_phase = BroadPhase::grid;
    return true;
}

}  // namespace

namespace {

/// Split triangle t with its corners, its projection not yet chosen.
Triangle split_triangle_at(const Mesh& mesh, const std::vector<Vec3d>& points, std::size_t t) {
    Triangle view;
    view.index = detail::split_triangle(mesh, t);
    for (int k = 0; k < 3; ++k) view.corner[k] = points[view.index[k]];
    return view;
}

/// split_triangle_at() of a usable triangle, with its projection: what
/// intersect() reads.
Triangle usable_split_triangle(const Mesh& mesh, const std::vector<Vec3d>& points, std::size_t t) {
    Triangle view = split_triangle_at(mesh, points, t);
    view.plane = projection_for(view.corner);
    return view;
}

}  // namespace

int detail::classify_split_triangle(const Mesh& mesh, const std::vector<Vec3d>& points, std::size_t t) {
    const Triangle triangle = split_triangle_at(mesh, points, t);
    Plane2 plane = kPlanes[0];
    return !finite(triangle) ? 2 : degenerate(triangle, plane) ? 1 : 0;
}

bool detail::split_triangles_intersect(const Mesh& mesh, const std::vector<Vec3d>& points, std::size_t s,
                                       std::size_t t) {
    return intersect(usable_split_triangle(mesh, points, s), usable_split_triangle(mesh, points, t));
}

void detail::intersecting_pairs_among(const Mesh& mesh, const std::vector<Vec3d>& points,
                                      const std::vector<std::uint32_t>& ids,
                                      std::vector<std::pair<std::size_t, std::size_t>>& pairs) {
    std::vector<Triangle> prepared;
    prepared.reserve(ids.size());
    for (std::uint32_t t : ids) prepared.push_back(usable_split_triangle(mesh, points, t));
    for (std::size_t a = 0; a < ids.size(); ++a)
        for (std::size_t b = a + 1; b < ids.size(); ++b)
            if (intersect(prepared[a], prepared[b])) pairs.emplace_back(ids[a], ids[b]);
}

SelfIntersections find_self_intersections(const Mesh& mesh, const SelfIntersectionOptions& options) {
    if (options.stored_precision != VertexPrecision::float32)
        return detail::find_self_intersections_at(mesh, mesh.points, options);
    std::vector<Vec3d> stored(mesh.points.size());
    tbb::parallel_for(std::size_t(0), stored.size(), [&](std::size_t i) { stored[i] = detail::rounded_to_float(mesh.points[i]); });
    return detail::find_self_intersections_at(mesh, stored, options);
}

SelfIntersections detail::find_self_intersections_at(const Mesh& mesh, const std::vector<Vec3d>& points,
                                                     const SelfIntersectionOptions& options) {
    return find_self_intersections_at(mesh, points, options, kGridPartTriangles);
}

SelfIntersections detail::find_self_intersections_at(const Mesh& mesh, const std::vector<Vec3d>& points,
                                                     const SelfIntersectionOptions& options,
                                                     std::size_t part_triangles, std::size_t* parts_used) {
    if (points.size() != mesh.points.size())
        throw std::invalid_argument("find_self_intersections_at: " + std::to_string(points.size()) +
                                    " points for a mesh of " + std::to_string(mesh.points.size()));
    validate(options);
    Triangles triangles = gather_triangles(mesh, points);
    const std::size_t count = triangles.size();
    SelfIntersections result;
    result.triangle_count = count;
    if (count == 0) return result;
    checkpoint(options);

    // skip: 1 degenerate, 2 non-finite.
    std::vector<char> skip(count, 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 4096), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t t = r.begin(); t != r.end(); ++t) {
            const Triangle triangle = triangles[t];
            Plane2 plane = kPlanes[0];
            skip[t] = !finite(triangle) ? 2 : degenerate(triangle, plane) ? 1 : 0;
            triangles.plane[t] = std::uint8_t(plane.i);  // kPlanes[k].i == k
        }
    });
    for (std::size_t t = 0; t < count; ++t) {
        if (skip[t] == 1) result.degenerate_triangles.push_back(t);
        if (skip[t] == 2) ++result.non_finite_triangle_count;
    }
    checkpoint(options);
    const std::vector<std::uint8_t> flat = detail::find_flat_vertices(mesh, points, skip);
    checkpoint(options);
    std::size_t parts = 0;
    if (options.broad_phase != BroadPhase::automatic ||
        !grid_pairs(triangles, skip, flat, options, std::max<std::size_t>(part_triangles, 1), result, parts)) {
        parts = 0;
        result.pair_count = 0;
        result.pairs.clear();
        result.broad_phase = BroadPhase::tree;
        std::vector<detail::Box> boxes(count);
        tbb::parallel_for(std::size_t(0), count, [&](std::size_t t) { boxes[t] = box_of(triangles, t); });
        tree_pairs(triangles, boxes, skip, flat, options, result);
    }
    if (parts_used) *parts_used = parts;
    return result;
}

std::string to_json(const SelfIntersections& r) {
    nlohmann::ordered_json first_pairs = nlohmann::ordered_json::array();
    for (std::size_t i = 0; i < std::min<std::size_t>(10, r.pairs.size()); ++i)
        first_pairs.push_back({r.pairs[i].first, r.pairs[i].second});
    return nlohmann::ordered_json{{"triangle_count", r.triangle_count},
                                  {"pair_count", r.pair_count},
                                  {"degenerate_triangle_count", r.degenerate_triangles.size()},
                                  {"non_finite_triangle_count", r.non_finite_triangle_count},
                                  {"first_pairs", std::move(first_pairs)}}
        .dump();
}

}  // namespace pqdc
