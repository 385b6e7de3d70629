#include "adaptive/polygonize.hpp"

#include "adaptive/collapse.hpp"
#include "adaptive/crease_splits.hpp"
#include "adaptive/leaf_sides.hpp"
#include "adaptive/shape_limits.hpp"
#include "adaptive/repair.hpp"
#include "lattice/crossings.hpp"
#include "lattice/cube.hpp"
#include "measure/mesh_internal.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace pqdc::adaptive_detail {
namespace {

using openvdb::Vec3d;
using detail::edge_end_corner;
using detail::edge_start_corner;

std::uint64_t pair_key(std::uint32_t a, std::uint32_t b) {
    return a < b ? std::uint64_t(a) << 32 | b : std::uint64_t(b) << 32 | a;
}

constexpr std::size_t kGrain = 8192;  // dual cells per chunk
constexpr std::size_t kChunksPerReport = 16;
constexpr std::size_t kItemsPerReport = 1 << 17;  // crossings

/// Step 2: sign masks of the dual cells and the sorted, unique dual edges
/// (leaf pairs) that cross, with an index of the pairs' runs by smaller leaf.
struct DualCrossings {
    std::vector<std::uint8_t> mask;
    std::vector<std::uint64_t> pairs;
    std::vector<std::uint32_t> pair_first;

    /// The crossing (vertex) id of a leaf pair: a search in the smaller
    /// leaf's few crossings instead of all of them.
    std::uint32_t vertex_id(std::uint64_t key) const {
        const auto begin = pairs.begin() + pair_first[key >> 32], end = pairs.begin() + pair_first[(key >> 32) + 1];
        return std::uint32_t(std::lower_bound(begin, end, key) - pairs.begin());
    }
};

DualCrossings dual_crossings(const std::vector<DualCell>& cells, const std::vector<std::uint8_t>& inside,
                             const detail::ProgressSpan& span) {
    const std::size_t n_cells = cells.size(), n_chunks = (n_cells + kGrain - 1) / kGrain;
    DualCrossings d;
    d.mask.resize(n_cells);
    std::vector<std::vector<std::uint64_t>> chunk_pairs(n_chunks);
    detail::parallel_ranges(n_chunks, 1, kChunksPerReport, span.part(0.0, 0.7),
                            [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t chunk = r.begin(); chunk != r.end(); ++chunk) {
            std::vector<std::uint64_t>& pairs = chunk_pairs[chunk];
            const std::size_t end = std::min(n_cells, (chunk + 1) * kGrain);
            for (std::size_t c = chunk * kGrain; c < end; ++c) {
                unsigned m = 0;
                for (int i = 0; i < 8; ++i)
                    if (inside[cells[c][i]]) m |= 1u << i;
                d.mask[c] = std::uint8_t(m);
                const detail::CubeLoops& loops = detail::cube_loops(std::uint8_t(m));
                for (int l = 0; l < loops.count; ++l)
                    for (int k = 0; k < loops.size[l]; ++k) {
                        const int e = loops.edge[l][k];
                        pairs.push_back(pair_key(cells[c][edge_start_corner(e)], cells[c][edge_end_corner(e)]));
                    }
            }
            std::sort(pairs.begin(), pairs.end());
            pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
        }
    });
    for (auto& p : chunk_pairs) {
        d.pairs.insert(d.pairs.end(), p.begin(), p.end());
        std::vector<std::uint64_t>().swap(p);
    }
    tbb::parallel_sort(d.pairs.begin(), d.pairs.end());
    d.pairs.erase(std::unique(d.pairs.begin(), d.pairs.end()), d.pairs.end());
    d.pair_first.assign(inside.size() + 1, 0);
    for (std::uint64_t key : d.pairs) ++d.pair_first[(key >> 32) + 1];
    for (std::size_t i = 0; i < inside.size(); ++i) d.pair_first[i + 1] += d.pair_first[i];
    return d;
}

