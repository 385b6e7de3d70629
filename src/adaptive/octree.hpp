// Internal data structures shared by adaptive.cpp (Hermite data, octree
// simplification) and adaptive_dual.cpp (dual grid, marching cubes). Not
// installed.
#pragma once

#include "pqdc/adaptive.hpp"
#include "pqdc/quadric.hpp"

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

/// A sum of point quadrics |x - q_i|^2 kept as its five independent numbers
/// (its matrix is count * I): 40 bytes instead of a quadricd's 80, on every
/// finest cell.
struct PointSum {
    double count = 0;
    vec3<double> sum{};
    double sum_sq = 0;

    void add(const vec3<double>& q) {
        count += 1;
        sum += q;
        sum_sq += dot(q, q);
    }
    PointSum& operator+=(const PointSum& o) {
        count += o.count;
        sum += o.sum;
        sum_sq += o.sum_sq;
        return *this;
    }
    /// The same sum with the points expressed relative to `origin`, with the
    /// arithmetic of quadric::relative_to (long double), so both stay exact
    /// to the same degree.
    PointSum relative_to(const vec3<double>& origin) const {
        using W = long double;
        const vec3<W> s(sum), o(origin);
        const vec3<W> Ao = o * W(count);
        PointSum r;
        r.count = count;
        r.sum = vec3<double>(s - Ao);
        r.sum_sq = double(W(sum_sq) - W(2) * dot(s, o) + dot(o, Ao));
        return r;
    }
    quadricd as_quadric() const { return {sym3<double>::identity(count), sum, sum_sq}; }
};

/// Sums of a cell's Hermite data, in coordinates relative to the cell's
/// origin (voxels). `classical`: plane quadrics <x - q, n>^2 (point quadrics
/// |x - q|^2 for degenerate normals); `points`: point quadrics |x - q|^2 of
/// every crossing, so that classical + sigma_n^2 * points is the
/// probabilistic plane quadric sum and points.count is the sample count.
struct CellQuadrics {
    quadricd classical;
    PointSum points;
};

enum NodeFlags : std::uint8_t {
    kLeaf = 1,      ///< a leaf (finest surface cell or merged parent)
    kManifold = 2,  ///< leaf whose surface may merge further (manifold sign configuration)
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
    std::int64_t find(std::uint64_t c) const;
};

struct Octree {
    std::vector<Level> levels;  ///< levels[L] holds cells of edge 2^L voxels
    int top = 0;                ///< the root level
    openvdb::Coord offset;      ///< index coordinate of Morton code 0 (aligned to 2^top)

    /// Index-space origin of a cell.
    openvdb::Coord origin(int level, std::uint64_t code) const {
        const auto c = unmorton(code);
        return offset + openvdb::Coord(int(c[0]) << level, int(c[1]) << level, int(c[2]) << level);
    }
};

/// Per-thread evaluation of the signed field g (negative inside) at
/// index-space points.
class FieldProbe {
public:
    virtual ~FieldProbe() = default;
    virtual double value(const openvdb::Vec3d& p_index) = 0;
};
/// |grad g| at an index-space point (central differences, half a voxel apart).
double field_gradient_length(FieldProbe& probe, const openvdb::Vec3d& p_index);
/// First-order distance |g(p)| / gradient_length from an index-space point to
/// the surface, in voxels, with a gradient length measured at or near p
/// (field_gradient_length); infinity where it vanishes or g is not finite.
double field_distance_voxels(FieldProbe& probe, const openvdb::Vec3d& p_index, double gradient_length);
/// One Newton step of p towards g = 0 along the gradient (p itself where the
/// gradient vanishes or the step would leave a box of `reach` voxels).
openvdb::Vec3d project_to_surface(FieldProbe& probe, const openvdb::Vec3d& p_index, double reach);

class FieldSource {
public:
    virtual ~FieldSource() = default;
    virtual std::unique_ptr<FieldProbe> probe() const = 0;
};

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
using DualCell = std::array<std::uint32_t, 8>;
std::vector<DualCell> generate_dual_cells(const Octree& tree, const LeafNumbering& numbering);

/// Marching cubes on the dual cells; returns an index-space mesh (points are
/// converted to world space by the caller).
Mesh polygonize_dual_cells(const Octree& tree, const LeafNumbering& numbering,
                           const std::vector<DualCell>& cells, const FieldSource& field, FaceType faces,
                           AdaptiveStats& stats);

/// Marching-cubes loops of a corner sign mask (bit i set = corner i inside),
/// as sequences of cube edge indices, oriented counter-clockwise seen from
/// outside. Edge e joins corners edge_corners(e)[0] and [1].
struct CubeLoops {
    std::uint8_t count = 0;
    std::uint8_t size[4] = {};
    std::uint8_t edge[4][12] = {};
};
const CubeLoops& cube_loops(unsigned mask);
std::array<int, 2> edge_corners(int edge);
/// True when the mask gives one surface sheet whichever way ambiguous faces
/// are resolved (the "manifold" sign configurations of Ju et al. 2002).
bool manifold_configuration(unsigned mask);

}  // namespace pqdc::adaptive_detail
