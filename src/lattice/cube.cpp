#include "lattice/cube.hpp"

namespace pqdc::detail {
namespace {

int edge_between(int c0, int c1) {
    const int diff = c0 ^ c1;
    const int axis = diff == 1 ? 0 : (diff == 2 ? 1 : 2);
    const int start = c0 & c1;
    const int u = (start >> ((axis + 1) % 3)) & 1, v = (start >> ((axis + 2) % 3)) & 1;
    return 4 * axis + u + 2 * v;
}

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

}  // namespace pqdc::detail
