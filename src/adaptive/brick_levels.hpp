// The octree's lowest levels brick by brick (issue 14: adaptive mode with
// memory bounded by the bricks, not by the finest level). A brick's finest
// cells merge into levels 1..kBrickLevels right after stage "hermite" built
// them, and only the nodes that stay in the octree are kept: the finest
// level is never held whole.
//
// Why a ring of one block makes a brick's levels exact: a parent of level
// L + 1 merges depending on its children and (2:1 balance, simplify.hpp) on
// whether the level-L cells around it, at most 2^L voxels away, are
// subdivided; their own merges depend on cells 2^(L-1) further, and so on
// down to level 1, whose merges depend on their children only. So the nodes
// of levels up to 3 (8-voxel cells) depend on finest cells at most
// 4 + 2 = 6 voxels outside them, and a brick built with the candidate
// blocks of the ring of blocks around it has exactly the in-core levels
// 0..3 inside it. The ring's own nodes are built and dropped.
#pragma once

#include "adaptive/octree.hpp"

#include <openvdb/openvdb.h>

#include <cstddef>
#include <vector>

namespace pqdc::adaptive_detail {

/// The highest level built brick by brick (cells of 2^3 voxels, one block:
/// see the file comment), or the root level when it is lower.
constexpr int kBrickLevels = 3;
inline int brick_levels(const Octree& frame) { return std::min(kBrickLevels, frame.top); }

/// Voxels beyond a brick whose values its levels read: the ring of blocks
/// (8), the finest cells' reach past a block (2) and the merge tests' probes
/// past a cell (central differences and trilinear samples: 2).
constexpr int kBrickLevelsReach = 8 + 2 + 2;

/// The candidate blocks (`sorted`: in Coord order) in the ring of blocks
/// around `brick` (a block-aligned box).
std::vector<openvdb::Coord> ring_blocks(const std::vector<openvdb::Coord>& sorted, const openvdb::CoordBBox& brick);

/// Appends to out[0..top] the nodes of `local` (levels 0..top built over a
/// brick and its ring) whose origin lies in `brick`, without the nodes below
/// a merged leaf (no later stage reads them); quadrics only at level `top`,
/// the only ones the next merges read. first_child is left for
/// sort_and_link. Returns the number of nodes appended.
std::size_t append_brick_nodes(const Octree& local, int top, const openvdb::CoordBBox& brick,
                               std::vector<Level>& out);

/// Puts every level of `levels` (each brick's nodes, appended in brick
/// order) in code order and sets first_child from the codes.
void sort_and_link(std::vector<Level>& levels);

}  // namespace pqdc::adaptive_detail
