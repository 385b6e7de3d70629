// Uniform stage "cells", region part: the classified cells of one leaf cut
// down to those whose centre lies in options.region, with the face and
// incidence counts the face stage preallocates from recounted to match.
#pragma once

#include "lattice/cube.hpp"
#include "lattice/region.hpp"
#include "lattice/value_block.hpp"
#include "uniform/classify.hpp"

#include <algorithm>

namespace pqdc::detail {

/// Keeps the cells of `leaf` (classified from `block`, points origin - 1 ..)
/// that `probe` accepts. A crossing edge keeps its face when its four cells
/// are all kept: they are crossed (they share the edge), in the domain (an
/// active corner, no NaN corner, as classify_leaf decides) and in the region.
inline void restrict_leaf_cells(const DenseBlock& block, const openvdb::Coord& origin, Region::Probe& probe,
                                LeafCells& leaf) {
    auto kept = [&](const openvdb::Coord& local) { return probe.contains(origin + local); };
    auto in_domain = [&](const openvdb::Coord& local) {
        bool on = false, nan = false;
        for (int c = 0; c < 8; ++c) {
            const int x = local.x() + 1 + (c & 1), y = local.y() + 1 + ((c >> 1) & 1), z = local.z() + 1 + ((c >> 2) & 1);
            on = on || block.on(x, y, z);
            nan = nan || ((block.nan_row[x][y] >> z) & 1);
        }
        return on && !nan;
    };
    const auto end = std::remove_if(leaf.cells.begin(), leaf.cells.end(),
                                    [&](const ClassifiedCell& c) { return !kept(c.local); });
    leaf.cells.erase(end, leaf.cells.end());
    leaf.faces = leaf.incidences = 0;
    for (const ClassifiedCell& c : leaf.cells) {
        leaf.incidences += std::uint32_t(__builtin_popcount(crossing_edges(c.config)));
        for (int axis = 0; axis < 3; ++axis) {
            if (!(((c.config >> (1 << axis)) ^ c.config) & 1)) continue;  // owned edge does not cross
            const int u = (axis + 1) % 3, v = (axis + 2) % 3;
            openvdb::Coord cu = c.local, cv = c.local, cuv = c.local;
            cu[u] -= 1;
            cv[v] -= 1;
            cuv[u] -= 1;
            cuv[v] -= 1;
            bool all = true;
            for (const openvdb::Coord& n : {cu, cv, cuv}) all = all && in_domain(n) && kept(n);
            leaf.faces += all;
        }
    }
}

}  // namespace pqdc::detail