/// Step 3. An edge from a surface leaf crosses at the leaf's vertex: it lies
/// on the surface up to the merge error and is the feature-preserving
/// position, while a root of the field along the edge would only add a
/// sliver next to it. Edges between two empty leaves (where the surface
/// leaves the domain) are root-found on the field.
std::vector<Vec3d> place_crossings(const std::vector<std::uint64_t>& pairs, const LeafVertices& leaves,
                                   const FieldSource& field, const detail::ProgressSpan& span) {
    std::vector<Vec3d> points(pairs.size());
    detail::parallel_ranges(pairs.size(), 512, kItemsPerReport, span, [&](const tbb::blocked_range<std::size_t>& r) {
        auto probe = field.probe();
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            std::uint32_t a = std::uint32_t(pairs[i] >> 32), b = std::uint32_t(pairs[i]);
            if (!leaves.inside[a]) std::swap(a, b);
            const Vec3d pa = leaves.position[a], pb = leaves.position[b];
            if (leaves.is_surface[a] || !(leaves.value[a] < 0 && leaves.value[b] >= 0)) {
                points[i] = pa;
                continue;
            }
            const double len = (pb - pa).length();
            const double tol = len > 0 ? 1e-7 / len : 1.0;
            const double t = detail::root_on_unit_interval([&](double s) { return probe->value(pa + (pb - pa) * s); },
                                                           leaves.value[a], leaves.value[b], tol);
            points[i] = pa + (pb - pa) * t;
        }
    });
    return points;
}

/// A loop corner: a crossing and the dual cell's faces holding its dual edge(s).
struct Corner {
    std::uint32_t id;
    unsigned faces;  ///< bit 2d + side
};

/// Step 4 for one chunk of dual cells: each loop's crossings, with repeated
/// vertices (crossings on the same pair of leaves, from degenerate dual
/// cells) removed, split into simple loops and triangulated. A loop's
/// triangulation must not add an edge between two crossings on a common face
/// of the dual cell: the neighbour across that face may hold the same two
/// crossings (ambiguous faces, degenerate cells) and add the same edge.
class LoopTriangulator {
public:
    static constexpr std::uint32_t kExtra = 0x80000000u;  ///< chunk-local centroid vertex

    LoopTriangulator(const std::vector<Vec3d>& points, const FieldSource& field, FaceType faces)
        : points_(points), probe_(field.probe()), faces_(faces) {}

    std::vector<openvdb::Vec3I> tris;
    std::vector<openvdb::Vec4I> quads;          ///< 4-corner loops (FaceType::quads)
    std::vector<std::uint32_t> quad_first_tri;  ///< first triangle of each quad
    std::vector<Vec3d> extra;                   ///< added centroid vertices

