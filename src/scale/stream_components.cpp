#include "scale/stream_components.hpp"

#include "measure/mesh_internal.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace pqdc::detail {
namespace {

constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();

/// What remove_small_components() decides from: a component's box and
/// whether a corner was not finite.
struct ComponentBox {
    openvdb::Vec3d lo{std::numeric_limits<double>::infinity()}, hi{-std::numeric_limits<double>::infinity()};
    bool non_finite = false;
};

/// Every face's corners joined, brick by brick.
UnionFind join_face_corners(StreamScratch& scratch) {
    UnionFind sets(std::size_t(scratch.vertex_count()));
    const std::size_t n = std::size_t(scratch.arity());
    std::vector<std::uint32_t> faces;
    for (std::size_t b = 0; b < scratch.bricks(); ++b) {
        scratch.read_faces(b, faces);
        for (std::size_t f = 0; f < faces.size(); f += n)
            for (std::size_t k = 1; k < n; ++k) sets.unite(faces[f], faces[f + k]);
    }
    return sets;
}

/// Numbers the components (roots in vertex order) and turns the
/// union-find's array into each used vertex's component number (kNone for
/// unused vertices). Returns a box per component.
std::vector<ComponentBox> number_components(const StreamScratch& scratch, UnionFind& sets) {
    const std::uint64_t n = scratch.vertex_count();
    std::vector<std::uint32_t>& label = sets.parent;
    // Every parent points to a smaller vertex or itself, so in vertex order
    // each find() meets only flattened vertices: afterwards each vertex's
    // entry is its root, the smallest vertex of its component.
    for (std::uint64_t v = 0; v < n; ++v) label[v] = sets.find(std::uint32_t(v));
    const auto used = [&](std::uint64_t v) { return (scratch.used()[v >> 6] >> (v & 63)) & 1; };
    std::uint32_t count = 0;
    for (std::uint64_t v = 0; v < n; ++v) {
        if (!used(v)) {  // in no face: alone in its set
            label[v] = kNone;
            continue;
        }
        // The root came earlier and already holds its component's number.
        const std::uint32_t root = label[v];
        label[v] = root == v ? count++ : label[root];
    }
    return std::vector<ComponentBox>(count);
}

}  // namespace

void remove_streamed_islands(StreamScratch& scratch, const std::vector<MovedVertex>& moved, double voxel_size,
                             double min_diagonal_voxels, ComponentFilterStats& stats) {
    if (!scratch.foreign().empty() || scratch.first_global() != 0)
        throw std::logic_error("internal error: the streamed component filter got one rank of several");
    if (scratch.vertex_count() >= kNone)
        throw std::logic_error("internal error: the streamed component filter got more than 2^32 - 2 vertices");
    UnionFind sets = join_face_corners(scratch);
    std::vector<ComponentBox> boxes = number_components(scratch, sets);
    // The union-find's array now holds the labels: 4 bytes per vertex in all.
    const std::vector<std::uint32_t>& label = sets.parent;

    std::vector<ScratchVertex> vs;
    auto next_move = moved.begin();
    for (std::size_t b = 0; b < scratch.bricks(); ++b) {
        scratch.read_vertices(b, vs);
        const std::uint64_t first = scratch.first_vertex(b);
        for (std::size_t i = 0; i < vs.size(); ++i) {
            const std::uint64_t v = first + i;
            openvdb::Vec3d p = vs[i].position;
            while (next_move != moved.end() && next_move->first < v) ++next_move;
            if (next_move != moved.end() && next_move->first == v) p = next_move->second;
            if (label[v] == kNone) continue;
            ComponentBox& box = boxes[label[v]];
            if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) box.non_finite = true;
            box.lo = openvdb::math::minComponent(box.lo, p);
            box.hi = openvdb::math::maxComponent(box.hi, p);
        }
    }

    // The decisions, in remove_small_components()'s words.
    ComponentFilterStats s;
    std::vector<char> remove(boxes.size(), 0);
    bool kept_any = false;
    for (std::size_t c = 0; c < boxes.size(); ++c) {
        ++s.components;
        if (boxes[c].non_finite) continue;
        const double diagonal = (boxes[c].hi - boxes[c].lo).length() / voxel_size;
        if (diagonal < min_diagonal_voxels) {
            remove[c] = 1;
            ++s.removed_components;
            s.largest_removed_diagonal_voxels = std::max(s.largest_removed_diagonal_voxels, diagonal);
        } else if (!kept_any || diagonal < s.smallest_kept_diagonal_voxels) {
            s.smallest_kept_diagonal_voxels = diagonal;
            kept_any = true;
        }
    }
    std::vector<std::uint32_t> faces;
    const std::size_t n = std::size_t(scratch.arity());
    for (std::size_t b = 0; b < scratch.bricks(); ++b) {
        scratch.read_faces(b, faces);
        for (std::size_t f = 0; f < faces.size(); f += n) s.removed_faces += remove[label[faces[f]]];
    }
    for (std::uint64_t v = 0; v < scratch.vertex_count(); ++v) {
        if (label[v] == kNone || !remove[label[v]]) continue;
        scratch.mark_unused(v);
        ++s.removed_points;
    }
    stats = s;
}

}  // namespace pqdc::detail
