#include "scale/stream_components.hpp"

#include "measure/mesh_internal.hpp"
#include "postprocess/component_rule.hpp"
#include "ranks/rank_exchange.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>

namespace pqdc::detail {
namespace {

constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();
constexpr const char* kWhat = "the streamed component filter's exchange";

/// A rank's slots in the union-find: its own vertices first, then the
/// entries of the group's list of vertices used across rank boundaries
/// (StreamNumbering::foreign: the same list on every rank).
class Slots {
public:
    Slots(const StreamScratch& scratch, const std::vector<std::uint64_t>& foreign)
        : lo_(scratch.first_global()), own_(scratch.vertex_count()), foreign_(foreign) {
        if (own_ + foreign.size() >= kNone)
            throw std::logic_error("internal error: the streamed component filter got more than 2^32 - 2 vertices");
    }
    std::size_t count() const { return std::size_t(own_ + foreign_.size()); }
    std::uint64_t own() const { return own_; }
    bool is_own(std::uint64_t v) const { return v >= lo_ && v - lo_ < own_; }
    std::uint32_t of(std::uint64_t v) const {
        if (is_own(v)) return std::uint32_t(v - lo_);
        const auto it = std::lower_bound(foreign_.begin(), foreign_.end(), v);
        if (it == foreign_.end() || *it != v)
            throw std::logic_error("internal error: a face uses another rank's vertex the exchange missed");
        return std::uint32_t(own_ + std::uint64_t(it - foreign_.begin()));
    }

private:
    std::uint64_t lo_, own_;
    const std::vector<std::uint64_t>& foreign_;
};

/// Every face's corners joined, brick by brick; `in_play`: the slots a face
/// uses (own vertices used only by other ranks' faces are added later).
UnionFind join_face_corners(StreamScratch& scratch, const Slots& slots, std::vector<char>& in_play) {
    UnionFind sets(slots.count());
    in_play.assign(slots.count(), 0);
    const std::size_t n = std::size_t(scratch.arity());
    std::vector<std::uint32_t> faces;
    for (std::size_t b = 0; b < scratch.bricks(); ++b) {
        scratch.read_faces(b, faces);
        for (std::size_t f = 0; f < faces.size(); f += n) {
            const std::uint32_t first = slots.of(faces[f]);
            in_play[first] = 1;
            for (std::size_t k = 1; k < n; ++k) {
                const std::uint32_t s = slots.of(faces[f + k]);
                in_play[s] = 1;
                sets.unite(first, s);
            }
        }
    }
    return sets;
}

/// Numbers the local components (roots in slot order) and turns the
/// union-find's array into each slot's component number (kNone for slots
/// no face of this rank and no other rank uses). Returns the count.
std::uint32_t number_components(const StreamScratch& scratch, const std::vector<char>& in_play, UnionFind& sets) {
    std::vector<std::uint32_t>& label = sets.parent;
    // Every parent points to a smaller slot or itself, so in slot order each
    // find() meets only flattened slots: afterwards each entry is its root,
    // the smallest slot of its set.
    for (std::size_t s = 0; s < label.size(); ++s) label[s] = sets.find(std::uint32_t(s));
    const auto used = [&](std::size_t v) { return (scratch.used()[v >> 6] >> (v & 63)) & 1; };
    std::uint32_t count = 0;
    for (std::size_t s = 0; s < label.size(); ++s) {
        // Own vertices used by other ranks' faces only are components of their own here.
        const bool plays = in_play[s] || (s < scratch.vertex_count() && used(s));
        if (!plays) {
            label[s] = kNone;
            continue;
        }
        // The root came earlier and already holds its component's number.
        const std::uint32_t root = label[s];
        label[s] = root == s ? count++ : label[root];
    }
    return count;
}

/// Each local component's box over this rank's vertices, the untangle
/// stage's moves applied.
std::vector<ComponentBox> own_boxes(StreamScratch& scratch, const std::vector<MovedVertex>& moved,
                                    const std::vector<std::uint32_t>& label, std::uint32_t count) {
    std::vector<ComponentBox> boxes(count);
    std::vector<ScratchVertex> vs;
    const std::uint64_t lo = scratch.first_global();
    auto next_move = std::lower_bound(moved.begin(), moved.end(), lo,
                                      [](const MovedVertex& m, std::uint64_t v) { return m.first < v; });
    for (std::size_t b = 0; b < scratch.bricks(); ++b) {
        scratch.read_vertices(b, vs);
        const std::uint64_t first = scratch.first_vertex(b);
        for (std::size_t i = 0; i < vs.size(); ++i) {
            const std::uint64_t v = first + i;
            openvdb::Vec3d p = vs[i].position;
            while (next_move != moved.end() && next_move->first < v) ++next_move;
            if (next_move != moved.end() && next_move->first == v) p = next_move->second;
            if (label[v - lo] != kNone) boxes[label[v - lo]].add(p);
        }
    }
    return boxes;
}

/// The group-wide numbers of the components that cross rank boundaries
/// (sorted), and for each the smallest number it is joined with: every
/// rank's local components (this rank's numbered from `first` on) joined
/// where they hold the same entry of the group's boundary list.
struct JoinedComponents {
    std::vector<std::uint64_t> shared;
    std::vector<std::uint64_t> representative;  ///< of shared[k]