    void cell(const DualCell& cell, std::uint8_t mask, const DualCrossings& d) {
        const detail::CubeLoops& loops = detail::cube_loops(mask);
        for (int l = 0; l < loops.count; ++l) {
            Corner ids[12];
            int n = 0;
            for (int k = 0; k < loops.size[l]; ++k) {
                const int e = loops.edge[l][k];
                const int c0 = edge_start_corner(e), c1 = edge_end_corner(e);
                const int axis = e / 4, p = axis == 0 ? 1 : 0, q = axis == 2 ? 1 : 2;
                const unsigned faces_of_edge = 1u << (2 * p + (c0 >> p & 1)) | 1u << (2 * q + (c0 >> q & 1));
                const std::uint32_t id = d.vertex_id(pair_key(cell[c0], cell[c1]));
                if (n > 0 && ids[n - 1].id == id)
                    ids[n - 1].faces |= faces_of_edge;
                else
                    ids[n++] = Corner{id, faces_of_edge};
            }
            while (n > 1 && ids[n - 1].id == ids[0].id) ids[0].faces |= ids[--n].faces;
            split_and_emit(ids, n);
        }
    }

private:
    /// Splits at vertices that repeat non-consecutively into simple loops.
    void split_and_emit(const Corner* ids, int n) {
        Corner stack[16][12];
        int stack_n[16], depth = 0;
        std::copy(ids, ids + n, stack[0]);
        stack_n[depth++] = n;
        while (depth > 0) {
            --depth;
            Corner loop[12];
            const int m = stack_n[depth];
            std::copy(stack[depth], stack[depth] + m, loop);
            int si = -1, sj = -1;
            for (int i = 0; i < m && si < 0; ++i)
                for (int j = i + 1; j < m; ++j)
                    if (loop[i].id == loop[j].id) {
                        si = i;
                        sj = j;
                        break;
                    }
            if (si < 0) {
                emit(loop, m);
                continue;
            }
            loop[si].faces |= loop[sj].faces;
            loop[sj].faces = loop[si].faces;
            stack_n[depth] = 0;
            for (int i = si; i < sj; ++i) stack[depth][stack_n[depth]++] = loop[i];
            ++depth;
            stack_n[depth] = 0;
            for (int i = sj; i < m; ++i) stack[depth][stack_n[depth]++] = loop[i];
            for (int i = 0; i < si; ++i) stack[depth][stack_n[depth]++] = loop[i];
            ++depth;
        }
    }

    /// The safe apex whose worst fan triangle is fattest (area over squared
    /// longest side), so collinear corners get no sliver; -1 when none is safe.
    int best_apex(const Corner* loop, int m) const {
        int apex = -1;
        double best = -1;
        for (int k = 0; k < m; ++k) {
            bool safe = true;
            for (int j = 0; j < m && safe; ++j) {
                if (j == k || j == (k + 1) % m || k == (j + 1) % m) continue;
                safe = (loop[k].faces & loop[j].faces) == 0;
            }
            if (!safe) continue;
            double worst = std::numeric_limits<double>::infinity();
            for (int i = 1; i + 1 < m; ++i) {
                const Vec3d& a = points_[loop[k].id];
                const Vec3d& b = points_[loop[(k + i) % m].id];
                const Vec3d& c = points_[loop[(k + i + 1) % m].id];
                const double side2 = std::max({(b - a).lengthSqr(), (c - b).lengthSqr(), (a - c).lengthSqr()});
                worst = std::min(worst, side2 > 0 ? (b - a).cross(c - a).length() / side2 : 0.0);
            }
            if (worst > best) {
                best = worst;
                apex = k;
            }
        }
        return apex;
    }

    void emit(const Corner* loop, int m) {
        if (m < 3) return;
        if (m == 3) {
            tris.emplace_back(loop[0].id, loop[1].id, loop[2].id);
            return;
        }
        if (m == 4 && faces_ == FaceType::quads) {
            // Triangulated like any loop (the collapse works on triangles)
            // and joined again afterwards if both halves survive.
            quads.emplace_back(loop[0].id, loop[1].id, loop[2].id, loop[3].id);
            quad_first_tri.push_back(std::uint32_t(tris.size()));
        }
        const int apex = best_apex(loop, m);
        if (apex >= 0) {
            for (int i = 1; i + 1 < m; ++i)
                tris.emplace_back(loop[apex].id, loop[(apex + i) % m].id, loop[(apex + i + 1) % m].id);
            return;
        }
        // Else a fan around the loop's centroid, projected onto the surface.
        Vec3d centroid(0.0);
        double reach = 0;
        for (int i = 0; i < m; ++i) centroid += points_[loop[i].id];
        centroid /= double(m);
        for (int i = 0; i < m; ++i) reach = std::max(reach, (points_[loop[i].id] - centroid).length());
        const std::uint32_t c = kExtra | std::uint32_t(extra.size());
        extra.push_back(project_to_surface(*probe_, centroid, reach));
        for (int i = 0; i < m; ++i) tris.emplace_back(c, loop[i].id, loop[(i + 1) % m].id);
    }

