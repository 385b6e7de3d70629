// The adaptive extractor's octree: Morton-coded nodes per level, built from
// the finest surface cells (finest_level.hpp) upwards (simplify.hpp), read by
// the dual grid (dual_grid.hpp) and the polygons (polygonize.hpp).
#pragma once

#include "pqdc/adaptive.hpp"
#include "lattice/cell_quadric.hpp"
#include "pqdc/quadric.hpp"

#include <algorithm>

#include <openvdb/openvdb.h>

#include <array>
#include <cstdint>
#include <memory>
#include <vector>

namespace pqdc::adaptive_detail {

/// Index coordinates are stored relative to an origin aligned to the largest
/// cell size, with this many bits per axis (3 * 19 = 57-bit Morton codes).
constexpr int kCoordBits = 19;
constexpr int kMaxLevel = 12;  // cells of 4096 voxels

inline std::uint64_t spread_bits(std::uint64_t v) {
    v &= 0x1fffff;
    v = (v | v << 32) & 0x1f00000000ffffULL;
    v = (v | v << 16) & 0x1f0000ff0000ffULL;
    v = (v | v << 8) & 0x100f00f00f00f00fULL;
    v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
    v = (v | v << 2) & 0x1249249249249249ULL;
    return v;
}
inline std::uint64_t compact_bits(std::uint64_t v) {
    v &= 0x1249249249249249ULL;
    v = (v ^ (v >> 2)) & 0x10c30c30c30c30c3ULL;
    v = (v ^ (v >> 4)) & 0x100f00f00f00f00fULL;
    v = (v ^ (v >> 8)) & 0x1f0000ff0000ffULL;
    v = (v ^ (v >> 16)) & 0x1f00000000ffffULL;
    v = (v ^ (v >> 32)) & 0x1fffff;
    return v;
}
/// Set bits of an 8-bit child mask. __builtin_popcount becomes a libgcc call
/// without -mpopcnt (not in Debian's x86-64 baseline), which took 5% of the
/// dual-grid recursion.
inline int popcount8(unsigned v) {
    v &= 0xffu;
    v = v - ((v >> 1) & 0x55u);
    v = (v & 0x33u) + ((v >> 2) & 0x33u);
    return int((v + (v >> 4)) & 0x0fu);
}

/// Morton code with x in bit 0 of every triple, so that the low three bits of
/// a code are the octant (x + 2y + 4z) of the cell inside its parent.
inline std::uint64_t morton(std::uint32_t x, std::uint32_t y, std::uint32_t z) {
    return spread_bits(x) | spread_bits(y) << 1 | spread_bits(z) << 2;
}
inline std::array<std::uint32_t, 3> unmorton(std::uint64_t m) {
    return {std::uint32_t(compact_bits(m)), std::uint32_t(compact_bits(m >> 1)),
            std::uint32_t(compact_bits(m >> 2))};
}

/// A leaf of the octree as a single key: level in the top bits, the Morton
/// code of (origin - offset) >> level below.
inline std::uint64_t leaf_key(int level, std::uint64_t code) {
    return std::uint64_t(level) << 58 | code;
}
inline int key_level(std::uint64_t key) { return int(key >> 58); }
inline std::uint64_t key_code(std::uint64_t key) { return key & ((std::uint64_t(1) << 58) - 1); }

/// A cell's Hermite data (lattice/cell_quadric.hpp), relative to the cell's origin.
using CellQuadrics = detail::CellQuadric;

enum NodeFlags : std::uint8_t {
    kLeaf = 1,      ///< a leaf (finest surface cell or merged parent)
    kManifold = 2,  ///< leaf whose surface may merge further (manifold sign configuration, not at an edge of the mesh)
};

/// The nodes of one octree level holding surface, sorted by Morton code.
struct Level {
    std::vector<std::uint64_t> code;
    std::vector<std::uint8_t> flags;
    std::vector<std::uint8_t> child_mask;   ///< internal nodes: which children hold surface (empty at level 0)
    std::vector<std::uint32_t> first_child; ///< internal nodes: index of the first child in the level below (empty at level 0)
    std::vector<CellQuadrics> quadrics;     ///< leaves
    std::vector<openvdb::Vec3d> vertex;     ///< leaves: index-space vertex position

    std::size_t size() const { return code.size(); }
    /// Index of the node with this code, or -1.
    std::int64_t find(std::uint64_t c) const {
        const auto it = std::lower_bound(code.begin(), code.end(), c);
        if (it == code.end() || *it != c) return -1;
        return it - code.begin();
    }
};

struct Octree {
    std::vector<Level> levels;  ///< levels[L] holds cells of edge 2^L voxels
    int top = 0;                ///< the root level
    openvdb::Coord offset;      ///< index coordinate of Morton code 0 (aligned to 2^top)

    /// Index-space origin of a cell.
    openvdb::Coord origin(int level, std::uint64_t code) const {
        const auto c = unmorton(code);
        // The codes of missing roots beside a root at code 0 wrap around to
        // 2^19 - 1; in 64 bits the arithmetic stays defined (converted back
        // modulo 2^32, the value the 32-bit expression always produced).
        auto axis = [&](int a) { return int(std::int64_t(offset[a]) + (std::int64_t(c[a]) << level)); };
        return openvdb::Coord(axis(0), axis(1), axis(2));
    }
};

}  // namespace pqdc::adaptive_detail
