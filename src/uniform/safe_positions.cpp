#include "uniform/safe_positions.hpp"

#include "lattice/resources.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace pqdc::detail {

openvdb::Vec3d safe_patch_position(const openvdb::Coord& cell, std::uint8_t config, std::uint8_t joined, int group) {
    const openvdb::Vec3d center = cell.asVec3d() + openvdb::Vec3d(0.5);
    const EdgeGroups groups = edge_groups(config, joined);
    if (groups.count <= 1) return center;
    openvdb::Vec3d mean(0.0);
    int n = 0;
    for (int e = 0; e < 12; ++e) {
        if (groups.group[e] != group) continue;
        const int c = edge_start_corner(e);
        openvdb::Vec3d mid(double(c & 1), double((c >> 1) & 1), double((c >> 2) & 1));
        mid[e >> 2] = 0.5;
        mean += mid;
        ++n;
    }
    if (n == 0) return center;
    return center + (cell.asVec3d() + mean / double(n) - center) * kPatchPull;
}

namespace {

/// How many surface patches (vertices) a cell of this configuration and
/// these joined faces has.
int patch_count(std::uint8_t config, std::uint8_t joined) {
    return joined ? edge_groups(config, joined).count : plain_edge_groups()[config].count;
}

}  // namespace

VertexCells::VertexCells(const std::vector<CellLeaf*>& leaves, const std::vector<std::uint64_t>& leaf_first,
                         std::size_t count)
    : origin_(leaves.size()) {
    reserve_large(vertex_, count);
    vertex_.resize(count);
    tbb::parallel_for(std::size_t(0), leaves.size(), [&](std::size_t li) {
        if (!leaves[li]) return;
        origin_[li] = leaves[li]->origin();
        for (auto it = leaves[li]->cbeginValueOn(); it; ++it) {
            const CellValue value = *it;
            const auto config = std::uint32_t(value & 255), joined = std::uint32_t((value >> 8) & 63);
            const std::uint64_t first = leaf_first[leaves[li]->transientData()] + local_first_vertex(value);
            const int patches = patch_count(std::uint8_t(config), std::uint8_t(joined));
            const openvdb::Coord o = it.getCoord() - origin_[li];
            const std::uint32_t offset = std::uint32_t(o.x() << 6 | o.y() << 3 | o.z());
            for (int g = 0; g < patches; ++g)
                vertex_[first + std::uint64_t(g)] =
                    Packed{std::uint32_t(li), offset | config << 9 | joined << 17 | std::uint32_t(g) << 23};
        }
    });
}

std::vector<std::uint8_t> cell_patches(const VertexCells& cells) {
    std::vector<std::uint8_t> patch(cells.size(), 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, cells.size(), 1 << 14), [&](const auto& r) {
        for (std::size_t v = r.begin(); v != r.end(); ++v)
            patch[v] = std::uint8_t(cells.patch(v) | (patch_count(cells.config(v), cells.joined(v)) << 4));
    });
    return patch;
}

}  // namespace pqdc::detail