    const std::vector<Vec3d>& points_;
    std::unique_ptr<FieldProbe> probe_;
    FaceType faces_;
};

/// Triangles of every loop (in dual-cell order), the quads they came from,
/// and the added centroid vertices appended to `points`.
struct LoopFaces {
    std::vector<openvdb::Vec3I> tris;
    std::vector<openvdb::Vec4I> quads;
    std::vector<std::uint32_t> quad_tri;
};

LoopFaces triangulate_loops(const std::vector<DualCell>& cells, const DualCrossings& d, const FieldSource& field,
                            FaceType faces, std::vector<Vec3d>& points, AdaptiveStats& stats,
                            const detail::ProgressSpan& span) {
    const std::size_t n_cells = cells.size(), n_chunks = (n_cells + kGrain - 1) / kGrain;
    std::vector<std::unique_ptr<LoopTriangulator>> chunks(n_chunks);
    detail::parallel_ranges(n_chunks, 1, kChunksPerReport, span, [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t chunk = r.begin(); chunk != r.end(); ++chunk) {
            chunks[chunk] = std::make_unique<LoopTriangulator>(points, field, faces);
            const std::size_t end = std::min(n_cells, (chunk + 1) * kGrain);
            for (std::size_t c = chunk * kGrain; c < end; ++c) chunks[chunk]->cell(cells[c], d.mask[c], d);
        }
    });
    std::vector<std::uint32_t> extra_base(n_chunks);
    std::uint32_t base = std::uint32_t(points.size());
    for (std::size_t ch = 0; ch < n_chunks; ++ch) {
        extra_base[ch] = base;
        base += std::uint32_t(chunks[ch]->extra.size());
        stats.added_vertices += chunks[ch]->extra.size();
        points.insert(points.end(), chunks[ch]->extra.begin(), chunks[ch]->extra.end());
    }
    LoopFaces out;
    for (std::size_t ch = 0; ch < n_chunks; ++ch) {
        LoopTriangulator& t = *chunks[ch];
        for (auto& tri : t.tris)
            for (int k = 0; k < 3; ++k)
                if (tri[k] & LoopTriangulator::kExtra) tri[k] = extra_base[ch] + (tri[k] & ~LoopTriangulator::kExtra);
        const std::uint32_t first = std::uint32_t(out.tris.size());
        out.tris.insert(out.tris.end(), t.tris.begin(), t.tris.end());
        out.quads.insert(out.quads.end(), t.quads.begin(), t.quads.end());
        for (std::uint32_t q : t.quad_first_tri) out.quad_tri.push_back(first + q);
        chunks[ch].reset();
    }
    return out;
}

/// Step 5's tiles: the octree root of each crossing's surface leaf.
std::vector<std::uint64_t> crossing_tiles(const Octree& tree, const LeafNumbering& numbering,
                                          const std::vector<std::uint64_t>& pairs, const LeafVertices& leaves,
                                          std::size_t n_points) {
    std::vector<std::uint64_t> tile(n_points, kNoTile);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, pairs.size(), 4096),
                      [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            std::uint32_t a = std::uint32_t(pairs[i] >> 32), b = std::uint32_t(pairs[i]);
            if (!leaves.inside[a]) std::swap(a, b);
            if (!leaves.is_surface[a]) continue;
            int level = 0;
            while (level < tree.top && numbering.node_first[level + 1] <= a) ++level;
            const std::uint64_t code = tree.levels[level].code[a - numbering.node_first[level]];
            tile[i] = code >> (3 * (tree.top - level));
        }
    });
    return tile;
}

