// Dual grid of the simplified octree (Schaefer & Warren 2004, §3: the
// cell/face/edge/vertex recursion) and marching cubes on its cells.
#include "adaptive/octree.hpp"
#include "lattice/value_block.hpp"
#include "pqdc/exceptions.hpp"

#include <utility>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>
#include <tbb/enumerable_thread_specific.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <unordered_map>

namespace pqdc::adaptive_detail {

std::int64_t Level::find(std::uint64_t c) const {
    const auto it = std::lower_bound(code.begin(), code.end(), c);
    if (it == code.end() || *it != c) return -1;
    return it - code.begin();
}

// ------------------------------------------------------------ field helpers

namespace {
openvdb::Vec3d central_gradient(FieldProbe& probe, const openvdb::Vec3d& p) {
    const double h = 0.5;
    openvdb::Vec3d g;
    for (int d = 0; d < 3; ++d) {
        openvdb::Vec3d a = p, b = p;
        a[d] -= h;
        b[d] += h;
        g[d] = (probe.value(b) - probe.value(a)) / (2 * h);
    }
    return g;
}
}  // namespace

double field_gradient_length(FieldProbe& probe, const openvdb::Vec3d& p) {
    return central_gradient(probe, p).length();
}

double field_distance_voxels(FieldProbe& probe, const openvdb::Vec3d& p, double gradient_length) {
    const double g = probe.value(p);
    if (!(gradient_length > 0) || !std::isfinite(g)) return std::numeric_limits<double>::infinity();
    return std::fabs(g) / gradient_length;
}

openvdb::Vec3d project_to_surface(FieldProbe& probe, const openvdb::Vec3d& p, double reach) {
    const double g = probe.value(p);
    const openvdb::Vec3d grad = central_gradient(probe, p);
    const double len2 = grad.lengthSqr();
    if (!(len2 > 0) || !std::isfinite(g)) return p;
    const openvdb::Vec3d step = grad * (g / len2);
    if (!(step.length() <= reach)) return p;
    return p - step;
}

// ------------------------------------------------------------ cube tables

std::array<int, 2> edge_corners(int edge) {
    const int axis = edge / 4, k = edge % 4;
    int a = 0;
    if (axis == 0) a = (k & 1) << 1 | (k >> 1) << 2;
    if (axis == 1) a = (k & 1) | (k >> 1) << 2;
    if (axis == 2) a = (k & 1) | (k >> 1) << 1;
    return {a, a | 1 << axis};
}

namespace {

int edge_between(int a, int b) {
    for (int e = 0; e < 12; ++e) {
        const auto c = edge_corners(e);
        if ((c[0] == a && c[1] == b) || (c[0] == b && c[1] == a)) return e;
    }
    return -1;
}

// Loops of one sign mask. On every cube face, walked counter-clockwise
// around its outward normal, the crossing where the walk enters the inside
// is joined to the next crossing where it leaves: inside corners are always
// separated on ambiguous faces, and the segment direction makes the loops
// counter-clockwise seen from outside the surface.
CubeLoops make_loops(unsigned mask) {
    int next[12];
    std::fill(std::begin(next), std::end(next), -1);
    for (int d = 0; d < 3; ++d) {
        const int u = d == 0 ? 1 : 0, v = d == 2 ? 1 : 2;
        // (0,0),(1,0),(1,1),(0,1) in (u, v) turns counter-clockwise around u x v,
        // which is +x for d = 0, -y for d = 1, +z for d = 2.
        const int natural = d == 1 ? -1 : 1;
        for (int side = 0; side < 2; ++side) {
            int corner[4];
            const int uv[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
            for (int i = 0; i < 4; ++i)
                corner[i] = side << d | uv[i][0] << u | uv[i][1] << v;
            if ((side == 1 ? 1 : -1) * natural < 0) std::reverse(corner, corner + 4);
            int enter[2], exit_[2], ne = 0, nx = 0, enter_pos[2], exit_pos[2];
            for (int i = 0; i < 4; ++i) {
                const int a = corner[i], b = corner[(i + 1) % 4];
                const bool ia = mask >> a & 1, ib = mask >> b & 1;
                if (ia && !ib) { exit_pos[nx] = i; exit_[nx++] = edge_between(a, b); }
                if (!ia && ib) { enter_pos[ne] = i; enter[ne++] = edge_between(a, b); }
            }
            for (int k = 0; k < ne; ++k) {
                // The first exit after this entry, walking on.
                int best = -1, best_dist = 5;
                for (int m = 0; m < nx; ++m) {
                    const int dist = (exit_pos[m] - enter_pos[k] + 4) % 4;
                    if (dist > 0 && dist < best_dist) { best_dist = dist; best = m; }
                }
                next[enter[k]] = exit_[best];
            }
        }
    }
    CubeLoops loops;
    bool used[12] = {};
    for (int e = 0; e < 12; ++e) {
        if (next[e] < 0 || used[e]) continue;
        const int l = loops.count++;
        for (int f = e; !used[f]; f = next[f]) {
            used[f] = true;
            loops.edge[l][loops.size[l]++] = std::uint8_t(f);
        }
    }
    return loops;
}

struct LoopTable {
    CubeLoops loops[256];
    bool manifold[256];
    LoopTable() {
        for (unsigned m = 0; m < 256; ++m) loops[m] = make_loops(m);
        for (unsigned m = 0; m < 256; ++m)
            manifold[m] = loops[m].count == 1 && loops[255 - m].count == 1;
    }
};
const LoopTable& loop_table() {
    static const LoopTable table;
    return table;
}

// ------------------------------------------------------------ dual grid

// 16 bytes: the recursion copies arrays of them.
struct Handle {
    std::int32_t level;
    std::uint32_t id;    // LeafNumbering id
    std::int64_t index;  // into tree.levels[level]; -1: an empty leaf
};

class DualBuilder {
public:
    DualBuilder(const Octree& tree, const LeafNumbering& numbering, std::vector<DualCell>& out)
        : tree_(tree), numbering_(numbering), out_(out) {}

    bool is_leaf(const Handle& h) const {
        return h.index < 0 || (tree_.levels[h.level].flags[h.index] & kLeaf);
    }
    Handle child(const Handle& h, int octant) const {
        if (is_leaf(h)) return h;
        const Level& lv = tree_.levels[h.level];
        const unsigned mask = lv.child_mask[h.index];
        Handle c{h.level - 1, 0, -1};
        const unsigned below = (1u << octant) - 1;
        if (mask >> octant & 1) {
            c.index = std::int64_t(lv.first_child[h.index]) + popcount8(mask & below);
            c.id = std::uint32_t(numbering_.node_first[c.level] + std::uint64_t(c.index));
        } else {
            c.id = numbering_.empty_first[h.level][std::size_t(h.index)] + popcount8(~mask & below);
        }
        return c;
    }

    void cell(const Handle& h) {
        if (is_leaf(h)) return;
        Handle c[8];
        for (int i = 0; i < 8; ++i) c[i] = child(h, i);
        for (int i = 0; i < 8; ++i) cell(c[i]);
        for (int d = 0; d < 3; ++d)
            for (int i = 0; i < 8; ++i)
                if (!(i >> d & 1)) face(c[i], c[i | 1 << d], d);
        for (int d = 0; d < 3; ++d) {
            const int p = d == 0 ? 1 : 0, q = d == 2 ? 1 : 2;
            for (int s = 0; s < 2; ++s) {
                Handle n[4];
                for (int j = 0; j < 4; ++j) n[j] = c[s << d | (j & 1) << p | (j >> 1) << q];
                edge(n, d);
            }
        }
        vertex(c);
    }

    // a on the low side of axis d, b on the high side.
    void face(const Handle& a, const Handle& b, int d) {
        if (is_leaf(a) && is_leaf(b)) return;
        const int e = d == 0 ? 1 : 0, f = d == 2 ? 1 : 2;
        for (int k = 0; k < 4; ++k) {
            const int bits = (k & 1) << e | (k >> 1) << f;
            face(child(a, 1 << d | bits), child(b, bits), d);
        }
        // The four half edges in the face plane, parallel to e and to f.
        for (int along : {e, f}) {
            const int other = along == e ? f : e;
            const int p = std::min(d, other);
            for (int s = 0; s < 2; ++s) {
                Handle n[4];
                for (int j = 0; j < 4; ++j) {
                    const int bp = j & 1, bq = j >> 1;
                    const int sd = p == d ? bp : bq, w = p == d ? bq : bp;
                    const int oct = (1 - sd) << d | w << other | s << along;
                    n[j] = child(sd == 0 ? a : b, oct);
                }
                edge(n, along);
            }
        }
        Handle v[8];
        for (int i = 0; i < 8; ++i) {
            const int rest = i & ~(1 << d);
            v[i] = (i >> d & 1) ? child(b, rest) : child(a, rest | 1 << d);
        }
        vertex(v);
    }

    // n[j]: the node in quadrant j = bit(p) + 2 bit(q) around an edge
    // parallel to d, where p < q are the other two axes.
    void edge(const Handle (&n)[4], int d) {
        if (is_leaf(n[0]) && is_leaf(n[1]) && is_leaf(n[2]) && is_leaf(n[3])) return;
        const int p = d == 0 ? 1 : 0, q = d == 2 ? 1 : 2;
        for (int s = 0; s < 2; ++s) {
            Handle m[4];
            for (int j = 0; j < 4; ++j)
                m[j] = child(n[j], s << d | (1 - (j & 1)) << p | (1 - (j >> 1)) << q);
            edge(m, d);
        }
        Handle v[8];
        for (int i = 0; i < 8; ++i) {
            // The node spans the whole edge: along d its child on the vertex's
            // side touches the midpoint; across, the half facing the edge.
            const int j = (i >> p & 1) | (i >> q & 1) << 1;
            v[i] = child(n[j], (i & 1 << d) | ((7 - i) & ~(1 << d)));
        }
        vertex(v);
    }

    void vertex(const Handle (&n)[8]) {
        bool all_leaves = true, any_surface = false;
        for (const Handle& h : n) {
            all_leaves = all_leaves && is_leaf(h);
            any_surface = any_surface || h.index >= 0;
        }
        if (!any_surface) return;
        if (all_leaves) {
            DualCell c;
            for (int i = 0; i < 8; ++i) c[i] = n[i].id;
            out_.push_back(c);
            return;
        }
        Handle m[8];
        for (int i = 0; i < 8; ++i) m[i] = child(n[i], 7 - i);
        vertex(m);
    }

private:
    const Octree& tree_;
    const LeafNumbering& numbering_;
    std::vector<DualCell>& out_;
};

// Work items at the root level: cell recursions and the faces, edges and
// corners shared by root cells (missing roots are empty leaves).
struct RootTask {
    enum Kind : std::uint8_t { cell, face, edge, vertex } kind;
    std::uint8_t axis;
    std::uint64_t base;  // root code of the lowest cell of the tuple
};

}  // namespace

const CubeLoops& cube_loops(unsigned mask) { return loop_table().loops[mask & 255]; }
bool manifold_configuration(unsigned mask) { return loop_table().manifold[mask & 255]; }

LeafNumbering number_leaves(const Octree& tree) {
    LeafNumbering n;
    const int top = tree.top;
    std::uint64_t next = 0;
    for (int level = 0; level <= top; ++level) {
        n.node_first[level] = next;
        next += tree.levels[level].size();
    }
    n.empty_first_id = next;
    n.empty_first.resize(top + 1);
    for (int level = 1; level <= top; ++level) {
        const Level& lv = tree.levels[level];
        auto& first = n.empty_first[level];
        first.assign(lv.size(), 0);
        for (std::size_t i = 0; i < lv.size(); ++i) {
            if (lv.flags[i] & kLeaf) continue;
            first[i] = std::uint32_t(next);  // checked below, with the total
            next += 8 - popcount8(lv.child_mask[i]);
        }
    }
    // Roots are one root away from the code origin at least (Octree::offset),
    // so their neighbours have codes.
    const Level& roots = tree.levels[top];
    std::vector<std::uint64_t> missing;
    for (std::size_t r = 0; r < roots.size(); ++r) {
        const auto c = unmorton(roots.code[r]);
        for (int dz = -1; dz <= 1; ++dz)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    const std::uint64_t code = morton(c[0] + std::uint32_t(dx), c[1] + std::uint32_t(dy),
                                                      c[2] + std::uint32_t(dz));
                    if (roots.find(code) < 0) missing.push_back(code);
                }
    }
    tbb::parallel_sort(missing.begin(), missing.end());
    missing.erase(std::unique(missing.begin(), missing.end()), missing.end());
    n.missing_root_first_id = next;
    next += missing.size();
    n.missing_roots = std::move(missing);
    n.count = next;
    // Leaf ids are 32-bit, as the mesh's vertex indices are.
    if (n.count > std::numeric_limits<std::uint32_t>::max())
        throw resource_error("the adaptive octree has " + std::to_string(n.count) +
                             " leaves around the surface, more than 2^32; mesh the volume in parts "
                             "or with a larger max_error");
    n.empty_key.resize(n.count - n.empty_first_id);
    for (int level = 1; level <= top; ++level) {
        const Level& lv = tree.levels[level];
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, lv.size(), 4096),
                          [&](const tbb::blocked_range<std::size_t>& r) {
            for (std::size_t i = r.begin(); i != r.end(); ++i) {
                if (lv.flags[i] & kLeaf) continue;
                std::uint64_t id = n.empty_first[level][i] - n.empty_first_id;
                for (unsigned o = 0; o < 8; ++o)
                    if (!(lv.child_mask[i] >> o & 1)) n.empty_key[id++] = leaf_key(level - 1, lv.code[i] << 3 | o);
            }
        });
    }
    for (std::size_t k = 0; k < n.missing_roots.size(); ++k)
        n.empty_key[n.missing_root_first_id - n.empty_first_id + k] = leaf_key(top, n.missing_roots[k]);
    return n;
}

