// Flat stars: vertices around which no two triangles can intersect, proven
// once per vertex instead of once per pair (internal to the
// self-intersection finder).
//
// On a meshed surface almost every candidate pair of the broad phase shares
// a vertex (a 2.4 M-triangle sphere: 10.8 M pairs share one, 3.5 M an edge,
// 0.4 M none), and settling them pair by pair was most of the exact test's
// time. A vertex v is *flat* when, in one coordinate projection P:
//  - its triangles form one closed, consistently oriented fan (v, a_i, a_i+1),
//  - each projects with the same non-zero orientation (P is then injective
//    on each), and
//  - their angular sectors at P(v) wind around it exactly once.
// The sectors, each narrower than a half turn, then tile the directions
// around P(v) once in cyclic order, so two of them share nothing but P(v),
// or the ray of their common edge when adjacent. Two triangles of the star
// therefore meet only at v or along their shared edge: no pair sharing a
// flat vertex intersects. Every sign is exact (geometry/exact_predicates.hpp).
#pragma once

#include "pqdc/mesh.hpp"

#include <openvdb/openvdb.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace pqdc::detail {

/// Per vertex (points.size() entries, the positions of the mesh's points):
/// 1 when the vertex is flat. The mesh's triangles are numbered as
/// find_self_intersections numbers them (quads split); triangles with
/// skip[t] != 0 (degenerate or non-finite) make their corners not flat.
std::vector<std::uint8_t> find_flat_vertices(const Mesh& mesh, const std::vector<openvdb::Vec3d>& points,
                                             const std::vector<char>& skip);

}  // namespace pqdc::detail