/// The corners of the triangles with a corner in a cell that stage
/// "untangle" pinned (none without pinned cells).
std::vector<std::uint8_t> pinned_corners(const Octree& tree, const PinnedCells& pinned,
                                         const std::vector<Vec3d>& points, const std::vector<openvdb::Vec3I>& tris) {
    std::vector<std::uint8_t> near(points.size(), 0);
    if (pinned.size() == 0) return near;
    std::vector<std::uint8_t> in_pinned(tris.size(), 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, tris.size(), 4096), [&](const auto& r) {
        for (std::size_t t = r.begin(); t != r.end(); ++t)
            for (int k = 0; k < 3 && !in_pinned[t]; ++k)
                in_pinned[t] = pinned.pinned(tree, openvdb::Coord::floor(points[tris[t][k]]));
    });
    for (std::size_t t = 0; t < tris.size(); ++t)
        if (in_pinned[t])
            for (int k = 0; k < 3; ++k) near[tris[t][k]] = 1;
    return near;
}

/// `mask` grown by `rings` rings of triangles: every corner of a triangle
/// with a marked corner is marked, `rings` times.
void grow_by_rings(std::vector<std::uint8_t>& mask, const std::vector<openvdb::Vec3I>& tris,
                   const std::vector<std::uint8_t>& alive, int rings) {
    for (int ring = 0; ring < rings; ++ring) {
        std::vector<std::uint8_t> grown = mask;
        for (std::size_t t = 0; t < tris.size(); ++t) {
            const openvdb::Vec3I& c = tris[t];
            if (alive[t] && (mask[c[0]] || mask[c[1]] || mask[c[2]]))
                for (int k = 0; k < 3; ++k) grown[c[k]] = 1;
        }
        mask.swap(grown);
    }
}

/// The triangles angle flips must leave alone: both halves of each quad
/// (so that it can be joined again), and around the cells stage "untangle"
/// pinned, every triangle with a corner in a pinned cell and every triangle
/// sharing a vertex with one of those (`pinned_near`: pinned_corners).
std::vector<std::uint8_t> frozen_for_flips(const LoopFaces& loops, const std::vector<std::uint8_t>& pinned_near) {
    std::vector<std::uint8_t> frozen(loops.tris.size(), 0);
    for (std::uint32_t t : loops.quad_tri) frozen[t] = frozen[t + 1] = 1;
    for (std::size_t t = 0; t < loops.tris.size(); ++t)
        for (int k = 0; k < 3; ++k) frozen[t] = frozen[t] | pinned_near[loops.tris[t][k]];
    return frozen;
}

/// The vertices tangential relaxation may move: those within two triangles
/// of a corner on a merged leaf (or of an added centre), where dual cells of
/// different sizes meet and make the thin triangles, but none of a triangle
/// that touches a pinned cell's triangles (`pinned_near`: pinned_corners),
/// as for the flips: the rebuild must not move an intersection back in.
/// (Three rings instead of one made no difference in the procedural sweep.)
/// Among finest leaves farther away the mesh stays the uniform extractor's
/// (max_error 0 merges nothing, so nothing moves). The crease vertices that
/// split_at_concave_creases added (from `first_split` on) count as finest.
std::vector<std::uint8_t> relaxable_vertices(const Octree& tree, const LeafNumbering& numbering,
                                             const std::vector<std::uint64_t>& pairs, const LeafVertices& leaves,
                                             std::size_t point_count, std::size_t first_split,
                                             const std::vector<openvdb::Vec3I>& tris,
                                             const std::vector<std::uint8_t>& alive,
                                             std::vector<std::uint8_t> pinned_near) {
    std::vector<std::uint8_t> near(point_count, 1);  // added centres (after the crossings) count as merged
    std::fill(near.begin() + std::ptrdiff_t(first_split), near.end(), 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, pairs.size(), 4096), [&](const auto& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            std::uint32_t a = std::uint32_t(pairs[i] >> 32), b = std::uint32_t(pairs[i]);
            if (!leaves.inside[a]) std::swap(a, b);
            near[i] = leaves.is_surface[a] && tree.top > 0 && a >= numbering.node_first[1];  // finest ids come first
        }
    });
    grow_by_rings(near, tris, alive, 2);
    grow_by_rings(pinned_near, tris, alive, 1);
    for (std::size_t v = 0; v < point_count; ++v) near[v] &= !pinned_near[v];
    return near;
}