std::vector<DualCell> generate_dual_cells(const Octree& tree, const LeafNumbering& numbering) {
    const Level& roots = tree.levels[tree.top];
    const int top = tree.top;
    auto root_handle = [&](std::int64_t x, std::int64_t y, std::int64_t z) {
        const std::uint64_t code = morton(std::uint32_t(x), std::uint32_t(y), std::uint32_t(z));
        const std::int64_t index = roots.find(code);
        std::uint64_t id;
        if (index >= 0) {
            id = numbering.node_first[top] + std::uint64_t(index);
        } else {
            const auto& m = numbering.missing_roots;
            id = numbering.missing_root_first_id + std::uint64_t(std::lower_bound(m.begin(), m.end(), code) - m.begin());
        }
        return Handle{top, std::uint32_t(id), index};
    };
    std::vector<RootTask> tasks;
    for (std::size_t r = 0; r < roots.size(); ++r) {
        const auto c = unmorton(roots.code[r]);
        const std::int64_t x = c[0], y = c[1], z = c[2];
        tasks.push_back({RootTask::cell, 0, roots.code[r]});
        // Each shared element is emitted by the first present cell of its tuple.
        for (int d = 0; d < 3; ++d) {
            const std::int64_t lo[3] = {x - (d == 0), y - (d == 1), z - (d == 2)};
            tasks.push_back({RootTask::face, std::uint8_t(d), roots.code[r]});
            if (root_handle(lo[0], lo[1], lo[2]).index < 0)
                tasks.push_back({RootTask::face, std::uint8_t(d),
                                 morton(std::uint32_t(lo[0]), std::uint32_t(lo[1]), std::uint32_t(lo[2]))});
            const int p = d == 0 ? 1 : 0, q = d == 2 ? 1 : 2;
            for (int j = 0; j < 4; ++j) {
                std::int64_t b[3] = {x, y, z};
                b[p] -= j & 1;
                b[q] -= j >> 1;
                bool first = true;
                for (int k = 0; k < j && first; ++k) {
                    std::int64_t o[3] = {b[0], b[1], b[2]};
                    o[p] += k & 1;
                    o[q] += k >> 1;
                    first = root_handle(o[0], o[1], o[2]).index < 0;
                }
                if (first)
                    tasks.push_back({RootTask::edge, std::uint8_t(d),
                                     morton(std::uint32_t(b[0]), std::uint32_t(b[1]), std::uint32_t(b[2]))});
            }
        }
        for (int i = 0; i < 8; ++i) {
            const std::int64_t b[3] = {x - (i & 1), y - (i >> 1 & 1), z - (i >> 2 & 1)};
            bool first = true;
            for (int k = 0; k < i && first; ++k)
                first = root_handle(b[0] + (k & 1), b[1] + (k >> 1 & 1), b[2] + (k >> 2 & 1)).index < 0;
            if (first)
                tasks.push_back({RootTask::vertex, 0,
                                 morton(std::uint32_t(b[0]), std::uint32_t(b[1]), std::uint32_t(b[2]))});
        }
    }

    std::vector<std::vector<DualCell>> per_task(tasks.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, tasks.size(), 1),
                      [&](const tbb::blocked_range<std::size_t>& range) {
        for (std::size_t t = range.begin(); t != range.end(); ++t) {
            DualBuilder builder(tree, numbering, per_task[t]);
            const RootTask& task = tasks[t];
            const auto c = unmorton(task.base);
            const std::int64_t x = c[0], y = c[1], z = c[2];
            switch (task.kind) {
            case RootTask::cell:
                builder.cell(root_handle(x, y, z));
                break;
            case RootTask::face: {
                const int d = task.axis;
                builder.face(root_handle(x, y, z),
                             root_handle(x + (d == 0), y + (d == 1), z + (d == 2)), d);
                break;
            }
            case RootTask::edge: {
                const int d = task.axis, p = d == 0 ? 1 : 0, q = d == 2 ? 1 : 2;
                Handle n[4];
                for (int j = 0; j < 4; ++j) {
                    std::int64_t o[3] = {x, y, z};
                    o[p] += j & 1;
                    o[q] += j >> 1;
                    n[j] = root_handle(o[0], o[1], o[2]);
                }
                builder.edge(n, d);
                break;
            }
            case RootTask::vertex: {
                Handle n[8];
                for (int i = 0; i < 8; ++i)
                    n[i] = root_handle(x + (i & 1), y + (i >> 1 & 1), z + (i >> 2 & 1));
                builder.vertex(n);
                break;
            }
            }
        }
    });
    std::size_t total = 0;
    for (const auto& v : per_task) total += v.size();
    std::vector<DualCell> cells;
    cells.reserve(total);
    for (auto& v : per_task) {
        cells.insert(cells.end(), v.begin(), v.end());
        std::vector<DualCell>().swap(v);
    }
    return cells;
}

