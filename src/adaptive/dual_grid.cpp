#include "adaptive/dual_grid.hpp"

#include "pqdc/exceptions.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <limits>
#include <string>

namespace pqdc::adaptive_detail {
namespace {

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

namespace {

/// The handle of the root at root coordinates (x, y, z): its index in the top
/// level and its leaf id, or -1 and the id of the missing (empty) root.
struct RootHandles {
    const Level& roots;
    const LeafNumbering& numbering;
    int top;

    Handle operator()(std::int64_t x, std::int64_t y, std::int64_t z) const {
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
    }
};

/// The recursions to run, root by root: each root's cell, and each face,
/// edge and vertex it shares with other roots, emitted by the first present
/// cell of its tuple (so each once, in the same order for any thread count).
std::vector<RootTask> root_tasks(const Level& roots, const RootHandles& root_handle) {
    const auto code_of = [](const std::int64_t (&b)[3]) {
        return morton(std::uint32_t(b[0]), std::uint32_t(b[1]), std::uint32_t(b[2]));
    };
    std::vector<RootTask> tasks;
    for (std::size_t r = 0; r < roots.size(); ++r) {
        const auto c = unmorton(roots.code[r]);
        const std::int64_t x = c[0], y = c[1], z = c[2];
        tasks.push_back({RootTask::cell, 0, roots.code[r]});
        for (int d = 0; d < 3; ++d) {
            const std::int64_t lo[3] = {x - (d == 0), y - (d == 1), z - (d == 2)};
            tasks.push_back({RootTask::face, std::uint8_t(d), roots.code[r]});
            if (root_handle(lo[0], lo[1], lo[2]).index < 0)
                tasks.push_back({RootTask::face, std::uint8_t(d), code_of(lo)});
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
                if (first) tasks.push_back({RootTask::edge, std::uint8_t(d), code_of(b)});
            }
        }
        for (int i = 0; i < 8; ++i) {
            const std::int64_t b[3] = {x - (i & 1), y - (i >> 1 & 1), z - (i >> 2 & 1)};
            bool first = true;
            for (int k = 0; k < i && first; ++k)
                first = root_handle(b[0] + (k & 1), b[1] + (k >> 1 & 1), b[2] + (k >> 2 & 1)).index < 0;
            if (first) tasks.push_back({RootTask::vertex, 0, code_of(b)});
        }
    }
    return tasks;
}

/// One task's recursion into `builder`.
void run_root_task(const RootTask& task, const RootHandles& root_handle, DualBuilder& builder) {
    const auto c = unmorton(task.base);
    const std::int64_t x = c[0], y = c[1], z = c[2];
    switch (task.kind) {
    case RootTask::cell:
        builder.cell(root_handle(x, y, z));
        break;
    case RootTask::face: {
        const int d = task.axis;
        builder.face(root_handle(x, y, z), root_handle(x + (d == 0), y + (d == 1), z + (d == 2)), d);
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
        for (int i = 0; i < 8; ++i) n[i] = root_handle(x + (i & 1), y + (i >> 1 & 1), z + (i >> 2 & 1));
        builder.vertex(n);
        break;
    }
    }
}

}  // namespace

std::vector<DualCell> generate_dual_cells(const Octree& tree, const LeafNumbering& numbering,
                                          const detail::ProgressSpan& span) {
    const RootHandles root_handle{tree.levels[tree.top], numbering, tree.top};
    const std::vector<RootTask> tasks = root_tasks(tree.levels[tree.top], root_handle);
    std::vector<std::vector<DualCell>> per_task(tasks.size());
    // A root's recursion takes up to ~10 ms (a root of 64^3 voxels full of surface).
    constexpr std::size_t kTasksPerReport = 16;
    detail::parallel_ranges(tasks.size(), 1, kTasksPerReport, span, [&](const tbb::blocked_range<std::size_t>& range) {
        for (std::size_t t = range.begin(); t != range.end(); ++t) {
            DualBuilder builder(tree, numbering, per_task[t]);
            run_root_task(tasks[t], root_handle, builder);
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
}  // namespace pqdc::adaptive_detail