/// Step 5b's points: the vertices of surface leaves that no surviving
/// triangle uses and where the field is concave (a concave crease the loops
/// cut off, see crease_splits.cpp), in leaf order; none in pinned cells,
/// so that stage "untangle" can take a split back.
std::vector<Vec3d> skipped_crease_vertices(const Octree& tree, const std::vector<std::uint64_t>& pairs,
                                           const LeafVertices& leaves, const std::vector<openvdb::Vec3I>& tris,
                                           const std::vector<std::uint8_t>& alive, const FieldSource& field,
                                           const PinnedCells& pinned) {
    // On a concave crease from kConcave voxels of concavity on (a 90-degree
    // crease: about 0.3). 0.1 also split smooth concave parts of the
    // armadillo (clean ang5 18.4 -> 17.3 degrees at 128 cells); 0.15 keeps
    // it within 3% and the CSG part and fandisk at 0.076 voxel (0.2: 0.09).
    constexpr double kConcave = 0.15;
    std::vector<std::uint8_t> used(leaves.inside.size(), 0);
    for (std::size_t t = 0; t < tris.size(); ++t) {
        if (!alive[t]) continue;
        for (int k = 0; k < 3; ++k) {
            if (tris[t][k] >= pairs.size()) continue;  // an added centre
            std::uint32_t a = std::uint32_t(pairs[tris[t][k]] >> 32), b = std::uint32_t(pairs[tris[t][k]]);
            used[leaves.inside[a] ? a : b] = 1;
        }
    }
    std::vector<std::uint8_t> crease(used.size(), 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, used.size(), 4096), [&](const auto& r) {
        auto probe = field.probe();
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            if (!leaves.is_surface[i] || used[i]) continue;
            const Vec3d& p = leaves.position[i];
            crease[i] = !(pinned.size() > 0 && pinned.pinned(tree, openvdb::Coord::floor(p))) &&
                        concavity(*probe, p) > kConcave;
        }
    });
    std::vector<Vec3d> out;
    for (std::size_t i = 0; i < used.size(); ++i)
        if (crease[i]) out.push_back(leaves.position[i]);
    return out;
}

/// Step 6: surviving faces, quads re-joined where both halves survive
/// unflipped, vertices compacted in order.
void assemble_output(const LoopFaces& f, const std::vector<std::uint32_t>& rep, const std::vector<std::uint8_t>& alive,
                     const std::vector<std::uint8_t>& flipped, Mesh& mesh) {
    std::vector<std::uint8_t> in_quad(f.tris.size(), 0);
    for (std::size_t q = 0; q < f.quads.size(); ++q) {
        const std::uint32_t t = f.quad_tri[q];
        openvdb::Vec4I v;
        for (int k = 0; k < 4; ++k) v[k] = rep[f.quads[q][k]];
        const bool distinct =
            v[0] != v[1] && v[0] != v[2] && v[0] != v[3] && v[1] != v[2] && v[1] != v[3] && v[2] != v[3];
        if (alive[t] && alive[t + 1] && !flipped[t] && !flipped[t + 1] && distinct) {
            in_quad[t] = in_quad[t + 1] = 1;
            mesh.quads.push_back(v);
        }
    }
    for (std::size_t t = 0; t < f.tris.size(); ++t)
        if (alive[t] && !in_quad[t]) mesh.triangles.emplace_back(rep[f.tris[t][0]], rep[f.tris[t][1]], rep[f.tris[t][2]]);
    std::vector<std::uint32_t> remap(mesh.points.size(), 0);
    for (const auto& t : mesh.triangles)
        for (int k = 0; k < 3; ++k) remap[t[k]] = 1;
    for (const auto& q : mesh.quads)
        for (int k = 0; k < 4; ++k) remap[q[k]] = 1;
    std::uint32_t next = 0;
    for (std::size_t i = 0; i < remap.size(); ++i) {
        if (remap[i]) {
            mesh.points[next] = mesh.points[i];
            remap[i] = next++;
        }
    }
    mesh.points.resize(next);
    for (auto& t : mesh.triangles)
        for (int k = 0; k < 3; ++k) t[k] = remap[t[k]];
    for (auto& q : mesh.quads)
        for (int k = 0; k < 4; ++k) q[k] = remap[q[k]];
}

}  // namespace

