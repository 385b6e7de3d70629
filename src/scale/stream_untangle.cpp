#include "scale/stream_untangle.hpp"

#include "lattice/resources.hpp"
#include "ranks/part_bytes.hpp"
#include "ranks/rank_exchange.hpp"
#include "uniform/safe_positions.hpp"

#include <algorithm>
#include <cmath>
#include <string>
#include <unordered_map>
#include <unordered_set>

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
        for (const auto& bucket : buckets_)
            for (int x = -1; x <= 1; ++x)
                for (int y = -1; y <= 1; ++y)
                    for (int z = -1; z <= 1; ++z) around_.insert(bucket.first.offsetBy(x, y, z));
    }
    bool near(const openvdb::Coord& c, int r) const {
        // With r <= block the buckets looked at below are those of key(c)
        // and its 26 neighbours: one look-up rules out every cell far from
        // all seeds, which is nearly every cell of the mesh.
        if (r <= block_ && around_.count(key(c)) == 0) return false;
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
    std::unordered_set<openvdb::Coord, CoordHash> around_;  ///< the buckets' keys and their neighbours'
};

/// Every rank's seeds' cells, on every rank.
std::vector<openvdb::Coord> seed_cells(StreamScratch& scratch, const std::vector<std::uint64_t>& seeds,
                                       RankGroup& group) {
    std::vector<openvdb::Coord> cells;
    std::vector<ScratchVertex> vs;
    auto next = std::lower_bound(seeds.begin(), seeds.end(), scratch.first_global());
    for (std::size_t b = 0; b < scratch.bricks() && next != seeds.end(); ++b) {
        const std::uint64_t first = scratch.first_vertex(b), end = scratch.first_vertex(b + 1);
        if (*next >= end) continue;
        scratch.read_vertices(b, vs);
        for (; next != seeds.end() && *next < end; ++next) cells.push_back(vs[*next - first].cell);
    }
    return all_gather_values(group, cells, "the untangle stage's seeds");
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

/// One rank's share of the part: its vertices within reach + 1 of a seed,
/// its faces with a corner within reach (global numbers), and how many of
/// its vertices lie within reach.
struct RankPart {
    std::vector<std::uint64_t> global;
    std::vector<openvdb::Vec3d> points, safe;
    std::vector<openvdb::Coord> cells;
    std::vector<std::uint32_t> faces;
    std::uint64_t inner = 0;
};

RankPart rank_part(StreamScratch& scratch, const SeedCells& seeds, int reach, const LatticeTransform& xf) {
    RankPart part;
    // One bit per vertex of this rank: within reach of a seed.
    const std::uint64_t first = scratch.first_vertex(0), own = scratch.first_vertex(scratch.bricks()) - first;
    std::vector<std::uint64_t> inner((own + 63) / 64, 0);
    std::vector<ScratchVertex> vs;
    for (std::size_t b = 0; b < scratch.bricks(); ++b) {
        scratch.read_vertices(b, vs);
        for (std::size_t i = 0; i < vs.size(); ++i) {
            if (!seeds.near(vs[i].cell, reach + 1)) continue;
            part.global.push_back(scratch.first_vertex(b) + i);
            part.points.push_back(vs[i].position);
            part.safe.push_back(xf.to_world(safe_patch_position(vs[i].cell, vs[i].config, vs[i].joined, vs[i].patch)));
            part.cells.push_back(vs[i].cell);
            if (seeds.near(vs[i].cell, reach)) {
                const std::uint64_t k = part.global.back() - first;
                inner[k / 64] |= std::uint64_t(1) << (k % 64);
                ++part.inner;
            }
        }
    }
    // A corner is inner when it is this rank's and inner, or another rank's
    // in a cell within reach.
    auto inner_own = [&](std::uint32_t v) {
        const std::uint64_t k = std::uint64_t(v) - first;
        return std::uint64_t(v) >= first && k < own && ((inner[k / 64] >> (k % 64)) & 1);
    };
    const auto& foreign = scratch.foreign();
    auto next_foreign = foreign.begin();
    const int n = scratch.arity();
    std::vector<std::uint32_t> faces;
    for (std::size_t b = 0; b < scratch.bricks(); ++b) {
        scratch.read_faces(b, faces);
        const std::uint64_t at = scratch.first_index(b);
        for (std::size_t f = 0; f < faces.size(); f += std::size_t(n)) {
            bool any_inner = false;
            for (int k = 0; k < n; ++k) {
                const std::uint64_t position = at + f + std::size_t(k);
                while (next_foreign != foreign.end() && next_foreign->position < position) ++next_foreign;
                const bool is_foreign = next_foreign != foreign.end() && next_foreign->position == position;
                any_inner = any_inner || (is_foreign ? seeds.near(next_foreign->cell, reach)
                                                     : inner_own(faces[f + std::size_t(k)]));
            }
            if (any_inner) part.faces.insert(part.faces.end(), faces.begin() + std::ptrdiff_t(f), faces.begin() + std::ptrdiff_t(f) + n);
        }
    }
    return part;
}

std::string encode(const RankPart& p) {
    std::string bytes;
    PartWriter w(bytes);
    w.put(std::uint64_t(p.global.size()));
    w.put(std::uint64_t(p.faces.size()));
    w.put(p.inner);
    w.put_array(p.global);
    w.put_array(p.points);
    w.put_array(p.safe);
    w.put_array(p.cells);
    w.put_array(p.faces);
    return bytes;
}

/// The ranks' shares (rank 0's own first) merged into one part with local
/// numbering; `vertices`: the whole mesh's count.
Part merge(const std::vector<std::string>& shares, int arity, std::uint64_t vertices) {
    Part part;
    std::vector<std::uint32_t> faces;
    std::uint64_t inner = 0;
    for (const std::string& share : shares) {
        PartReader r(share, "the untangle stage's part of the mesh");
        const auto nv = std::size_t(r.get<std::uint64_t>()), nf = std::size_t(r.get<std::uint64_t>());
        inner += r.get<std::uint64_t>();
        if (nv * (sizeof(std::uint64_t) + 2 * sizeof(openvdb::Vec3d) + sizeof(openvdb::Coord)) + nf * sizeof(std::uint32_t) !=
            r.left())
            r.malformed("its sizes disagree");
        r.append_array(nv, part.global);
        r.append_array(nv, part.mesh.points);
        r.append_array(nv, part.safe);
        r.append_array(nv, part.cells);
        r.append_array(nf, faces);
    }
    part.whole = inner == vertices;
    auto local = [&](std::uint32_t v) -> std::uint32_t {
        const auto it = std::lower_bound(part.global.begin(), part.global.end(), std::uint64_t(v));
        if (it == part.global.end() || *it != v)
            throw std::logic_error("untangle_streamed: a face near a seed has a corner two cells away");
        return std::uint32_t(it - part.global.begin());
    };
    for (std::size_t f = 0; f < faces.size(); f += std::size_t(arity)) {
        if (arity == 3) part.mesh.triangles.emplace_back(local(faces[f]), local(faces[f + 1]), local(faces[f + 2]));
        else part.mesh.quads.emplace_back(local(faces[f]), local(faces[f + 1]), local(faces[f + 2]), local(faces[f + 3]));
    }
    return part;
}

/// Rank 0: untangles `part` (within `reach` of the seeds in `near`); the
/// verdict: whether the premise held (or the part is the whole mesh), the
/// stage's counters and the moved vertices.
std::string repair(Part part, const SeedCells& near, int reach, int margin, const LatticeTransform& xf,
                   const UntangleSettings& settings, const ExtractOptions& limits) {
    check_memory(double(part.global.size()) * kPartVertexBytes, limits, "part of the mesh the untangle stage repairs");
    const std::vector<openvdb::Vec3d> before = part.mesh.points;
    UntangleCounters c;
    untangle(part.mesh, part.safe, xf.transform->voxelSize()[0], settings, c);
    std::vector<std::uint64_t> moved;
    std::vector<openvdb::Vec3d> to;
    bool contained = true;
    for (std::size_t i = 0; i < before.size(); ++i) {
        if (part.mesh.points[i] == before[i]) continue;
        contained = contained && near.near(part.cells[i], reach - margin);
        moved.push_back(part.global[i]);
        to.push_back(part.mesh.points[i]);
    }
    std::string verdict;
    PartWriter w(verdict);
    w.put(std::uint8_t(contained || part.whole));
    w.put(c);
    w.put(std::uint64_t(moved.size()));
    w.put_array(moved);
    w.put_array(to);
    return verdict;
}

}  // namespace

