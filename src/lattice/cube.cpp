#include "lattice/cube.hpp"

#include <algorithm>
#include <iterator>

namespace pqdc::detail {
namespace {

struct UnionFind {
    int parent[12];
    UnionFind() {
        for (int i = 0; i < 12; ++i) parent[i] = i;
    }
    int find(int i) {
        while (parent[i] != i) i = parent[i] = parent[parent[i]];
        return i;
    }
    void unite(int a, int b) {
        a = find(a);
        b = find(b);
        // Smaller root wins so the table does not depend on union order.
        if (a < b) parent[b] = a;
        else if (b < a) parent[a] = b;
    }
};

EdgeGroups build(int config, int joined_faces) {
    auto inside = [config](int corner) { return (config >> corner) & 1; };
    auto crossing = [&](int edge) { return inside(edge_start_corner(edge)) != inside(edge_end_corner(edge)); };

    UnionFind uf;
    for (int axis = 0; axis < 3; ++axis) {
        for (int w = 0; w < 2; ++w) {
            const int p = (axis + 1) % 3, q = (axis + 2) % 3;
            const int corners[4] = {w << axis, (w << axis) | (1 << p), (w << axis) | (1 << p) | (1 << q),
                                    (w << axis) | (1 << q)};
            int edges[4];
            int crossings = 0;
            for (int i = 0; i < 4; ++i) {
                edges[i] = edge_between(corners[i], corners[(i + 1) % 4]);
                crossings += crossing(edges[i]);
            }
            if (crossings == 2) {
                int first = -1;
                for (int e : edges) {
                    if (!crossing(e)) continue;
                    if (first < 0) first = e;
                    else uf.unite(first, e);
                }
            } else if (crossings == 4) {
                // Ambiguous face: each segment cuts off one corner of the
                // class that stays apart (inside by default).
                const bool cut_inside = !((joined_faces >> (2 * axis + w)) & 1);
                for (int i = 0; i < 4; ++i)
                    if (bool(inside(corners[i])) == cut_inside) uf.unite(edges[(i + 3) % 4], edges[i]);
            }
        }
    }

    EdgeGroups g{};
    g.count = 0;
    int root_group[12];
    for (int i = 0; i < 12; ++i) root_group[i] = -1;
    for (int e = 0; e < 12; ++e) {
        g.group[e] = -1;
        if (!crossing(e)) continue;
        const int r = uf.find(e);
        if (root_group[r] < 0) root_group[r] = g.count++;
        g.group[e] = static_cast<std::int8_t>(root_group[r]);
    }
    return g;
}

bool is_tunnel(int config, int face) {
    const int axis = face >> 1, w = face & 1;
    const int p = (axis + 1) % 3, q = (axis + 2) % 3;
    const int corners[4] = {w << axis, (w << axis) | (1 << p), (w << axis) | (1 << p) | (1 << q),
                            (w << axis) | (1 << q)};
    auto inside = [config](int c) { return (config >> c) & 1; };
    const bool ambiguous = inside(corners[0]) == inside(corners[2]) && inside(corners[1]) == inside(corners[3]) &&
                           inside(corners[0]) != inside(corners[1]);
    if (!ambiguous) return false;
    const EdgeGroups g = build(config, 0);
    // The face's four edges all cross; with the default rule they form two
    // segments. A tunnel means all four belong to one patch.
    int group = -1;
    for (int i = 0; i < 4; ++i) {
        const int c0 = corners[i], c1 = corners[(i + 1) % 4];
        const int e = edge_between(c0, c1);
        if (group < 0) group = g.group[e];
        else if (g.group[e] != group) return false;
    }
    return true;
}

struct Tables {
    std::array<EdgeGroups, 256> plain;      // no face joined: nearly every cell
    std::array<std::uint8_t, 256> tunnels;  // bit f: tunnel through face f
};

const Tables& tables() {
    static const Tables t = [] {
        Tables t;
        for (int c = 0; c < 256; ++c) {
            t.plain[c] = build(c, 0);
            t.tunnels[c] = 0;
            for (int f = 0; f < 6; ++f)
                if (is_tunnel(c, f)) t.tunnels[c] |= std::uint8_t(1u << f);
        }
        return t;
    }();
    return t;
}

// Loops of one configuration, walking each face counter-clockwise around its
// outward normal: the crossing where the walk enters the inside is joined to
// the next crossing where it leaves.
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
            for (int i = 0; i < 4; ++i) corner[i] = side << d | uv[i][0] << u | uv[i][1] << v;
            if ((side == 1 ? 1 : -1) * natural < 0) std::reverse(corner, corner + 4);
            int enter[2], exit_[2], ne = 0, nx = 0, enter_pos[2], exit_pos[2];
            for (int i = 0; i < 4; ++i) {
                const int a = corner[i], b = corner[(i + 1) % 4];
                const bool ia = mask >> a & 1, ib = mask >> b & 1;
                if (ia && !ib) {
                    exit_pos[nx] = i;
                    exit_[nx++] = edge_between(a, b);
                }
                if (!ia && ib) {
                    enter_pos[ne] = i;
                    enter[ne++] = edge_between(a, b);
                }
            }
            for (int k = 0; k < ne; ++k) {
                // The first exit after this entry, walking on.
                int best = -1, best_dist = 5;
                for (int m = 0; m < nx; ++m) {
                    const int dist = (exit_pos[m] - enter_pos[k] + 4) % 4;
                    if (dist > 0 && dist < best_dist) {
                        best_dist = dist;
                        best = m;
                    }
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
        for (unsigned m = 0; m < 256; ++m) manifold[m] = loops[m].count == 1 && loops[255 - m].count == 1;
    }
};

const LoopTable& loop_table() {
    static const LoopTable table;
    return table;
}

}  // namespace

const EdgeGroups& edge_groups(std::uint8_t config) { return tables().plain[config]; }

EdgeGroups edge_groups(std::uint8_t config, std::uint8_t joined_faces) {
    // Joined faces need two neighbouring tunnels: rare enough to build on demand.
    if ((joined_faces & 63) == 0) return tables().plain[config];
    return build(config, joined_faces & 63);
}

bool tunnel_through_face(std::uint8_t config, int face) { return (tables().tunnels[config] >> face) & 1; }
std::uint8_t tunnel_faces(std::uint8_t config) { return tables().tunnels[config]; }
const EdgeGroups* plain_edge_groups() { return tables().plain.data(); }

const CubeLoops& cube_loops(std::uint8_t config) { return loop_table().loops[config]; }
bool manifold_configuration(std::uint8_t config) { return loop_table().manifold[config]; }

}  // namespace pqdc::detail