// ------------------------------------------------------------ polygons

namespace {

/// Illinois (modified regula falsi) on [0, 1] for a sign change between
/// g0 = g(0) and g1 = g(1); stops when the bracket is shorter than t_tol.
template <class G>
double find_root(G&& g, double g0, double g1, double t_tol) {
    return pqdc::detail::root_on_unit_interval(std::forward<G>(g), g0, g1, t_tol);
}

std::uint64_t pair_key(std::uint32_t a, std::uint32_t b) {
    return a < b ? std::uint64_t(a) << 32 | b : std::uint64_t(b) << 32 | a;
}

/// Collapses edges whose end points coincide exactly, in a fixed order,
/// whenever the link condition holds (the common neighbours of the two end
/// points are exactly the two vertices opposite the edge), which keeps a
/// closed edge-manifold oriented triangle mesh so. rep maps every vertex to
/// its survivor; alive marks the triangles that remain.
///
/// tile[v] names the octree root holding vertex v's surface leaf (kNoTile
/// for vertices of no leaf). A collapse reads and writes only triangles
/// around its two vertices, and a triangle joins leaves around one octree
/// corner, so two roots that are not neighbours never touch the same
/// triangle: the roots of one coordinate-parity class are processed in
/// parallel, the eight classes one after another; edges between tiles come
/// last, in one sequential sweep over all edges. The result depends on the
/// tiles, not on the threads.
constexpr std::uint64_t kNoTile = std::numeric_limits<std::uint64_t>::max();

void collapse_coincident_vertices(const std::vector<openvdb::Vec3d>& points,
                                  const std::vector<std::uint64_t>& tile,
                                  std::vector<openvdb::Vec3I>& tris, std::vector<std::uint32_t>& rep,
                                  std::vector<std::uint8_t>& alive) {
    const std::size_t nv = points.size();
    rep.resize(nv);
    std::iota(rep.begin(), rep.end(), 0u);
    alive.assign(tris.size(), 1);
    // (tile, edge) so that sorting groups the edges by tile in a fixed order.
    std::vector<std::pair<std::uint64_t, std::uint64_t>> edges;
    for (const auto& t : tris)
        for (int k = 0; k < 3; ++k) {
            const std::uint32_t a = t[k], b = t[(k + 1) % 3];
            if (a != b && points[a] == points[b])
                edges.emplace_back(tile[a] == tile[b] ? tile[a] : kNoTile, pair_key(a, b));
        }
    if (edges.empty()) return;
    tbb::parallel_sort(edges.begin(), edges.end());
    edges.erase(std::unique(edges.begin(), edges.end()), edges.end());

    // Original incident triangles (CSR) of the vertices on those edges; a
    // merged group's triangles are those of its members (linked list).
    std::vector<std::uint8_t> involved(nv, 0);
    for (const auto& e : edges) involved[e.second >> 32] = involved[std::uint32_t(e.second)] = 1;
    std::vector<std::uint32_t> first(nv + 1, 0);
    for (const auto& t : tris)
        for (int k = 0; k < 3; ++k)
            if (involved[t[k]]) ++first[t[k] + 1];
    for (std::size_t v = 0; v < nv; ++v) first[v + 1] += first[v];
    std::vector<std::uint32_t> incident(first[nv]);
    {
        std::vector<std::uint32_t> fill(first.begin(), first.end() - 1);
        for (std::uint32_t t = 0; t < tris.size(); ++t)
            for (int k = 0; k < 3; ++k)
                if (involved[tris[t][k]]) incident[fill[tris[t][k]]++] = t;
    }
    std::vector<std::uint32_t> next_member(nv, std::numeric_limits<std::uint32_t>::max()), last_member(nv);
    std::iota(last_member.begin(), last_member.end(), 0u);
    auto find = [&](std::uint32_t v) {
        while (rep[v] != v) v = rep[v] = rep[rep[v]];
        return v;
    };
    struct Scratch {
        std::vector<std::uint32_t> fk, fd, na, nb;
    };
    auto gather = [&](std::uint32_t root, std::vector<std::uint32_t>& out) {
        out.clear();
        for (std::uint32_t m = root; m != std::numeric_limits<std::uint32_t>::max(); m = next_member[m])
            for (std::uint32_t i = first[m]; i < first[m + 1]; ++i)
                if (alive[incident[i]]) out.push_back(incident[i]);
        std::sort(out.begin(), out.end());
        out.erase(std::unique(out.begin(), out.end()), out.end());
    };
    // Tries the edges [begin, end) in order; true when one collapsed.
    auto run = [&](std::size_t begin, std::size_t end, Scratch& sc) {
        bool changed = false;
        auto& fk = sc.fk;
        auto& fd = sc.fd;
        auto& na = sc.na;
        auto& nb = sc.nb;
        for (std::size_t ei = begin; ei < end; ++ei) {
            const std::uint64_t e = edges[ei].second;
            const std::uint32_t a = find(std::uint32_t(e >> 32)), b = find(std::uint32_t(e));
            if (a == b) continue;
            const std::uint32_t keep = std::min(a, b), drop = std::max(a, b);
            gather(keep, fk);
            gather(drop, fd);
            na.clear();
            nb.clear();
            std::uint32_t apex[2] = {0, 0};
            int shared = 0;
            for (std::uint32_t t : fk) {
                bool has_drop = false;
                for (int k = 0; k < 3; ++k) has_drop = has_drop || tris[t][k] == drop;
                for (int k = 0; k < 3; ++k) {
                    const std::uint32_t v = tris[t][k];
                    if (v == keep || v == drop) continue;
                    na.push_back(v);
                    if (has_drop && shared < 2) apex[shared] = v;
                }
                if (has_drop) ++shared;
            }
            for (std::uint32_t t : fd)
                for (int k = 0; k < 3; ++k)
                    if (tris[t][k] != keep && tris[t][k] != drop) nb.push_back(tris[t][k]);
            if (shared != 2 || apex[0] == apex[1]) continue;
            std::sort(na.begin(), na.end());
            na.erase(std::unique(na.begin(), na.end()), na.end());
            std::sort(nb.begin(), nb.end());
            nb.erase(std::unique(nb.begin(), nb.end()), nb.end());
            std::size_t common = 0;
            for (std::size_t i = 0, j = 0; i < na.size() && j < nb.size();) {
                if (na[i] < nb[j]) ++i;
                else if (nb[j] < na[i]) ++j;
                else { ++common; ++i; ++j; }
            }
            // The merged vertex keeps |na| + |nb| - 2 neighbours; fewer than 3
            // (a tetrahedron) would leave two faces on the same three vertices.
            if (common != 2 || na.size() + nb.size() < 5) continue;
            for (std::uint32_t t : fd) {
                bool has_keep = false;
                for (int k = 0; k < 3; ++k) has_keep = has_keep || tris[t][k] == keep;
                if (has_keep) {
                    alive[t] = 0;
                    continue;
                }
                for (int k = 0; k < 3; ++k)
                    if (tris[t][k] == drop) tris[t][k] = keep;
            }
            rep[drop] = keep;
            next_member[last_member[keep]] = drop;
            last_member[keep] = last_member[drop];
            changed = true;
        }
        return changed;
    };

    // Runs of edges per tile, grouped by the tile's parity class.
    struct Run {
        std::size_t begin, end;
    };
    std::array<std::vector<Run>, 8> by_color;
    std::size_t mixed_begin = edges.size();
    for (std::size_t i = 0; i < edges.size();) {
        const std::uint64_t t = edges[i].first;
        std::size_t j = i;
        while (j < edges.size() && edges[j].first == t) ++j;
        if (t == kNoTile) {
            mixed_begin = i;
        } else {
            const auto c = unmorton(t);
            by_color[(c[0] & 1) | (c[1] & 1) << 1 | (c[2] & 1) << 2].push_back({i, j});
        }
        i = j;
    }
    tbb::enumerable_thread_specific<Scratch> scratch;
    for (int pass = 0; pass < 4; ++pass) {
        std::atomic<bool> changed{false};
        for (const auto& runs : by_color)
            tbb::parallel_for(std::size_t(0), runs.size(), [&](std::size_t r) {
                if (run(runs[r].begin, runs[r].end, scratch.local())) changed = true;
            });
        if (!changed) break;
    }
    // Then every edge in order, sequentially: a collapse across tiles joins
    // groups of two tiles, which the parallel passes must not see. Edges
    // already collapsed are skipped at the cost of two finds.
    if (mixed_begin < edges.size())
        for (int pass = 0; pass < 4; ++pass)
            if (!run(0, edges.size(), scratch.local())) break;
    for (std::uint32_t v = 0; v < rep.size(); ++v) rep[v] = find(v);
}

/// Vertices the collapse had to keep apart although they coincide (a fold
/// of the surface through one leaf vertex, where merging them would make an
/// edge non-manifold) are moved a hair (1e-4 of the way towards the centroid
/// of their other neighbours) so that no face has zero area. The first vertex
/// of each coincident group stays.
void separate_coincident_vertices(Mesh& mesh, AdaptiveStats& stats) {
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
    for (const auto& t : mesh.triangles) {
        const std::uint32_t f[3] = {t[0], t[1], t[2]};
        visit(f, 3);
    }
    for (const auto& q : mesh.quads) {
        const std::uint32_t f[4] = {q[0], q[1], q[2], q[3]};
        visit(f, 4);
    }
    for (std::size_t m = 0; m < moving.size(); ++m) {
        if (!count[m]) continue;
        Vec3d& p = mesh.points[moving[m]];
        p += (sum[m] / double(count[m]) - p) * 1e-4;
        ++stats.separated_vertices;
    }
}

/// Triangles whose corners are collinear (three leaf vertices on one
/// straight feature line, e.g. sigma_n = 0 on a box edge) are removed by
/// flipping their longest edge: with b on segment ac, the triangles (a,b,c)
/// and (a,c,d) become (a,b,d) and (b,c,d), which tile the same area. Skipped
/// when the new edge bd already exists (the flip would make it non-manifold).
/// Flipped triangles are marked in `changed`.
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

}  // namespace

