#include "dc_tables.hpp"

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

EdgeGroups build(int config) {
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
                // Ambiguous face: cut off each inside corner with its own segment.
                for (int i = 0; i < 4; ++i)
                    if (inside(corners[i])) uf.unite(edges[(i + 3) % 4], edges[i]);
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

}  // namespace

const std::array<EdgeGroups, 256>& edge_group_table() {
    static const std::array<EdgeGroups, 256> table = [] {
        std::array<EdgeGroups, 256> t{};
        for (int c = 0; c < 256; ++c) t[c] = build(c);
        return t;
    }();
    return table;
}

}  // namespace pqdc::detail
