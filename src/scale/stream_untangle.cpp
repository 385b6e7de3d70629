#include "scale/stream_untangle.hpp"

#include "lattice/resources.hpp"
#include "uniform/safe_positions.hpp"

#include <algorithm>
#include <cmath>
#include <unordered_map>

namespace pqdc::detail {
namespace {

/// Memory per vertex of the part at the untangle stage's peak: points,
/// safe positions, cells, the copy before, two triangles, and the exact
/// finder's boxes and grid (about 300 bytes); rounded up.
constexpr double kPartVertexBytes = 400.0;


/// The seeds' cells, bucketed by blocks of `block` cells, for "is a seed
/// cell within r (max norm) of this cell" with r <= block.
class SeedCells {
public:
    SeedCells(const std::vector<openvdb::Coord>& cells, int block) : block_(block) {
        for (const openvdb::Coord& c : cells) buckets_[key(c)].push_back(c);
    }
    bool near(const openvdb::Coord& c, int r) const {
        const openvdb::Coord lo = key(c.offsetBy(-r)), hi = key(c.offsetBy(r));
        for (int x = lo.x(); x <= hi.x(); ++x)
            for (int y = lo.y(); y <= hi.y(); ++y)
                for (int z = lo.z(); z <= hi.z(); ++z) {
                    const auto it = buckets_.find(openvdb::Coord(x, y, z));
                    if (it == buckets_.end()) continue;
                    for (const openvdb::Coord& s : it->second)
                        if (std::abs(s.x() - c.x()) <= r && std::abs(s.y() - c.y()) <= r && std::abs(s.z() - c.z()) <= r)
                            return true;
                }
        return false;
    }

private:
    openvdb::Coord key(const openvdb::Coord& c) const {
        auto k = [&](int v) { return int(std::floor(double(v) / block_)); };
        return openvdb::Coord(k(c.x()), k(c.y()), k(c.z()));
    }
    int block_;
    std::unordered_map<openvdb::Coord, std::vector<openvdb::Coord>, CoordHash> buckets_;
};

std::vector<openvdb::Coord> seed_cells(StreamScratch& scratch, const std::vector<std::uint64_t>& seeds) {
    std::vector<openvdb::Coord> cells;
    std::vector<ScratchVertex> vs;
    std::size_t next = 0;
    for (std::size_t b = 0; b < scratch.bricks() && next < seeds.size(); ++b) {
        const std::uint64_t first = scratch.first_vertex(b), end = scratch.first_vertex(b + 1);
        if (seeds[next] >= end) continue;
        scratch.read_vertices(b, vs);
        for (; next < seeds.size() && seeds[next] < end; ++next) cells.push_back(vs[seeds[next] - first].cell);
    }
    return cells;
}

/// The part of the mesh around the seeds: faces with a corner within
/// `reach` of a seed cell, their corners (all within reach + 1).
struct Part {
    Mesh mesh;
    std::vector<openvdb::Vec3d> safe;
    std::vector<openvdb::Coord> cells;
    std::vector<std::uint64_t> global;  ///< sorted: part index -> global index
    bool whole = false;                 ///< every vertex is within reach: the part is the mesh
};

Part part_near(StreamScratch& scratch, const SeedCells& seeds, int reach, const LatticeTransform& xf) {
    Part part;
    std::vector<std::uint8_t> inner;
    std::vector<ScratchVertex> vs;
    std::uint64_t inner_count = 0;
    for (std::size_t b = 0; b < scratch.bricks(); ++b) {
        scratch.read_vertices(b, vs);
        for (std::size_t i = 0; i < vs.size(); ++i) {
            if (!seeds.near(vs[i].cell, reach + 1)) continue;
            part.global.push_back(scratch.first_vertex(b) + i);
            part.mesh.points.push_back(vs[i].position);
            part.safe.push_back(xf.to_world(safe_patch_position(vs[i].cell, vs[i].config, vs[i].joined, vs[i].patch)));
            part.cells.push_back(vs[i].cell);
            inner.push_back(seeds.near(vs[i].cell, reach));
            inner_count += inner.back();
        }
    }
    part.whole = inner_count == scratch.vertex_count();
    auto local = [&](std::uint32_t v) -> std::int64_t {
        const auto it = std::lower_bound(part.global.begin(), part.global.end(), std::uint64_t(v));
        return it != part.global.end() && *it == v ? it - part.global.begin() : -1;
    };
    const int n = scratch.arity();
    std::vector<std::uint32_t> faces;
    for (std::size_t b = 0; b < scratch.bricks(); ++b) {
        scratch.read_faces(b, faces);
        for (std::size_t f = 0; f < faces.size(); f += std::size_t(n)) {
            std::int64_t idx[4] = {-1, -1, -1, -1};
            bool any_inner = false;
            for (int k = 0; k < n; ++k) {
                idx[k] = local(faces[f + std::size_t(k)]);
                any_inner = any_inner || (idx[k] >= 0 && inner[std::size_t(idx[k])]);
            }
            if (!any_inner) continue;
            for (int k = 0; k < n; ++k)
                if (idx[k] < 0) throw std::logic_error("untangle_streamed: a face near a seed has a corner two cells away");
            if (n == 3) part.mesh.triangles.emplace_back(unsigned(idx[0]), unsigned(idx[1]), unsigned(idx[2]));
            else part.mesh.quads.emplace_back(unsigned(idx[0]), unsigned(idx[1]), unsigned(idx[2]), unsigned(idx[3]));
        }
    }
    return part;
}

}  // namespace

std::vector<MovedVertex> untangle_streamed(StreamScratch& scratch, const std::vector<std::uint64_t>& seeds,
                                           double max_offset, const LatticeTransform& xf,
                                           const UntangleSettings& settings,
                                           const ExtractOptions& limits, UntangleCounters& counters,
                                           int first_reach) {
    if (seeds.empty()) return {};
    // Corners of two triangles that meet lie within 2 + 2 max_offset cells;
    // one more for the corner that moved.
    const int margin = 3 + int(std::ceil(2.0 * max_offset));
    const std::vector<openvdb::Coord> cells = seed_cells(scratch, seeds);
    for (int reach = first_reach > 0 ? first_reach : 2 * margin;; reach *= 2) {
        const SeedCells near(cells, reach + 1);
        Part part = part_near(scratch, near, reach, xf);
        check_memory(double(part.global.size()) * kPartVertexBytes, limits, "part of the mesh the untangle stage repairs");
        const std::vector<openvdb::Vec3d> before = part.mesh.points;
        UntangleCounters c;
        untangle(part.mesh, part.safe, xf.transform->voxelSize()[0], settings, c);
        std::vector<MovedVertex> moved;
        bool contained = true;
        for (std::size_t i = 0; i < before.size(); ++i) {
            if (part.mesh.points[i] == before[i]) continue;
            contained = contained && near.near(part.cells[i], reach - margin);
            moved.emplace_back(part.global[i], part.mesh.points[i]);
        }
        if (!contained && !part.whole) continue;
        counters += c;
        return moved;
    }
}

}  // namespace pqdc::detail
