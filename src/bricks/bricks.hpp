// Brick decomposition (issue 14, out-of-core meshing): the candidate leaves
// of the uniform extractor cut into runs that each cover one aligned box of
// whole level-1 internal nodes (128^3 voxels).
//
// The in-core output is in the tree order of the candidate leaves (root
// children by origin, then each node's children by table offset: x-major, z
// fastest). A cube of 2^3 or more level-1 nodes is not a run of that order
// (its z-rows are interleaved with the neighbouring cubes'), so a brick of
// more than one node is the box of the same volume that is a run: nodes
// stacked along z first, then y, then x, inside one root child.
//   brick_size  128   256        512        1024        2048        4096
//   extent      128^3 128^2x1024 128x256x4096 128x2048x4096 512x4096^2 4096^3
// Every brick's candidates are thus one contiguous run of the in-core list,
// and bricks below or behind a brick (lower x, y, z) come earlier.
#pragma once

#include <openvdb/openvdb.h>

#include <cstddef>
#include <utility>
#include <vector>

namespace pqdc {
class RankGroup;
}

namespace pqdc::detail {

/// One brick: its box (voxels, without halo) and its run [begin, end) of
/// the candidate list.
struct BrickRun {
    openvdb::CoordBBox box;
    std::size_t begin = 0, end = 0;
};

/// The voxels along x, y and z of a brick of `brick_size` (a power of two
/// in [128, 4096]: see the file comment).
openvdb::Coord brick_extent(int brick_size);

/// The minimum corner of the brick of `extent` (brick_extent) holding `p`.
inline openvdb::Coord brick_origin(const openvdb::Coord& p, const openvdb::Coord& extent) {
    return openvdb::Coord(p.x() & ~(extent.x() - 1), p.y() & ~(extent.y() - 1), p.z() & ~(extent.z() - 1));
}

/// The candidate leaf origins `leaves` (tree order) cut into bricks of
/// `brick_size`, in the same order. Throws std::logic_error if a brick's
/// leaves were not contiguous (the list was not in tree order).
std::vector<BrickRun> split_into_bricks(const std::vector<openvdb::Coord>& leaves, int brick_size);

/// The bricks [first, last) that rank `rank` of `ranks` meshes: the ranks
/// take contiguous runs in order, cut where the running count of candidate
/// leaves passes rank / ranks of the total (so a rank may get none).
std::pair<std::size_t, std::size_t> rank_bricks(const std::vector<BrickRun>& bricks, int rank, int ranks);

/// Leaf-aligned halo (voxels on every side) that a brick's tree needs so
/// that the cells stage reads the same values as from the whole tree:
/// `cells_reach` points beyond a candidate leaf (CellStage::reach, uniform/cells.hpp), and
/// with field smoothing the smoothed values of those points, each computed
/// from the raw values within two points of its leaf (whole leaves: a leaf
/// with a non-finite value within two points is left unsmoothed).
int brick_halo(int cells_reach, bool smoothing);

/// Whether leaf origin `a` comes before `b` in the tree order of a 5-4-3
/// tree: root children by origin, then x-major table order in each node.
bool tree_order_less(const openvdb::Coord& a, const openvdb::Coord& b);

/// Throws option_error unless 0 <= group.rank() < group.size().
void check_rank_group(const RankGroup& group);

}  // namespace pqdc::detail
