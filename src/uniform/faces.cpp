#include "uniform/faces.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>

namespace pqdc::detail {
namespace {

using CellAccessor = openvdb::tree::ValueAccessor<const CellTree, /*IsSafe=*/false>;

/// Calls emit(q, axis, plus) for each face owned by the leaf, in a fixed
/// order: q are the four vertex indices, counter-clockwise seen from outside
/// in world space; the outward direction is +axis when `plus`.
template <class Emit>
void visit_leaf_quads(const CellTree& cells, const CellLeaf& leaf, const std::vector<std::uint64_t>& leaf_first,
                      bool flip, Emit&& emit) {
    const EdgeGroups* plain = plain_edge_groups();
    CellAccessor acc(cells);
    // A neighbour cell's record and the first vertex of its leaf's list.
    struct Neighbour {
        CellValue value;
        std::uint64_t leaf_first;
    };
    const std::uint64_t own_first = leaf_first[leaf.transientData()];
    // Most neighbours live in the same leaf: skip the accessor for them.
    auto probe = [&](const openvdb::Coord& p, Neighbour& out) {
        if ((p & ~(kLeafDim - 1)) == leaf.origin()) {
            out.leaf_first = own_first;
            return leaf.probeValue(p, out.value);
        }
        const CellLeaf* other = acc.probeConstLeaf(p);
        if (!other || !other->probeValue(p, out.value)) return false;
        out.leaf_first = leaf_first[other->transientData()];
        return true;
    };
    auto vertex = [&](const Neighbour& cell, int edge) {
        return openvdb::Index32(cell.leaf_first + local_first_vertex(cell.value) +
                                std::uint64_t(group_of_edge(plain, cell.value, edge)));
    };
    for (auto it = leaf.cbeginValueOn(); it; ++it) {
        const Neighbour self{*it, own_first};
        const CellValue value = self.value;
        const std::uint8_t config = std::uint8_t(value & 255);
        const bool inside0 = config & 1;
        const openvdb::Coord c = it.getCoord();
        for (int axis = 0; axis < 3; ++axis) {
            if (inside0 == bool((config >> (1 << axis)) & 1)) continue;
            const int u = (axis + 1) % 3, v = (axis + 2) % 3;
            openvdb::Coord cu = c, cv = c, cuv = c;
            cu[u] -= 1;
            cv[v] -= 1;
            cuv[u] -= 1;
            cuv[v] -= 1;
            Neighbour vu, vv, vuv;
            if (!probe(cu, vu) || !probe(cv, vv) || !probe(cuv, vuv)) continue;
            // Edge ids of this lattice edge as seen from each of the four cells.
            const int e = 4 * axis;
            openvdb::Index32 q[4] = {vertex(vuv, e + 3), vertex(vv, e + 2), vertex(self, e), vertex(vu, e + 1)};
            // Counter-clockwise seen from +axis; reversed when inside lies at
            // the far end, and again when the map to world space is a mirror.
            if (!inside0 != flip) std::swap(q[1], q[3]);
            emit(q, axis, inside0);
        }
    }
}

}  // namespace

std::uint64_t count_open_crossings(const CellTree& cells, const CellLeaf& leaf) {
    CellAccessor acc(cells);
    std::uint64_t n = 0;
    for (auto it = leaf.cbeginValueOn(); it; ++it) {
        const std::uint8_t config = std::uint8_t(*it & 255);
        for (unsigned edges = crossing_edges(config); edges; edges &= edges - 1) {
            const int e = __builtin_ctz(edges);
            const int axis = e >> 2, u = (axis + 1) % 3, v = (axis + 2) % 3;
            openvdb::Coord owner = it.getCoord();
            owner[u] += e & 1;
            owner[v] += (e >> 1) & 1;
            bool present[4];
            int self = -1;
            for (int k = 0; k < 4; ++k) {
                openvdb::Coord cell = owner;
                cell[u] -= k & 1;
                cell[v] -= (k >> 1) & 1;
                if (cell == it.getCoord()) {
                    present[k] = true;
                    self = k;
                } else {
                    present[k] = acc.isValueOn(cell);
                }
            }
            const bool all = present[0] && present[1] && present[2] && present[3];
            int first_present = 0;
            while (!present[first_present]) ++first_present;
            if (!all && first_present == self) ++n;
        }
    }
    return n;
}

namespace {

/// The two triangles of a quad: the split whose triangles both face the way
/// the surface crosses the edge (no fold-over); among those, the better
/// shape, judged by 2 area / (longest side)^2 (a smooth stand-in for the
/// minimum angle: both vanish together, one sqrt instead of three).
void split_quad(const std::vector<openvdb::Vec3d>& P, const openvdb::Index32* q, const openvdb::Vec3d& out,
                double out_len, openvdb::Vec3I* tris) {
    struct Tri {
        double facing, quality;
    };
    // The four candidate triangles share their six sides: each difference
    // and squared length is computed once (a side and its reverse have the
    // same squared length, bit for bit).
    const openvdb::Vec3d d01 = P[q[1]] - P[q[0]], d02 = P[q[2]] - P[q[0]], d03 = P[q[3]] - P[q[0]];
    const openvdb::Vec3d d12 = P[q[2]] - P[q[1]], d13 = P[q[3]] - P[q[1]], d23 = P[q[3]] - P[q[2]];
    const double l01 = d01.lengthSqr(), l02 = d02.lengthSqr(), l03 = d03.lengthSqr(), l12 = d12.lengthSqr(),
                 l13 = d13.lengthSqr(), l23 = d23.lengthSqr();
    // Triangle (a, b, c) with sides ab, ac from a and squared side lengths.
    auto tri = [&](const openvdb::Vec3d& ab, const openvdb::Vec3d& ac, double s1, double s2, double s3) {
        const openvdb::Vec3d n = ab.cross(ac);
        const double len = n.length();
        const double longest = std::max({s1, s2, s3});
        if (!(len > 0.0)) return Tri{-1.0, 0.0};
        return Tri{n.dot(out) / (len * out_len), len / longest};
    };
    const Tri ac1 = tri(d01, d02, l01, l12, l02), ac2 = tri(d02, d03, l02, l23, l03);
    const Tri bd1 = tri(d01, d03, l01, l13, l03), bd2 = tri(d12, d13, l12, l23, l13);
    const double ac_facing = std::min(ac1.facing, ac2.facing), bd_facing = std::min(bd1.facing, bd2.facing);
    const bool use_bd = (ac_facing <= 0.0 || bd_facing <= 0.0)
                            ? bd_facing > ac_facing
                            : std::min(bd1.quality, bd2.quality) > std::min(ac1.quality, ac2.quality);
    if (use_bd) {
        tris[0] = openvdb::Vec3I(q[0], q[1], q[3]);
        tris[1] = openvdb::Vec3I(q[1], q[2], q[3]);
    } else {
        tris[0] = openvdb::Vec3I(q[0], q[1], q[2]);
        tris[1] = openvdb::Vec3I(q[0], q[2], q[3]);
    }
}

}  // namespace

void count_boundary_crossings(const CellTree& cells, const std::vector<CellLeaf*>& leaves,
                              const std::vector<std::uint32_t>& leaf_faces,
                              const std::vector<std::uint32_t>& leaf_incidences, const Progress& progress,
                              ExtractStats& stats) {
    // Exactly 4 incidences per face when every crossing has its four cells,
    // the common case that needs no counting of open crossings.
    std::uint64_t nquads = 0, total_incidences = 0;
    for (std::size_t i = 0; i < leaves.size(); ++i) {
        nquads += leaf_faces[i];
        total_incidences += leaf_incidences[i];
    }
    if (total_incidences != 4 * nquads) {
        std::vector<std::uint64_t> open(leaves.size(), 0);
        parallel_chunks(leaves.size(), progress, 0.46, 0.48, [&](std::size_t li) {
            if (leaves[li]) open[li] = count_open_crossings(cells, *leaves[li]);
        });
        for (auto b : open) stats.boundary_crossings += b;
    }
    stats.crossing_edges = nquads + stats.boundary_crossings;
    progress.report(0.48);
}

namespace {

/// The world-space direction of each index axis and its length.
struct AxisDirections {
    openvdb::Vec3d world[3];
    double length[3];
    explicit AxisDirections(const LatticeTransform& xf) {
        for (int a = 0; a < 3; ++a) {
            openvdb::Vec3d e(0.0);
            e[a] = 1.0;
            world[a] = xf.to_world(e) - xf.to_world(openvdb::Vec3d(0.0));
            length[a] = world[a].length();
        }
    }
};

}  // namespace

void build_quads(const CellTree& cells, const std::vector<CellLeaf*>& leaves,
                 const std::vector<std::uint64_t>& leaf_first, const std::vector<std::uint32_t>& leaf_faces,
                 const LatticeTransform& xf, const ExtractOptions& options, const Progress& progress, Mesh& mesh,
                 std::vector<std::uint8_t>& sides) {
    // Count (done by classification), prefix sum, fill.
    std::vector<std::uint64_t> first(leaves.size() + 1, 0);
    for (std::size_t i = 0; i < leaves.size(); ++i) first[i + 1] = first[i] + leaf_faces[i];
    const std::uint64_t nquads = first.back();
    check_memory(double(nquads) * double(sizeof(openvdb::Vec4I) + 1), options, "face list");
    reserve_large(mesh.quads, nquads);
    reserve_large(sides, nquads);
    mesh.quads.resize(nquads);
    sides.resize(nquads);
    parallel_chunks(leaves.size(), progress, 0.48, 0.5, [&](std::size_t li) {
        if (first[li + 1] == first[li]) return;
        std::uint64_t k = first[li];
        visit_leaf_quads(cells, *leaves[li], leaf_first, xf.mirrored, [&](const openvdb::Index32* q, int axis, bool plus) {
            mesh.quads[k] = openvdb::Vec4I(q[0], q[1], q[2], q[3]);
            sides[k] = std::uint8_t(2 * axis + plus);
            ++k;
        });
    });
}

void split_quads(const std::vector<std::uint8_t>& sides, const LatticeTransform& xf, const ExtractOptions& options,
                 Mesh& mesh) {
    const AxisDirections axes(xf);
    const std::size_t n = mesh.quads.size();
    check_memory(double(n) * double(2 * sizeof(openvdb::Vec3I)), options, "face list");
    reserve_large(mesh.triangles, 2 * n);
    mesh.triangles.resize(2 * n);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 1 << 14), [&](const auto& r) {
        for (std::size_t k = r.begin(); k != r.end(); ++k) {
            const int axis = sides[k] >> 1;
            const openvdb::Vec3d out = sides[k] & 1 ? axes.world[axis] : -axes.world[axis];
            split_quad(mesh.points, mesh.quads[k].asPointer(), out, axes.length[axis], &mesh.triangles[2 * k]);
        }
    });
    std::vector<openvdb::Vec4I>().swap(mesh.quads);
}

