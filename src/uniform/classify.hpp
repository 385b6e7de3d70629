// Uniform stage "classify": which cells of one 8^3 leaf the surface crosses,
// their corner configurations and the choice on ambiguous faces.
#pragma once

#include "lattice/value_block.hpp"

#include <openvdb/openvdb.h>

#include <cstdint>
#include <vector>

namespace pqdc::detail {

struct ClassifiedCell {
    openvdb::Coord local;  ///< position in the leaf, [0, 8)^3
    std::uint8_t config;   ///< bit c: corner c inside (cube.hpp numbering)
    std::uint8_t joined;   ///< bit f: face f resolved by cutting off outside corners (join_face)
};

struct LeafCells {
    std::vector<ClassifiedCell> cells;  ///< in (x, y, z) order
    std::uint32_t faces = 0;            ///< owned crossing edges whose four cells take part
    std::uint32_t incidences = 0;       ///< (cell, crossing edge) pairs
    std::uint64_t non_finite = 0;       ///< active NaN points owned by the leaf
};

/// True when every point of the block lies on one side and none is NaN: no
/// cell of the leaf is crossed.
bool block_is_one_sided(const DenseBlock& block);

/// Classifies the cells of the leaf whose values are `block` (lattice points
/// origin - 1 .. origin + 9). A cell takes part (domain) when at least one of
/// its corners is active and none is NaN.
void classify_leaf(const DenseBlock& block, LeafCells& out);

}  // namespace pqdc::detail
