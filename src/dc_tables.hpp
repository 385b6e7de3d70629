// Cell topology tables shared by the dual contouring stages (internal).
//
// Corner i of a cell sits at offset (i & 1, (i >> 1) & 1, (i >> 2) & 1).
// Edge e = 4 * axis + u + 2 * v runs along `axis` from the corner whose
// coordinates along the two other axes (next = (axis+1)%3, after = (axis+2)%3)
// are u and v. A configuration has bit i set when corner i is inside.
#pragma once

#include <array>
#include <cstdint>

namespace pqdc::detail {

constexpr int edge_start_corner(int edge) {
    const int axis = edge >> 2, u = edge & 1, v = (edge >> 1) & 1;
    return (u << ((axis + 1) % 3)) | (v << ((axis + 2) % 3));
}
constexpr int edge_end_corner(int edge) { return edge_start_corner(edge) | (1 << (edge >> 2)); }

/// Surface patches of a cell: which patch each crossing edge belongs to.
struct EdgeGroups {
    std::int8_t group[12];  ///< patch index per edge, -1 for edges without sign change
    std::uint8_t count;     ///< number of patches (0..4)
};

/// For every configuration, the connected surface patches as marching cubes
/// would build them, so two sheets in one cell get separate vertices. Face
/// ambiguities (two diagonal inside corners on a face) are resolved by keeping
/// the inside corners apart; the rule depends only on the face's four signs,
/// so the two cells sharing a face always agree.
const std::array<EdgeGroups, 256>& edge_group_table();

}  // namespace pqdc::detail
