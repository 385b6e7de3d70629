// The uniform extractor's cell tree: an Int64 OpenVDB tree with one active
// voxel per crossed cell, whose value packs what the face stage needs.
#pragma once

#include "lattice/cube.hpp"

#include <openvdb/openvdb.h>

#include <cstdint>

namespace pqdc::detail {

// Cell value layout: bits 0-7 corner signs, 8-13 faces whose ambiguity is
// resolved by cutting off outside corners (see join_face), 14-24 the cell's
// first vertex within its leaf's list, 25+ the leaf's index.
using CellTree = openvdb::Int64Tree;
using CellLeaf = CellTree::LeafNodeType;
constexpr int kLeafDim = int(CellLeaf::DIM);
constexpr int kLocalShift = 14;
constexpr int kLeafShift = 25;
static_assert(CellLeaf::SIZE * 4 <= (1 << (kLeafShift - kLocalShift)), "local vertex index must fit");

inline std::int64_t pack_cell(std::uint8_t config, std::uint8_t joined, std::int64_t first_vertex, std::int64_t leaf) {
    return std::int64_t(config) | (std::int64_t(joined) << 8) | (first_vertex << kLocalShift) | (leaf << kLeafShift);
}

/// The surface patch (vertex offset within the cell) that edge `edge` of a cell belongs to.
inline int group_of_edge(const EdgeGroups* plain, std::int64_t value, int edge) {
    const auto joined = std::uint8_t((value >> 8) & 63);
    if (joined == 0) return plain[value & 255].group[edge];
    return edge_groups(std::uint8_t(value & 255), joined).group[edge];
}

}  // namespace pqdc::detail