std::vector<MovedVertex> untangle_streamed(StreamScratch& scratch, const std::vector<std::uint64_t>& seeds,
                                           double max_offset, std::uint64_t vertices, const LatticeTransform& xf,
                                           const UntangleSettings& settings, const ExtractOptions& limits,
                                           UntangleCounters& counters, RankGroup& group, int first_reach) {
    if (seeds.empty()) return {};
    // Corners of two triangles that meet lie within 2 + 2 max_offset cells;
    // one more for the corner that moved.
    const int margin = 3 + int(std::ceil(2.0 * max_offset));
    const std::vector<openvdb::Coord> cells = seed_cells(scratch, seeds, group);
    for (int reach = first_reach > 0 ? first_reach : 2 * margin;; reach *= 2) {
        const SeedCells near(cells, reach + 1);
        const std::vector<std::string> shares = group.gather_at_root(encode(rank_part(scratch, near, reach, xf)));
        std::string verdict;
        if (group.rank() == 0)
            verdict = repair(merge(shares, scratch.arity(), vertices), near, reach, margin, xf, settings, limits);
        verdict = group.broadcast_from_root(std::move(verdict));
        PartReader r(verdict, "the untangle stage's verdict");
        if (!r.get<std::uint8_t>()) continue;
        const auto c = r.get<UntangleCounters>();
        const auto n = std::size_t(r.get<std::uint64_t>());
        if (n * (sizeof(std::uint64_t) + sizeof(openvdb::Vec3d)) != r.left()) r.malformed("its sizes disagree");
        std::vector<std::uint64_t> moved;
        std::vector<openvdb::Vec3d> to;
        r.append_array(n, moved);
        r.append_array(n, to);
        std::vector<MovedVertex> out(n);
        for (std::size_t i = 0; i < n; ++i) out[i] = {moved[i], to[i]};
        counters += c;
        return out;
    }
}

}  // namespace pqdc::detail
