// The alive triangles around each vertex (a CSR, triangles in index order),
// shared by the relaxation and the crease splits.
#pragma once

#include <openvdb/openvdb.h>

#include <cstdint>
#include <vector>

namespace pqdc::adaptive_detail {

/// Vertex v's alive triangles are triangle[begin[v], begin[v + 1]).
struct Fans {
    std::vector<std::uint32_t> begin, triangle;
};

inline Fans build_fans(std::size_t vertex_count, const std::vector<openvdb::Vec3I>& tris,
                       const std::vector<std::uint8_t>& alive) {
    Fans f;
    f.begin.assign(vertex_count + 1, 0);
    for (std::size_t t = 0; t < tris.size(); ++t)
        if (alive[t])
            for (int k = 0; k < 3; ++k) ++f.begin[tris[t][k] + 1];
    for (std::size_t v = 0; v < vertex_count; ++v) f.begin[v + 1] += f.begin[v];
    f.triangle.resize(f.begin.back());
    std::vector<std::uint32_t> next(f.begin.begin(), f.begin.end() - 1);
    for (std::size_t t = 0; t < tris.size(); ++t)
        if (alive[t])
            for (int k = 0; k < 3; ++k) f.triangle[next[tris[t][k]]++] = std::uint32_t(t);
    return f;
}

}  // namespace pqdc::adaptive_detail
