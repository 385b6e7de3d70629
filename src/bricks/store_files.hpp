// A brick store's files opened on demand and held compactly (issue 14).
//
// Each brick file is its own OpenVDB grid, so its tree carries a whole
// level-2 node (a 32^3 table: 268 KB) for the few level-1 nodes of its
// brick. Held as opened, the 462 files of a 2048^3 sphere store took 2.3x
// the memory of the same topology assembled into one tree. A CompactBrick
// keeps only the brick's part of that table (its level-1 nodes and tiles)
// and the emptied file grid: leaf copies not yet read refer to that grid's
// background through their stream metadata, so it must outlive them.
#pragma once

#include "bricks/brick_source.hpp"
#include "bricks/store_index.hpp"

#include <openvdb/openvdb.h>

#include <cstdint>
#include <filesystem>
#include <functional>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <vector>

namespace pqdc::detail {

/// One brick file's nodes inside its box, taken out of the file's tree.
template <class TreeT>
class CompactBrick {
public:
    using ValueT = typename TreeT::ValueType;
    using RootT = typename TreeT::RootNodeType;
    using Node2 = typename RootT::ChildNodeType;
    using Node1 = typename Node2::ChildNodeType;

    /// Takes the level-1 nodes and tiles of `tree` (the tree of `grid`) in
    /// `box`, a box of whole level-1 nodes inside one root child, leaving
    /// `tree` empty.
    CompactBrick(openvdb::GridBase::Ptr grid, TreeT& tree, const openvdb::CoordBBox& box)
        : grid_(std::move(grid)), box_(box), nodes_(box.dim() >> kNode1Log2) {
        for (auto it = tree.root().cbeginValueAll(); it; ++it) {
            const auto tile = openvdb::CoordBBox::createCube(it.getCoord(), int(Node2::DIM));
            if (tile.hasOverlap(box)) root_tiles_.push_back({tile.min(), *it, it.isValueOn()});
        }
        slots_.resize(std::size_t(nodes_.x()) * std::size_t(nodes_.y()) * std::size_t(nodes_.z()));
        for_each_node_overlap(box, box, kNode1, [&](const openvdb::Coord& p) {
            Node2* n2 = tree.root().template probeNode<Node2>(p);
            if (!n2) return;  // no root child here: nothing to copy
            Slot& s = slots_[slot_of(p)];
            const openvdb::Index n = Node2::coordToOffset(p);
            s.present = true;
            if (n2->isChildMaskOn(n)) {
                s.child.reset(n2->template stealNode<Node1>(p, tree.background(), false));
                bytes_ += s.child->memUsage();
            } else {
                s.value = n2->getTable()[n].getValue();
                s.active = n2->isValueMaskOn(n);
            }
        });
        tree.clear();
        bytes_ += sizeof(*this) + slots_.size() * sizeof(Slot) + root_tiles_.size() * sizeof(RootTile);
    }

    /// copy_tree_box(the file's tree, part, into) for `part` inside the brick's box.
    void copy(const openvdb::CoordBBox& part, TreeT& into) const {
        for (const RootTile& t : root_tiles_)
            if (openvdb::CoordBBox::createCube(t.origin, int(Node2::DIM)).hasOverlap(part))
                into.addTile(RootT::LEVEL, t.origin, t.value, t.active);
        for_each_node_overlap(box_, part, kNode1, [&](const openvdb::Coord& p) {
            const Slot& s = slots_[slot_of(p)];
            if (!s.present) return;
            if (s.child) copy_node1_box(*s.child, part, into);
            else into.addTile(Node2::LEVEL, p, s.value, s.active);
        });
    }

    /// Whether voxel `p` (inside the brick's box) is active; masks only.
    bool is_value_on(const openvdb::Coord& p) const {
        for (const RootTile& t : root_tiles_)
            if (openvdb::CoordBBox::createCube(t.origin, int(Node2::DIM)).isInside(p)) return t.active;
        const Slot& s = slots_[slot_of(p)];
        return s.child ? s.child->isValueOn(p) : s.present && s.active;
    }

    /// Memory held (the level-1 nodes with their leaves, unloaded).
    std::uint64_t bytes() const { return bytes_; }
    /// The emptied file grid (see the file comment).
    const openvdb::GridBase::Ptr& grid() const { return grid_; }

private:
    static constexpr int kNode1 = int(Node1::DIM);
    static constexpr int kNode1Log2 = int(Node1::TOTAL);
    struct Slot {
        std::unique_ptr<Node1> child;
        ValueT value{};
        bool present = false, active = false;
    };
    struct RootTile {
        openvdb::Coord origin;
        ValueT value;
        bool active;
    };
    std::size_t slot_of(const openvdb::Coord& p) const {
        const openvdb::Coord q = (p - box_.min()) >> kNode1Log2;  // p is inside the box
        return (std::size_t(q.x()) * std::size_t(nodes_.y()) + std::size_t(q.y())) * std::size_t(nodes_.z()) +
               std::size_t(q.z());
    }