void build_faces(const CellTree& cells, const std::vector<CellLeaf*>& leaves,
                 const std::vector<std::uint64_t>& leaf_first, const std::vector<std::uint32_t>& leaf_faces,
                 const LatticeTransform& xf, const ExtractOptions& options, const Progress& progress, Mesh& mesh,
                 ExtractStats& stats) {
    std::vector<std::uint8_t> sides;
    build_quads(cells, leaves, leaf_first, leaf_faces, xf, options, progress, mesh, sides);
    count_faces(options, mesh.quads.size(), stats);
    if (options.faces == FaceType::triangles) split_quads(sides, xf, options, mesh);
}

void count_faces(const ExtractOptions& options, std::uint64_t quads, ExtractStats& stats) {
    const bool tris = options.faces == FaceType::triangles;
    stats.quads = tris ? 0 : quads;
    stats.triangles = tris ? 2 * quads : 0;
}

void drop_unused_vertices(Mesh& mesh) {
    std::vector<std::uint8_t> used;
    reserve_large(used, mesh.points.size());
    used.assign(mesh.points.size(), 0);
    for (const auto& t : mesh.triangles) used[t[0]] = used[t[1]] = used[t[2]] = 1;
    for (const auto& q : mesh.quads) used[q[0]] = used[q[1]] = used[q[2]] = used[q[3]] = 1;
    std::vector<openvdb::Index32> remap;
    reserve_large(remap, mesh.points.size());
    remap.resize(mesh.points.size());
    openvdb::Index32 kept = 0;
    for (std::size_t i = 0; i < mesh.points.size(); ++i) {
        remap[i] = kept;
        if (used[i]) mesh.points[kept++] = mesh.points[i];
    }
    if (kept == mesh.points.size()) return;
    mesh.points.resize(kept);
    mesh.points.shrink_to_fit();
    tbb::parallel_for(std::size_t(0), mesh.triangles.size(), [&](std::size_t i) {
        for (int j = 0; j < 3; ++j) mesh.triangles[i][j] = remap[mesh.triangles[i][j]];
    });
    tbb::parallel_for(std::size_t(0), mesh.quads.size(), [&](std::size_t i) {
        for (int j = 0; j < 4; ++j) mesh.quads[i][j] = remap[mesh.quads[i][j]];
    });
}

}  // namespace pqdc::detail
