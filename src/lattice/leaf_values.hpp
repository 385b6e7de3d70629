// Reading a tree's voxel values without loading a delay-loaded tree into
// memory (issue 14): pqdc::extract_bricks meshes grids whose leaf buffers
// stay in the file, and the diagnostics around it must not load them all.
#pragma once

#include <openvdb/openvdb.h>

namespace pqdc::detail {

/// Calls f(leaf) with the leaf's values readable. A leaf whose buffer is
/// still in the file is read through a copy, which loads only the copy
/// (freed on return): the tree stays unloaded.
template <class LeafT, class F>
void with_leaf_values(const LeafT& leaf, const F& f) {
    if (leaf.buffer().isOutOfCore()) {
        const LeafT copy(leaf);
        f(copy);
    } else {
        f(leaf);
    }
}

/// True when the tree's first leaf is still in the file: the tree was read
/// with delayed loading and not loaded since (extract_bricks never does).
template <class TreeT>
bool delay_loaded(const TreeT& tree) {
    const auto it = tree.cbeginLeaf();
    return it && it->buffer().isOutOfCore();
}

}  // namespace pqdc::detail
