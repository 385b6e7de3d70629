// Adaptive stage "dual grid": dense ids for the leaves that can be corners
// of dual cells, and the dual cells of the octree (Schaefer & Warren 2004,
// "Dual Marching Cubes: Primal Contouring of Dual Grids", §3: the
// cell/face/edge/vertex recursion).
#pragma once

#include "adaptive/octree.hpp"
#include "lattice/resources.hpp"

#include <array>
#include <cstdint>
#include <vector>

namespace pqdc::adaptive_detail {

/// Dense ids of the leaves that can be corners of dual cells, so that the
/// polygonization indexes arrays instead of sorting and searching keys:
///  - [0, empty_first_id): the nodes of every level, level L's node i being
///    node_first[L] + i (only the leaves among them are used);
///  - then the missing (empty) children of internal nodes: internal node i of
///    level L numbers its missing octants, in increasing order, from
///    empty_first[L][i];
///  - then the missing roots next to present roots (sorted by code).
struct LeafNumbering {
    std::array<std::uint64_t, kMaxLevel + 2> node_first{};
    std::vector<std::vector<std::uint32_t>> empty_first;  ///< [level][node], internal nodes
    std::vector<std::uint64_t> missing_roots;             ///< sorted root codes
    std::uint64_t empty_first_id = 0;
    std::uint64_t missing_root_first_id = 0;
    std::uint64_t count = 0;
    /// leaf_key(level, code) of every empty id, at [id - empty_first_id].
    std::vector<std::uint64_t> empty_key;
};
LeafNumbering number_leaves(const Octree& tree);

/// Dual cells of the octree: the ids of the 8 leaves around every octree
/// corner whose neighbourhood holds surface, in octant order (x + 2y + 4z).
/// The span reports (and cancels) between chunks of root tasks.
using DualCell = std::array<std::uint32_t, 8>;
std::vector<DualCell> generate_dual_cells(const Octree& tree, const LeafNumbering& numbering,
                                          const detail::ProgressSpan& span);

}  // namespace pqdc::adaptive_detail
