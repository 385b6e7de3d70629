// A brick store's index (pqdc/brick_store.hpp), checked, and one brick file
// opened (issue 14). The index is a few lines per brick, so a store can be
// meshed with only the index in memory and the files opened one at a time
// (bricks/store_files.hpp).
#pragma once

#include "pqdc/exceptions.hpp"

#include <openvdb/openvdb.h>

#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace pqdc::detail {

/// The first line of index.txt. Version 2 ends with a line "end N" (N: the
/// brick lines), so that a cut or shortened index is refused instead of
/// meshing part of the volume. Version 3 adds every file's checksum
/// (bricks/file_digest.hpp), so that a damaged file is refused before
/// OpenVDB parses it. Versions 1 (no end line) and 2 are still read.
inline constexpr const char* kStoreIndexMagic = "pqdc-brick-store 3";
inline constexpr const char* kStoreIndexMagicV2 = "pqdc-brick-store 2";
inline constexpr const char* kStoreIndexMagicV1 = "pqdc-brick-store 1";

/// The name of the k-th brick file (from 0) that pqdc-bricks writes.
std::string brick_file_name(std::size_t k);

/// One brick file of a store: its name in the store directory and the box
/// (voxels) of the volume it holds.
struct StoreBrickFile {
    std::string file;
    openvdb::CoordBBox box;
    std::uint64_t bytes = 0;  ///< the file's size
    std::string digest;       ///< file_digest() of the file; empty in stores before format 3
};

/// Throws input_error naming the store and the file unless the file at
/// `path` has `digest` (file_digest()); an empty `digest` (a store before
/// format 3) is not checked.
void check_file_digest(const std::string& store, const std::string& path, const std::string& digest);

/// index.txt of the store in `dir`, checked: the format line, every brick
/// line, the end line with their count (version 2), the files' sizes (where the index records them: stores written
/// before that end their lines after the box), and that the boxes are one
/// brick extent (pqdc/bricks.hpp) on its aligned grid, each at most once.
class StoreIndex {
public:
    /// Throws input_error naming the store, the file or the line, with what to do.
    explicit StoreIndex(const std::string& dir);

    const std::string& dir() const { return dir_; }
    /// The path of the shell grid (the grid without voxels).
    std::string shell_path() const;
    /// file_digest() of the shell grid's file; empty in stores before format 3.
    const std::string& shell_digest() const { return shell_digest_; }
    const std::vector<StoreBrickFile>& bricks() const { return bricks_; }
    /// The bricks (indices into bricks()) whose boxes overlap `box`, in index order.
    std::vector<std::size_t> overlapping(const openvdb::CoordBBox& box) const;
    /// The brick whose box holds `p`, or bricks().size() when none does.
    std::size_t holding(const openvdb::Coord& p) const;

private:
    /// The line after the format line: "shell grid.vdb", and from format 3
    /// the file's size and checksum.
    void read_shell_line(const std::string& line, bool has_digests);

    std::string dir_;
    std::string shell_digest_;
    std::vector<StoreBrickFile> bricks_;
    openvdb::Coord extent_{0};  // of every brick's box (brick_extent of the split's size)
    std::map<openvdb::Coord, std::size_t> by_min_;
};

/// Opens the grid of brick file `file` of `store` with delayed loading
/// (mapped, not copied). Throws input_error naming the store and the file.
openvdb::GridBase::Ptr open_brick_file(const std::string& store, const std::string& file);

/// Throws input_error unless brick file `file`'s grid `brick` is a piece of
/// the store's `shell`: the same name, transform and background (the
/// backgrounds given as doubles; NaN matches NaN). A file from another
/// volume meshed silently at another scale.
void check_brick_identity(const std::string& store, const StoreBrickFile& file, const openvdb::GridBase& brick,
                          double brick_background, const openvdb::GridBase& shell, double shell_background);

/// Throws input_error naming the brick unless every level-1 node and active
/// tile of `tree` lies inside the brick's index box (a file moved to another
/// brick's name left a hole where it belonged).
template <class TreeT>
void check_brick_contents(const std::string& store, const StoreBrickFile& file, const TreeT& tree) {
    using Node1 = typename TreeT::RootNodeType::ChildNodeType::ChildNodeType;
    for (auto n2 = tree.root().cbeginChildOn(); n2; ++n2) {
        bool inside = true;
        for (auto c = n2->cbeginChildOn(); c && inside; ++c) inside = file.box.isInside(c->getNodeBoundingBox());
        for (auto t = n2->cbeginValueOn(); t && inside; ++t)
            inside = file.box.isInside(openvdb::CoordBBox::createCube(t.getCoord(), int(Node1::DIM)));
        if (!inside)
            throw input_error("brick store '" + store + "': '" + file.file + "' holds voxels outside its box " +
                              "in index.txt (from " + std::to_string(file.box.min().x()) + "," +
                              std::to_string(file.box.min().y()) + "," + std::to_string(file.box.min().z()) +
                              "): files were renamed or swapped; split the volume again with pqdc-bricks split");
    }
}

/// open_brick_file() as a GridT (the store's value type), checked against
/// the store's shell and the file's index box; input_error when it is not
/// the store's (another value type, name, transform or background, or
/// voxels outside its box).
template <class GridT>
typename GridT::Ptr open_typed_brick_file(const std::string& store, const StoreBrickFile& file, const GridT& shell) {
    typename GridT::Ptr grid = openvdb::gridPtrCast<GridT>(open_brick_file(store, file.file));
    if (!grid)
        throw input_error("brick store '" + store + "': '" + file.file +
                          "' holds another value type than the store's grid.vdb; split the volume again with "
                          "pqdc-bricks split");
    check_brick_identity(store, file, *grid, double(grid->background()), shell, double(shell.background()));
    check_brick_contents(store, file, grid->tree());
    return grid;
}

}  // namespace pqdc::detail