    /// The index of component `id` in `shared`, or none.
    std::optional<std::size_t> find(std::uint64_t id) const {
        const auto it = std::lower_bound(shared.begin(), shared.end(), id);
        if (it == shared.end() || *it != id) return std::nullopt;
        return std::size_t(it - shared.begin());
    }
};

JoinedComponents join_across_ranks(const StreamScratch& scratch, const Slots& slots,
                                   const std::vector<std::uint64_t>& foreign, const std::vector<std::uint32_t>& label,
                                   std::uint64_t first, RankGroup& group) {
    // (boundary entry, component) for each entry one of this rank's components holds:
    // an own vertex (at its own slot) or another rank's (at its list slot).
    struct Hold {
        std::uint64_t first, second;  // entry, component
        bool operator<(const Hold& o) const { return first < o.first || (first == o.first && second < o.second); }
    };
    std::vector<Hold> mine;
    for (std::size_t k = 0; k < foreign.size(); ++k) {
        const std::uint64_t slot = slots.is_own(foreign[k]) ? foreign[k] - scratch.first_global() : slots.own() + k;
        if (label[std::size_t(slot)] != kNone) mine.push_back({k, first + label[std::size_t(slot)]});
    }
    std::vector<Hold> all = all_gather_values(group, mine, kWhat);
    std::sort(all.begin(), all.end());
    JoinedComponents j;
    for (const auto& entry : all) j.shared.push_back(entry.second);
    std::sort(j.shared.begin(), j.shared.end());
    j.shared.erase(std::unique(j.shared.begin(), j.shared.end()), j.shared.end());
    UnionFind sets(j.shared.size());  // the smaller root wins: the smallest number represents
    for (std::size_t k = 1; k < all.size(); ++k)
        if (all[k].first == all[k - 1].first) sets.unite(std::uint32_t(*j.find(all[k - 1].second)), std::uint32_t(*j.find(all[k].second)));
    j.representative.resize(j.shared.size());
    for (std::size_t k = 0; k < j.shared.size(); ++k) j.representative[k] = j.shared[sets.find(std::uint32_t(k))];
    return j;
}

/// A joined component's part of a box, tagged with its representative.
struct SharedBox {
    std::uint64_t representative;
    ComponentBox box;
};

/// The boxes of the joined components, whole: every rank's parts merged,
/// sorted by representative.
std::vector<SharedBox> whole_shared_boxes(const std::vector<ComponentBox>& boxes, const JoinedComponents& joined,
                                          std::uint64_t first, RankGroup& group) {
    std::vector<SharedBox> mine;
    for (std::size_t c = 0; c < boxes.size(); ++c)
        if (const auto k = joined.find(first + c)) mine.push_back({joined.representative[*k], boxes[c]});
    std::vector<SharedBox> all = all_gather_values(group, mine, kWhat);
    std::stable_sort(all.begin(), all.end(),
                     [](const SharedBox& a, const SharedBox& b) { return a.representative < b.representative; });
    std::vector<SharedBox> whole;
    for (const SharedBox& part : all) {
        if (whole.empty() || whole.back().representative != part.representative) whole.push_back({part.representative, {}});
        whole.back().box.add(part.box);
    }
    return whole;
}

/// The counts of every rank's part, added up (the same on every rank).
ComponentFilterStats add_up(const ComponentRule& part, RankGroup& group) {
    struct Counts {
        std::uint64_t components, removed_components, removed_faces, removed_points, kept_any;
        double largest_removed, smallest_kept;
    };
    const ComponentFilterStats& s = part.stats;
    const std::vector<Counts> all = all_gather_values(
        group,
        std::vector<Counts>{{s.components, s.removed_components, s.removed_faces, s.removed_points,
                             std::uint64_t(part.kept_any), s.largest_removed_diagonal_voxels,
                             s.smallest_kept_diagonal_voxels}},
        kWhat);
    ComponentFilterStats sum;
    bool kept_any = false;
    for (const Counts& c : all) {
        sum.components += c.components;
        sum.removed_components += c.removed_components;
        sum.removed_faces += c.removed_faces;
        sum.removed_points += c.removed_points;
        sum.largest_removed_diagonal_voxels = std::max(sum.largest_removed_diagonal_voxels, c.largest_removed);
        if (c.kept_any && (!kept_any || c.smallest_kept < sum.smallest_kept_diagonal_voxels))
            sum.smallest_kept_diagonal_voxels = c.smallest_kept;
        kept_any = kept_any || c.kept_any;
    }
    return sum;
}

}  // namespace

void remove_streamed_islands(StreamScratch& scratch, const std::vector<MovedVertex>& moved,
                             const std::vector<std::uint64_t>& foreign, double voxel_size,
                             double min_diagonal_voxels, RankGroup& group, ComponentFilterStats& stats) {
    const Slots slots(scratch, foreign);
    std::vector<char> in_play;
    UnionFind sets = join_face_corners(scratch, slots, in_play);
    const std::uint32_t count = number_components(scratch, in_play, sets);
    std::vector<char>().swap(in_play);
    // The union-find's array now holds the labels: 4 bytes per vertex (and boundary entry) in all.
    const std::vector<std::uint32_t>& label = sets.parent;
    const std::vector<ComponentBox> boxes = own_boxes(scratch, moved, label, count);

    // Group-wide component numbers: this rank's from `first` on.
    const std::vector<std::uint64_t> counts = all_gather_values(group, std::vector<std::uint64_t>{count}, kWhat);
    std::uint64_t first = 0;
    for (int r = 0; r < group.rank(); ++r) first += counts[std::size_t(r)];
    const JoinedComponents joined = join_across_ranks(scratch, slots, foreign, label, first, group);
    const std::vector<SharedBox> whole = whole_shared_boxes(boxes, joined, first, group);

    // Each component decided once: a local one here, a joined one (the
    // same decision on every rank) counted on rank 0.
    ComponentRule decide{voxel_size, min_diagonal_voxels, {}, false};
    std::vector<char> shared_goes(whole.size());
    for (std::size_t k = 0; k < whole.size(); ++k) {
        ComponentRule uncounted{voxel_size, min_diagonal_voxels, {}, false};
        shared_goes[k] = (group.rank() == 0 ? decide : uncounted).remove(whole[k].box);
    }
    std::vector<char> goes(count, 0);
    for (std::uint32_t c = 0; c < count; ++c) {
        const auto k = joined.find(first + c);
        if (!k) {
            goes[c] = decide.remove(boxes[c]);
            continue;
        }
        const std::uint64_t rep = joined.representative[*k];
        const auto w = std::lower_bound(whole.begin(), whole.end(), rep,
                                        [](const SharedBox& b, std::uint64_t r) { return b.representative < r; });
        goes[c] = shared_goes[std::size_t(w - whole.begin())];
    }

    std::vector<std::uint32_t> faces;
    const std::size_t n = std::size_t(scratch.arity());
    for (std::size_t b = 0; b < scratch.bricks(); ++b) {
        scratch.read_faces(b, faces);
        for (std::size_t f = 0; f < faces.size(); f += n) decide.stats.removed_faces += goes[label[slots.of(faces[f])]];
    }
    for (std::uint64_t v = 0; v < slots.own(); ++v) {
        if (label[v] == kNone || !goes[label[v]]) continue;
        scratch.mark_unused(scratch.first_global() + v);
        ++decide.stats.removed_points;
    }
    stats = add_up(decide, group);
}

}  // namespace pqdc::detail
