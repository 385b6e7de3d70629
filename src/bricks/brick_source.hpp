// Where a brick's values come from (issue 14): one small interface, so the
// out-of-core driver does not depend on how the volume is stored. OpenVDB's
// delayed loading (memory-mapped leaf buffers, read when touched) is one
// such store; it is gone from OpenVDB's development branch, and a brick
// store of small files is another, so the driver sees only this.
//
// Traps of delay-loaded trees, which the copy below avoids: a ValueAccessor
// loads a leaf's buffer when it caches the leaf (probeConstLeaf, getValue,
// isValueOn), and tools::clip loads every leaf; the tree's own node
// pointers do not. Copying a LeafNode copies its out-of-core file
// reference, so reading the copy loads only the copy, freed with it. The
// copy reads its inactive values against the background of the grid it
// was read with (the stream metadata points at that grid's tree), so that
// grid must outlive the copies.
#pragma once

#include "lattice/candidates.hpp"

#include <openvdb/openvdb.h>

#include <type_traits>
#include <vector>

namespace pqdc {
class RankGroup;
}

namespace pqdc::detail {

template <class TreeT>
class BrickSource {
public:
    using ValueT = typename TreeT::ValueType;
    virtual ~BrickSource() = default;
    /// The volume's background (inactive) value.
    virtual ValueT background() const = 0;
    /// candidate_blocks (lattice/candidates.hpp) of the whole volume, in tree
    /// order. Collective: every rank of `group` calls it and gets the whole
    /// list (a source may share the work among them).
    virtual std::vector<openvdb::Coord> candidate_blocks(double bytes_per_block, const ExtractOptions& options,
                                                         const openvdb::CoordBBox& clip, RankGroup& group) const = 0;
    /// Whether voxel `p` is active (from the masks: no value is read).
    virtual bool is_value_on(const openvdb::Coord& p) const = 0;
    /// Adds to `into` (same background) the source's leaves and tiles that
    /// overlap `box`, so that `into` holds the source's values and active
    /// states at every point of `box`. Leaves `into` already has are kept.
    virtual void copy_box(const openvdb::CoordBBox& box, TreeT& into) const = 0;
};

/// f(origin) for every node of `step` voxels inside `node` that overlaps `box`.
template <class F>
void for_each_node_overlap(const openvdb::CoordBBox& node, const openvdb::CoordBBox& box, int step, const F& f) {
    openvdb::CoordBBox part = node;
    part.intersect(box);
    if (part.empty()) return;
    const openvdb::Coord lo = part.min() & ~(step - 1);
    for (int x = lo.x(); x <= part.max().x(); x += step)
        for (int y = lo.y(); y <= part.max().y(); y += step)
            for (int z = lo.z(); z <= part.max().z(); z += step) f(openvdb::Coord(x, y, z));
}

/// Copies what overlaps `box` from the level-1 node `n1` (128^3 voxels)
/// into `into`: the whole node as one deep copy when `box` holds it, else
/// its leaves and tiles that overlap `box`. Leaf copies keep their file
/// references, so nothing is loaded.
template <class TreeT>
void copy_node1_box(const typename TreeT::RootNodeType::ChildNodeType::ChildNodeType& n1,
                    const openvdb::CoordBBox& box, TreeT& into) {
    using Node2 = typename TreeT::RootNodeType::ChildNodeType;  // a root child, 4096^3 voxels
    using Node1 = typename Node2::ChildNodeType;                 // 128^3 voxels
    using LeafT = typename Node1::ChildNodeType;
    static_assert(std::is_same_v<LeafT, typename TreeT::LeafNodeType>, "a 5-4-3 tree");
    const openvdb::CoordBBox b1 = n1.getNodeBoundingBox();
    if (box.isInside(b1)) {
        into.addTile(Node2::LEVEL, b1.min(), into.background(), false);  // makes sure the root child exists
        into.root().template probeNode<Node2>(b1.min())->addChild(new Node1(n1));
        return;
    }
    for_each_node_overlap(b1, box, int(LeafT::DIM), [&](const openvdb::Coord& p) {
        const openvdb::Index n = Node1::coordToOffset(p);
        if (n1.isChildMaskOn(n)) {
            if (!into.probeConstLeaf(p)) into.addLeaf(new LeafT(*n1.getTable()[n].getChild()));
        } else {
            into.addTile(Node1::LEVEL, p, n1.getTable()[n].getValue(), n1.isValueMaskOn(n));
        }
    });
}

/// Copies what overlaps `box` from `src` into `into` (see copy_box above)
/// through node pointers only, so no buffer of `src` is loaded.
template <class TreeT>
void copy_tree_box(const TreeT& src, const openvdb::CoordBBox& box, TreeT& into) {
    using RootT = typename TreeT::RootNodeType;
    using Node2 = typename RootT::ChildNodeType;
    const RootT& root = src.root();
    for (auto it = root.cbeginValueAll(); it; ++it) {
        const openvdb::CoordBBox tile = openvdb::CoordBBox::createCube(it.getCoord(), int(Node2::DIM));
        if (tile.hasOverlap(box)) into.addTile(RootT::LEVEL, tile.min(), *it, it.isValueOn());
    }
    for (auto it = root.cbeginChildOn(); it; ++it) {
        const Node2& n2 = *it;
        for_each_node_overlap(n2.getNodeBoundingBox(), box, int(Node2::ChildNodeType::DIM), [&](const openvdb::Coord& p) {
            const openvdb::Index n = Node2::coordToOffset(p);
            if (n2.isChildMaskOn(n)) copy_node1_box(*n2.getTable()[n].getChild(), box, into);
            else into.addTile(Node2::LEVEL, p, n2.getTable()[n].getValue(), n2.isValueMaskOn(n));
        });
    }
}

/// A tree the caller keeps alive: a grid in memory or one read from a .vdb
/// file with delayed loading (io::File::open(true)), whose buffers then stay
/// in the file and are read only through the bricks' copies.
template <class TreeT>
class TreeBrickSource : public BrickSource<TreeT> {
public:
    using typename BrickSource<TreeT>::ValueT;
    explicit TreeBrickSource(const TreeT& tree) : tree_(tree) {}
    ValueT background() const override { return tree_.background(); }
    std::vector<openvdb::Coord> candidate_blocks(double bytes_per_block, const ExtractOptions& options,
                                                 const openvdb::CoordBBox& clip, RankGroup&) const override {
        return detail::candidate_blocks(tree_, bytes_per_block, options, clip);
    }
    // The tree's own lookup, not an accessor's: it reads masks, never a buffer.
    bool is_value_on(const openvdb::Coord& p) const override { return tree_.isValueOn(p); }
    void copy_box(const openvdb::CoordBBox& box, TreeT& into) const override { copy_tree_box(tree_, box, into); }

private:
    const TreeT& tree_;
};

}  // namespace pqdc::detail