Mesh polygonize_dual_cells(const Octree& tree, const LeafNumbering& numbering,
                           const std::vector<DualCell>& cells, const FieldSource& field, FaceType faces,
                           AdaptiveStats& stats) {
    using openvdb::Vec3d;
    const std::size_t n_cells = cells.size();
    stats.dual_cells = n_cells;

    // 1. Every numbered leaf's vertex; empty leaves also get their field value.
    const std::size_t n_leaves = numbering.count;
    std::vector<Vec3d> position(n_leaves);
    std::vector<double> value(n_leaves, 0.0);
    std::vector<std::uint8_t> is_surface(n_leaves, 0);
    // Nodes below a merged leaf keep their own kLeaf flag: the leaves of the
    // octree are the flagged nodes whose parent is internal (or roots).
    {
        std::vector<std::uint8_t> internal, below;  // of the level above, of this level
        for (int level = tree.top; level >= 0; --level) {
            const Level& lv = tree.levels[level];
            const std::size_t first = numbering.node_first[level];
            below.assign(lv.size(), level == tree.top ? 1 : 0);
            if (level < tree.top) {
                const Level& up = tree.levels[level + 1];
                for (std::size_t p = 0; p < up.size(); ++p)
                    if (internal[p])
                        std::fill_n(below.begin() + up.first_child[p], popcount8(up.child_mask[p]), 1);
            }
            std::uint64_t leaves = 0;
            internal.assign(lv.size(), 0);
            for (std::size_t i = 0; i < lv.size(); ++i) {
                if (!below[i]) continue;
                if (!(lv.flags[i] & kLeaf)) {
                    internal[i] = 1;
                    continue;
                }
                position[first + i] = lv.vertex[i];
                is_surface[first + i] = 1;
                ++leaves;
            }
            stats.leaves_per_level[level] += leaves;
            stats.surface_leaves += leaves;
        }
    }
    const std::size_t empty_first = numbering.empty_first_id;
    stats.empty_leaves = n_leaves - empty_first;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(empty_first, n_leaves, 1024),
                      [&](const tbb::blocked_range<std::size_t>& r) {
        auto probe = field.probe();
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            const std::uint64_t key = numbering.empty_key[i - empty_first];
            const int level = key_level(key);
            // A lattice point inside the leaf (its center, or its lowest
            // corner for a single cell): every lattice point of an empty
            // leaf has the same sign, which the field between lattice
            // points (noise finer than a voxel) need not keep.
            const int half = level > 0 ? 1 << (level - 1) : 0;
            position[i] = (tree.origin(level, key_code(key)) + openvdb::Coord(half)).asVec3d();
            value[i] = probe->value(position[i]);
        }
    });
    // Surface leaves' vertices lie on the surface (up to the merge error), so
    // the sign of the field there is noise: classifying them by it splits the
    // surface into slivers and bubbles. They count as inside (a symbolic
    // perturbation of the field there towards the inside), empty leaves by
    // the field's sign.
    std::vector<std::uint8_t> inside(n_leaves);
    for (std::size_t i = 0; i < n_leaves; ++i) inside[i] = is_surface[i] || (i >= empty_first && value[i] < 0);

    // 2. Sign masks of the dual cells; the dual edges that cross.
    const std::size_t grain = 8192;
    const std::size_t n_chunks = (n_cells + grain - 1) / grain;
    std::vector<std::uint8_t> mask(n_cells);
    std::vector<std::vector<std::uint64_t>> chunk_pairs(n_chunks);
    tbb::parallel_for(std::size_t(0), n_chunks, [&](std::size_t chunk) {
        std::vector<std::uint64_t>& pairs = chunk_pairs[chunk];
        const std::size_t end = std::min(n_cells, (chunk + 1) * grain);
        for (std::size_t c = chunk * grain; c < end; ++c) {
            unsigned m = 0;
            for (int i = 0; i < 8; ++i)
                if (inside[cells[c][i]]) m |= 1u << i;
            mask[c] = std::uint8_t(m);
            const CubeLoops& loops = cube_loops(m);
            for (int l = 0; l < loops.count; ++l)
                for (int k = 0; k < loops.size[l]; ++k) {
                    const auto ec = edge_corners(loops.edge[l][k]);
                    pairs.push_back(pair_key(cells[c][ec[0]], cells[c][ec[1]]));
                }
        }
        std::sort(pairs.begin(), pairs.end());
        pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
    });
    std::vector<std::uint64_t> pairs;
    for (auto& p : chunk_pairs) {
        pairs.insert(pairs.end(), p.begin(), p.end());
        std::vector<std::uint64_t>().swap(p);
    }
    tbb::parallel_sort(pairs.begin(), pairs.end());
    pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());

    // 3. Crossings. An edge from a surface leaf crosses at the leaf's vertex:
    // it lies on the surface up to the merge error and is the
    // feature-preserving position, while a root of the field along the edge
    // would only add a sliver next to it. Edges between two empty leaves
    // (where the surface leaves the domain) are root-found on the field.
    Mesh mesh;
    mesh.points.resize(pairs.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, pairs.size(), 512),
                      [&](const tbb::blocked_range<std::size_t>& r) {
        auto probe = field.probe();
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            std::uint32_t a = std::uint32_t(pairs[i] >> 32), b = std::uint32_t(pairs[i]);
            if (!inside[a]) std::swap(a, b);
            const Vec3d pa = position[a], pb = position[b];
            if (is_surface[a] || !(value[a] < 0 && value[b] >= 0)) {
                mesh.points[i] = pa;
                continue;
            }
            const double len = (pb - pa).length();
            const double tol = len > 0 ? 1e-7 / len : 1.0;
            const double t = find_root([&](double s) { return probe->value(pa + (pb - pa) * s); },
                                       value[a], value[b], tol);
            mesh.points[i] = pa + (pb - pa) * t;
        }
    });

    // 4. Faces: each loop's crossings, with repeated vertices (crossings on
    // the same pair of leaves, from degenerate dual cells) removed. A loop's
    // triangulation must not add an edge between two crossings on a common
    // face of the dual cell: the neighbour across that face may hold the same
    // two crossings (ambiguous faces, degenerate cells) and add the same edge.
    // pairs is sorted by its smaller leaf id: index its runs by that id, so a
    // lookup searches a leaf's few crossings instead of all of them.
    std::vector<std::uint32_t> pair_first(n_leaves + 1, 0);
    for (std::uint64_t key : pairs) ++pair_first[(key >> 32) + 1];
    for (std::size_t i = 0; i < n_leaves; ++i) pair_first[i + 1] += pair_first[i];
    auto vertex_id = [&](std::uint64_t key) {
        const auto begin = pairs.begin() + pair_first[key >> 32], end = pairs.begin() + pair_first[(key >> 32) + 1];
        return std::uint32_t(std::lower_bound(begin, end, key) - pairs.begin());
    };
    constexpr std::uint32_t kExtra = 0x80000000u;  // chunk-local centroid vertex
    std::vector<std::vector<openvdb::Vec3I>> chunk_tris(n_chunks);
    std::vector<std::vector<openvdb::Vec4I>> chunk_quads(n_chunks);
    std::vector<std::vector<Vec3d>> chunk_extra(n_chunks);
    std::vector<std::vector<std::uint32_t>> chunk_quad_tri(n_chunks);  // first triangle of each quad
    tbb::parallel_for(std::size_t(0), n_chunks, [&](std::size_t chunk) {
        auto& tris = chunk_tris[chunk];
        auto& quads = chunk_quads[chunk];
        auto& extra = chunk_extra[chunk];
        auto& quad_first_tri = chunk_quad_tri[chunk];
        auto probe = field.probe();
        const std::size_t end = std::min(n_cells, (chunk + 1) * grain);
        struct Corner {
            std::uint32_t id;
            unsigned faces;  // cube faces (bit 2d + side) holding the crossing's dual edge(s)
        };
        auto emit = [&](const Corner* loop, int m) {
            if (m < 3) return;
            if (m == 3) {
                tris.emplace_back(loop[0].id, loop[1].id, loop[2].id);
                return;
            }
            if (m == 4 && faces == FaceType::quads) {
                // Triangulated like any loop (the collapse below works on
                // triangles) and joined again afterwards if both halves survive.
                quads.emplace_back(loop[0].id, loop[1].id, loop[2].id, loop[3].id);
                quad_first_tri.push_back(std::uint32_t(tris.size()));
            }
            // The safe apex whose worst fan triangle is fattest (area over
            // squared longest side), so collinear corners get no sliver.
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
                    const Vec3d& a = mesh.points[loop[k].id];
                    const Vec3d& b = mesh.points[loop[(k + i) % m].id];
                    const Vec3d& c = mesh.points[loop[(k + i + 1) % m].id];
                    const double side2 = std::max({(b - a).lengthSqr(), (c - b).lengthSqr(), (a - c).lengthSqr()});
                    worst = std::min(worst, side2 > 0 ? (b - a).cross(c - a).length() / side2 : 0.0);
                }
                if (worst > best) {
                    best = worst;
                    apex = k;
                }
            }
            if (apex >= 0) {
                for (int i = 1; i + 1 < m; ++i)
                    tris.emplace_back(loop[apex].id, loop[(apex + i) % m].id, loop[(apex + i + 1) % m].id);
                return;
            }
            Vec3d centroid(0.0);
            double reach = 0;
            for (int i = 0; i < m; ++i) centroid += mesh.points[loop[i].id];
            centroid /= double(m);
            for (int i = 0; i < m; ++i) reach = std::max(reach, (mesh.points[loop[i].id] - centroid).length());
            const std::uint32_t c = kExtra | std::uint32_t(extra.size());
            extra.push_back(project_to_surface(*probe, centroid, reach));
            for (int i = 0; i < m; ++i) tris.emplace_back(c, loop[i].id, loop[(i + 1) % m].id);
        };
        for (std::size_t c = chunk * grain; c < end; ++c) {
            const CubeLoops& loops = cube_loops(mask[c]);
            for (int l = 0; l < loops.count; ++l) {
                Corner ids[12];
                int n = 0;
                for (int k = 0; k < loops.size[l]; ++k) {
                    const int e = loops.edge[l][k];
                    const auto ec = edge_corners(e);
                    const int axis = e / 4, p = axis == 0 ? 1 : 0, q = axis == 2 ? 1 : 2;
                    const unsigned faces_of_edge = 1u << (2 * p + (ec[0] >> p & 1)) |
                                                   1u << (2 * q + (ec[0] >> q & 1));
                    const std::uint32_t id = vertex_id(pair_key(cells[c][ec[0]], cells[c][ec[1]]));
                    if (n > 0 && ids[n - 1].id == id)
                        ids[n - 1].faces |= faces_of_edge;
                    else
                        ids[n++] = Corner{id, faces_of_edge};
                }
                while (n > 1 && ids[n - 1].id == ids[0].id) ids[0].faces |= ids[--n].faces;
                // Split at vertices that repeat non-consecutively into simple loops.
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
                            if (loop[i].id == loop[j].id) { si = i; sj = j; break; }
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
        }
    });
    {
        std::vector<std::uint32_t> extra_base(n_chunks);
        std::uint32_t base = std::uint32_t(mesh.points.size());
        for (std::size_t ch = 0; ch < n_chunks; ++ch) {
            extra_base[ch] = base;
            base += std::uint32_t(chunk_extra[ch].size());
            stats.added_vertices += chunk_extra[ch].size();
            mesh.points.insert(mesh.points.end(), chunk_extra[ch].begin(), chunk_extra[ch].end());
        }
        for (std::size_t ch = 0; ch < n_chunks; ++ch)
            for (auto& t : chunk_tris[ch])
                for (int k = 0; k < 3; ++k)
                    if (t[k] & kExtra) t[k] = extra_base[ch] + (t[k] & ~kExtra);
    }
    std::vector<openvdb::Vec3I> tris;
    std::vector<openvdb::Vec4I> quad_loops;
    std::vector<std::uint32_t> quad_tri;
    for (std::size_t ch = 0; ch < n_chunks; ++ch) {
        const std::uint32_t base = std::uint32_t(tris.size());
        tris.insert(tris.end(), chunk_tris[ch].begin(), chunk_tris[ch].end());
        quad_loops.insert(quad_loops.end(), chunk_quads[ch].begin(), chunk_quads[ch].end());
        for (std::uint32_t t : chunk_quad_tri[ch]) quad_tri.push_back(base + t);
        std::vector<openvdb::Vec3I>().swap(chunk_tris[ch]);
    }

    // 5. Crossings placed on the same surface vertex are merged by edge
    // collapses that keep the mesh a closed 2-manifold (link condition).
    std::vector<std::uint32_t> rep;
    std::vector<std::uint8_t> alive;
    std::vector<std::uint64_t> tile(mesh.points.size(), kNoTile);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, pairs.size(), 4096),
                      [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            std::uint32_t a = std::uint32_t(pairs[i] >> 32), b = std::uint32_t(pairs[i]);
            if (!inside[a]) std::swap(a, b);
            if (!is_surface[a]) continue;
            int level = 0;
            while (level < tree.top && numbering.node_first[level + 1] <= a) ++level;
            const std::uint64_t code = tree.levels[level].code[a - numbering.node_first[level]];
            tile[i] = code >> (3 * (tree.top - level));
        }
    });
    collapse_coincident_vertices(mesh.points, tile, tris, rep, alive);
    for (std::uint32_t v = 0; v < rep.size(); ++v) stats.collapsed_vertices += rep[v] != v;
    std::vector<std::uint8_t> flipped;
    flip_collinear_triangles(mesh.points, tris, alive, flipped);

    // 6. Output: surviving faces, quads re-joined, vertices compacted.
    std::vector<std::uint8_t> in_quad(tris.size(), 0);
    for (std::size_t q = 0; q < quad_loops.size(); ++q) {
        const std::uint32_t t = quad_tri[q];
        openvdb::Vec4I v;
        for (int k = 0; k < 4; ++k) v[k] = rep[quad_loops[q][k]];
        const bool distinct = v[0] != v[1] && v[0] != v[2] && v[0] != v[3] && v[1] != v[2] &&
                              v[1] != v[3] && v[2] != v[3];
        if (alive[t] && alive[t + 1] && !flipped[t] && !flipped[t + 1] && distinct) {
            in_quad[t] = in_quad[t + 1] = 1;
            mesh.quads.push_back(v);
        }
    }
    for (std::size_t t = 0; t < tris.size(); ++t)
        if (alive[t] && !in_quad[t])
            mesh.triangles.emplace_back(rep[tris[t][0]], rep[tris[t][1]], rep[tris[t][2]]);
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
    separate_coincident_vertices(mesh, stats);
    stats.vertices = mesh.points.size();
    stats.triangles = mesh.triangles.size();
    stats.quads = mesh.quads.size();
    return mesh;
}

}  // namespace pqdc::adaptive_detail
