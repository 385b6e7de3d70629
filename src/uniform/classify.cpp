#include "uniform/classify.hpp"

#include "lattice/cube.hpp"
#include "uniform/cell_tree.hpp"

namespace pqdc::detail {
namespace {

/// Sign configuration of the cell at block point (x, y, z), and whether it
/// takes part (an active corner, no NaN corner).
std::uint8_t cell_config(const DenseBlock& b, int x, int y, int z, bool& domain) {
    std::uint8_t config = 0;
    unsigned on = 0, nan = 0;
    for (int c = 0; c < 8; ++c) {
        const int cx = x + (c & 1), cy = y + ((c >> 1) & 1), cz = z + ((c >> 2) & 1);
        config |= std::uint8_t(((b.inside_row[cx][cy] >> cz) & 1) << c);
        on |= (b.active_row[cx][cy] >> cz) & 1;
        nan |= (b.nan_row[cx][cy] >> cz) & 1;
    }
    domain = on && !nan;
    return config;
}

/// Ambiguous faces of the cell at block point l shared with a neighbour that
/// also tunnels through them: those are cut the other way (join_face).
std::uint8_t joined_faces(const DenseBlock& b, const openvdb::Coord& l, std::uint8_t config) {
    std::uint8_t joined = 0;
    for (unsigned tunnels = tunnel_faces(config); tunnels; tunnels &= tunnels - 1) {
        const int face = __builtin_ctz(tunnels);
        const int axis = face >> 1, side = face & 1;
        openvdb::Coord n = l;
        n[axis] += side ? 1 : -1;
        bool ndomain;
        const std::uint8_t nconfig = cell_config(b, n.x(), n.y(), n.z(), ndomain);
        if (ndomain && (side ? join_face(config, nconfig, axis) : join_face(nconfig, config, axis)))
            joined |= std::uint8_t(1u << face);
    }
    return joined;
}

}  // namespace

bool block_is_one_sided(const DenseBlock& b) {
    const int D = b.dim;
    unsigned all = 0xffffu, any = 0, nan = 0;
    for (int x = 0; x < D; ++x)
        for (int y = 0; y < D; ++y) {
            all &= b.inside_row[x][y];
            any |= b.inside_row[x][y];
            nan |= b.nan_row[x][y];
        }
    const unsigned full = (1u << D) - 1;
    return ((all & full) == full || (any & full) == 0) && !nan;
}

void classify_leaf(const DenseBlock& b, LeafCells& out) {
    out.cells.clear();
    out.faces = out.incidences = 0;
    out.non_finite = 0;
    const auto& in_row = b.inside_row;
    const auto& on_row = b.active_row;
    const auto& nan_row = b.nan_row;
    for (int x = 1; x <= kLeafDim; ++x)
        for (int y = 1; y <= kLeafDim; ++y)  // active NaN points owned by this leaf, each counted once
            out.non_finite += unsigned(__builtin_popcount(unsigned(nan_row[x][y] & on_row[x][y]) & 0x1feu));
    // usable[x + 1][y + 1] bit z + 1: cell (x, y, z) has an active corner
    // and no NaN corner, for x, y, z in [-1, 7] (this leaf's cells and its
    // lower neighbours', which decide whether an owned edge gets a face).
    std::uint16_t usable_row[kLeafDim + 1][kLeafDim + 1];
    for (int X = 0; X <= kLeafDim; ++X)
        for (int Y = 0; Y <= kLeafDim; ++Y) {
            const unsigned on = on_row[X][Y] | on_row[X + 1][Y] | on_row[X][Y + 1] | on_row[X + 1][Y + 1];
            const unsigned nan = nan_row[X][Y] | nan_row[X + 1][Y] | nan_row[X][Y + 1] | nan_row[X + 1][Y + 1];
            usable_row[X][Y] = std::uint16_t((on | (on >> 1)) & ~(nan | (nan >> 1)) & 0x1ffu);
        }
    auto usable = [&](int x, int y, int z) { return (usable_row[x + 1][y + 1] >> (z + 1)) & 1; };
    for (int x = 0; x < kLeafDim; ++x)
        for (int y = 0; y < kLeafDim; ++y) {
            // Which cells of this z-row are crossed and take part: 8 at a time.
            auto quad = [&](const std::uint16_t(&r)[DenseBlock::kMaxDim][DenseBlock::kMaxDim], bool conj) {
                const int X = x + 1, Y = y + 1;
                return conj ? std::uint16_t(r[X][Y] & r[X + 1][Y] & r[X][Y + 1] & r[X + 1][Y + 1])
                            : std::uint16_t(r[X][Y] | r[X + 1][Y] | r[X][Y + 1] | r[X + 1][Y + 1]);
            };
            const std::uint16_t in_all = quad(in_row, true), in_any = quad(in_row, false);
            const unsigned crossed = unsigned(in_any | (in_any >> 1)) & ~unsigned(in_all & (in_all >> 1));
            unsigned cells_in_row = ((crossed & usable_row[x + 1][y + 1]) >> 1) & 0xffu;  // bit z: cell (x, y, z)
            while (cells_in_row) {
                const int z = __builtin_ctz(cells_in_row);
                cells_in_row &= cells_in_row - 1;
                const openvdb::Coord l(x + 1, y + 1, z + 1);
                // Corner c = dx + 2 dy + 4 dz: row (dx, dy) gives bits c and c + 4.
                auto two = [&](int dx, int dy) {
                    const unsigned r = unsigned(in_row[l.x() + dx][l.y() + dy]) >> l.z();
                    return ((r & 1u) | ((r & 2u) << 3)) << (dx + 2 * dy);
                };
                const std::uint8_t config = std::uint8_t(two(0, 0) | two(1, 0) | two(0, 1) | two(1, 1));
                // Owned edges (from the minimum corner) that cross get a face
                // when the three other cells around them take part.
                for (int axis = 0; axis < 3; ++axis) {
                    if (!(((config >> (1 << axis)) ^ config) & 1)) continue;
                    const int u = (axis + 1) % 3, v = (axis + 2) % 3;
                    int cu[3] = {x, y, z}, cv[3] = {x, y, z}, cuv[3] = {x, y, z};
                    cu[u] -= 1;
                    cv[v] -= 1;
                    cuv[u] -= 1;
                    cuv[v] -= 1;
                    if (usable(cu[0], cu[1], cu[2]) && usable(cv[0], cv[1], cv[2]) && usable(cuv[0], cuv[1], cuv[2]))
                        ++out.faces;
                }
                out.incidences += std::uint32_t(__builtin_popcount(crossing_edges(config)));
                out.cells.push_back({openvdb::Coord(x, y, z), config, joined_faces(b, l, config)});
            }
        }
}

}  // namespace pqdc::detail
