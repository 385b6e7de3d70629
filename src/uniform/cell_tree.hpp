// The uniform extractor's cell tree: an Int32 OpenVDB tree with one active
// voxel per crossed cell, whose value packs what the face stage needs; each
// leaf's transient data holds its index in the candidate list (which orders
// the vertices: see leaf_first in faces.hpp). 32-bit records with the leaf
// index stored once per leaf, not in every record, halve the records' memory
// (2 KiB per surface leaf instead of 4 KiB: 0.12 GB on a 12.7 M-voxel sphere).
#pragma once

#include "lattice/cube.hpp"

#include <openvdb/openvdb.h>

#include <cstdint>

namespace pqdc::detail {

// Cell value layout: bits 0-7 corner signs, 8-13 faces whose ambiguity is
// resolved by cutting off outside corners (see join_face), 14-24 the cell's
// first vertex within its leaf's list.
using CellTree = openvdb::Int32Tree;
using CellLeaf = CellTree::LeafNodeType;
using CellValue = CellTree::ValueType;
constexpr int kLeafDim = int(CellLeaf::DIM);
constexpr int kLocalShift = 14;
constexpr int kLocalBits = 11;
static_assert(CellLeaf::SIZE * 4 <= (1 << kLocalBits), "local vertex index must fit");
static_assert(kLocalShift + kLocalBits <= 31, "a record must stay a non-negative int32");

inline CellValue pack_cell(std::uint8_t config, std::uint8_t joined, std::uint32_t first_vertex) {
    return CellValue(std::uint32_t(config) | (std::uint32_t(joined) << 8) | (first_vertex << kLocalShift));
}

/// The cell's first vertex within its leaf's vertex list.
inline std::uint32_t local_first_vertex(CellValue value) {
    return (std::uint32_t(value) >> kLocalShift) & ((1u << kLocalBits) - 1);
}

/// The surface patch (vertex offset within the cell) that edge `edge` of a cell belongs to.
inline int group_of_edge(const EdgeGroups* plain, CellValue value, int edge) {
    const auto joined = std::uint8_t((value >> 8) & 63);
    if (joined == 0) return plain[value & 255].group[edge];
    return edge_groups(std::uint8_t(value & 255), joined).group[edge];
}

}  // namespace pqdc::detail
