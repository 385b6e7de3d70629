// Cube topology shared by both extractors: corner and edge numbering, the
// surface patches of a corner configuration (edge groups, for dual
// contouring's vertices), marching-cubes loops (for the octree's dual cells)
// and the manifold table (for the octree's merge test). Tested once, in
// tests/test_cube.cpp.
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

/// The edge joining two corners that differ in one coordinate.
constexpr int edge_between(int c0, int c1) {
    const int diff = c0 ^ c1;
    const int axis = diff == 1 ? 0 : (diff == 2 ? 1 : 2);
    const int start = c0 & c1;
    const int u = (start >> ((axis + 1) % 3)) & 1, v = (start >> ((axis + 2) % 3)) & 1;
    return 4 * axis + u + 2 * v;
}

namespace cube_tables {
constexpr std::array<std::uint16_t, 256> make_crossing_edges() {
    std::array<std::uint16_t, 256> t{};
    for (int c = 0; c < 256; ++c)
        for (int e = 0; e < 12; ++e)
            if (((c >> edge_start_corner(e)) ^ (c >> edge_end_corner(e))) & 1) t[c] |= std::uint16_t(1u << e);
    return t;
}
inline constexpr std::array<std::uint16_t, 256> kCrossingEdges = make_crossing_edges();
}  // namespace cube_tables

/// Bit e set: edge e of the configuration joins corners of different sides.
constexpr unsigned crossing_edges(std::uint8_t config) { return cube_tables::kCrossingEdges[config]; }

/// Surface patches of a cell: which patch each crossing edge belongs to.
struct EdgeGroups {
    std::int8_t group[12];  ///< patch index per edge, -1 for edges without sign change
    std::uint8_t count;     ///< number of patches (0..4)
};

/// Faces are numbered 2 * axis + side (side 0: the face at the cell's
/// minimum along axis, 1: at its maximum).
///
/// The connected surface patches of a cell as marching cubes would build
/// them, so two sheets in one cell get separate vertices. A face with two
/// diagonal inside corners is ambiguous: by default its two segments cut off
/// the inside corners (inside kept apart); bit f of `joined_faces` cuts off
/// the outside corners of face f instead. Both cells sharing a face must use
/// the same choice (see join_face()).
EdgeGroups edge_groups(std::uint8_t config, std::uint8_t joined_faces);
/// edge_groups(config, 0), by reference.
const EdgeGroups& edge_groups(std::uint8_t config);

/// True when face f of the configuration is ambiguous and its default
/// resolution puts both of its segments into one patch: the two inside
/// corners of the face are connected through the rest of the cell (a tunnel).
bool tunnel_through_face(std::uint8_t config, int face);
/// Bit f set: tunnel_through_face(config, f). One lookup for all six faces.
std::uint8_t tunnel_faces(std::uint8_t config);
/// The 256 edge_groups(config) entries, for hot loops (no call per lookup).
const EdgeGroups* plain_edge_groups();

/// The shared choice for the face between a cell (config `lower`, the face is
/// its side-1 face along axis) and its neighbour (config `upper`, side 0).
/// When both cells would put both segments of the face into one patch, their
/// two vertices would be joined by two mesh edges (four faces on one edge);
/// cutting off the outside corners instead removes the tunnel in at least one
/// of them (a cell cannot have a tunnel of both kinds through one face).
inline bool join_face(std::uint8_t lower, std::uint8_t upper, int axis) {
    return tunnel_through_face(lower, 2 * axis + 1) && tunnel_through_face(upper, 2 * axis);
}

/// Marching-cubes loops of a configuration (bit i set = corner i inside),
/// as sequences of edge indices, oriented counter-clockwise seen from outside
/// (the inside being the set corners). On every cube face the crossing where
/// a counter-clockwise walk enters the inside is joined to the next one where
/// it leaves, so ambiguous faces always separate the inside corners.
struct CubeLoops {
    std::uint8_t count = 0;
    std::uint8_t size[4] = {};
    std::uint8_t edge[4][12] = {};
};
const CubeLoops& cube_loops(std::uint8_t config);

/// True when the configuration gives one surface sheet whichever way
/// ambiguous faces are resolved (the "manifold" configurations of Ju et al.
/// 2002, "Dual Contouring of Hermite Data").
bool manifold_configuration(std::uint8_t config);

}  // namespace pqdc::detail