Mesh polygonize_dual_cells(const Octree& tree, const LeafNumbering& numbering, const std::vector<DualCell>& cells,
                           const FieldSource& field, FaceType faces, const PinnedCells& pinned,
                           const ShapeLimits& shape, AdaptiveStats& stats, const detail::ProgressSpan& span) {
    stats.dual_cells = cells.size();
    LeafVertices leaves = leaf_sides(tree, numbering, cells, field, stats, span.part(0.0, 0.1));
    const DualCrossings crossings = dual_crossings(cells, leaves.inside, span.part(0.1, 0.3));
    span.report(0.3);
    Mesh mesh;
    mesh.points = place_crossings(crossings.pairs, leaves, field, span.part(0.3, 0.45));
    LoopFaces loops = triangulate_loops(cells, crossings, field, faces, mesh.points, stats, span.part(0.45, 0.7));
    span.report(0.7);

    // Step 5: crossings placed on the same surface vertex are merged by edge
    // collapses that keep the mesh a closed 2-manifold (link condition).
    std::vector<std::uint32_t> rep;
    std::vector<std::uint8_t> alive, flipped;
    const std::vector<std::uint64_t> tiles = crossing_tiles(tree, numbering, crossings.pairs, leaves, mesh.points.size());
    span.report(0.72);
    collapse_coincident_vertices(mesh.points, tiles, loops.tris, rep, alive, span.part(0.72, 0.85));
    for (std::uint32_t v = 0; v < rep.size(); ++v) stats.collapsed_vertices += rep[v] != v;
    span.report(0.85);
    flip_collinear_triangles(mesh.points, loops.tris, alive, flipped);
    const std::size_t first_split = mesh.points.size();
    {
        const std::vector<Vec3d> skipped =
            skipped_crease_vertices(tree, crossings.pairs, leaves, loops.tris, alive, field, pinned);
        auto probe = field.probe();
        split_at_concave_creases(skipped, *probe, mesh.points, loops.tris, alive, flipped);
        for (std::size_t v = rep.size(); v < mesh.points.size(); ++v) rep.push_back(std::uint32_t(v));
    }
    const std::vector<std::uint8_t> pinned_near = pinned_corners(tree, pinned, mesh.points, loops.tris);
    const std::vector<std::uint8_t> frozen = frozen_for_flips(loops, pinned_near);
    if (shape.relax.sweeps > 0) {
        const std::vector<std::uint8_t> movable = relaxable_vertices(
            tree, numbering, crossings.pairs, leaves, mesh.points.size(), first_split, loops.tris, alive, pinned_near);
        stats.relaxed_vertices = relax_tangentially(mesh.points, loops.tris, alive, movable, shape.relax);
    }
    {
        auto probe = field.probe();
        stats.angle_flips = flip_for_angles(mesh.points, loops.tris, alive, frozen, flipped, probe.get(), shape.flips);
    }
    span.report(0.9);

    assemble_output(loops, rep, alive, flipped, mesh);
    span.report(0.95);
    separate_coincident_vertices(mesh, stats, span.part(0.95, 1.0));
    stats.vertices = mesh.points.size();
    stats.triangles = mesh.triangles.size();
    stats.quads = mesh.quads.size();
    return mesh;
}

}  // namespace pqdc::adaptive_detail