    openvdb::GridBase::Ptr grid_;
    openvdb::CoordBBox box_;
    openvdb::Coord nodes_;  // level-1 nodes along each axis
    std::vector<Slot> slots_;
    std::vector<RootTile> root_tiles_;
    std::uint64_t bytes_ = 0;
};

/// The brick files of a store opened on demand, made compact, and kept while
/// they fit in `budget_bytes`, least recently used dropped first once no
/// caller holds them. Thread-safe: a file asked for by two threads at once
/// is opened once. Every file grid opened stays (emptied, a few hundred
/// bytes) until the cache goes, for the leaf copies made from it.
template <class TreeT>
class BrickFiles {
public:
    using Brick = CompactBrick<TreeT>;
    using GridT = openvdb::Grid<TreeT>;

    /// `shell`: the store's grid.vdb, which every brick file must match.
    BrickFiles(const StoreIndex& index, const GridT& shell, std::uint64_t budget_bytes)
        : index_(index), shell_(shell), budget_(budget_bytes), checked_(index.bricks().size(), 0) {}

    /// Brick file `k`. `fresh` (may be empty) sees the file's tree before it
    /// is made compact, when this call opened the file.
    std::shared_ptr<const Brick> open(std::size_t k, const std::function<void(const TreeT&)>& fresh = {}) const {
        std::shared_ptr<Entry> e;
        {
            const std::lock_guard<std::mutex> lock(mutex_);
            auto& slot = entries_[k];
            if (!slot) {
                slot = std::make_shared<Entry>();
                recent_.push_front(k);
            } else {
                recent_.splice(recent_.begin(), recent_, slot->recent);
            }
            slot->recent = recent_.begin();
            if (slot->brick) return slot->brick;
            e = slot;
        }
        const std::lock_guard<std::mutex> opening(e->opening);
        {
            const std::lock_guard<std::mutex> lock(mutex_);
            if (e->brick) return e->brick;  // opened by another thread while this one waited
        }
        std::shared_ptr<const Brick> brick;
        try {
            brick = read(k, fresh);
        } catch (...) {
            const std::lock_guard<std::mutex> lock(mutex_);
            const auto it = entries_.find(k);
            if (it != entries_.end() && it->second == e) {
                recent_.erase(e->recent);
                entries_.erase(it);
            }
            throw;
        }
        const std::lock_guard<std::mutex> lock(mutex_);
        e->brick = brick;
        held_ += brick->bytes();
        ++opened_;
        grids_.push_back(brick->grid());
        drop_least_recent(k);
        return brick;
    }

    /// Files opened so far (a file opened again after it was dropped counts again).
    std::uint64_t opened() const {
        const std::lock_guard<std::mutex> lock(mutex_);
        return opened_;
    }

private:
    struct Entry {
        std::mutex opening;                   // held while the file is opened
        std::shared_ptr<const Brick> brick;   // null until opened; under the cache's mutex
        std::list<std::size_t>::iterator recent;  // its place in recent_
    };

    std::shared_ptr<const Brick> read(std::size_t k, const std::function<void(const TreeT&)>& fresh) const {
        const StoreBrickFile& f = index_.bricks()[k];
        // The checksum once per file and run: a file dropped from the cache
        // and opened again is the same file.
        if (!checked(k)) {
            check_file_digest(index_.dir(), (std::filesystem::path(index_.dir()) / f.file).string(), f.digest);
            const std::lock_guard<std::mutex> lock(mutex_);
            checked_[k] = 1;
        }
        const typename GridT::Ptr grid = open_typed_brick_file<GridT>(index_.dir(), f, shell_);
        if (fresh) fresh(grid->tree());
        return std::make_shared<const Brick>(grid, grid->tree(), f.box);
    }

    bool checked(std::size_t k) const {
        const std::lock_guard<std::mutex> lock(mutex_);
        return checked_[k] != 0;
    }

    void drop_least_recent(std::size_t keep) const {  // under mutex_
        for (auto k = recent_.end(); held_ > budget_ && k != recent_.begin();) {
            --k;
            const auto victim = entries_.find(*k);
            const std::shared_ptr<const Brick>& brick = victim->second->brick;
            // Never the file just asked for, one still opening, or one a caller holds.
            if (*k == keep || !brick || brick.use_count() > 1) continue;
            held_ -= brick->bytes();
            entries_.erase(victim);
            k = recent_.erase(k);
        }
    }

    const StoreIndex& index_;
    const GridT& shell_;
    const std::uint64_t budget_;
    mutable std::mutex mutex_;
    mutable std::map<std::size_t, std::shared_ptr<Entry>> entries_;
    mutable std::list<std::size_t> recent_;  // most recent first
    mutable std::vector<openvdb::GridBase::Ptr> grids_;
    mutable std::uint64_t held_ = 0, opened_ = 0;
    mutable std::vector<char> checked_;  // per file: its checksum matched; under mutex_
};

}  // namespace pqdc::detail
