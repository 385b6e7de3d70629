#include "adaptive/collapse.hpp"

#include "adaptive/octree.hpp"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <numeric>
#include <utility>

namespace pqdc::adaptive_detail {
namespace {

constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();

std::uint64_t pair_key(std::uint32_t a, std::uint32_t b) {
    return a < b ? std::uint64_t(a) << 32 | b : std::uint64_t(b) << 32 | a;
}

void sort_unique(std::vector<std::uint32_t>& v) {
    std::sort(v.begin(), v.end());
    v.erase(std::unique(v.begin(), v.end()), v.end());
}

/// The state of the collapses: merged groups as union-find with member
/// lists, and the original triangles around every vertex on a candidate edge.
class Collapser {
public:
    struct Scratch {
        std::vector<std::uint32_t> fk, fd, na, nb;
    };

    Collapser(std::size_t nv, std::vector<openvdb::Vec3I>& tris, std::vector<std::uint32_t>& rep,
              std::vector<std::uint8_t>& alive, const std::vector<std::pair<std::uint64_t, std::uint64_t>>& edges)
        : tris_(tris), rep_(rep), alive_(alive), edges_(edges), next_member_(nv, kNone), last_member_(nv) {
        std::iota(last_member_.begin(), last_member_.end(), 0u);
        // Original incident triangles (CSR) of the vertices on those edges; a
        // merged group's triangles are those of its members (linked list).
        std::vector<std::uint8_t> involved(nv, 0);
        for (const auto& e : edges) involved[e.second >> 32] = involved[std::uint32_t(e.second)] = 1;
        first_.assign(nv + 1, 0);
        for (const auto& t : tris)
            for (int k = 0; k < 3; ++k)
                if (involved[t[k]]) ++first_[t[k] + 1];
        for (std::size_t v = 0; v < nv; ++v) first_[v + 1] += first_[v];
        incident_.resize(first_[nv]);
        std::vector<std::uint32_t> fill(first_.begin(), first_.end() - 1);
        for (std::uint32_t t = 0; t < tris.size(); ++t)
            for (int k = 0; k < 3; ++k)
                if (involved[tris[t][k]]) incident_[fill[tris[t][k]]++] = t;
    }

    std::uint32_t find(std::uint32_t v) {
        while (rep_[v] != v) v = rep_[v] = rep_[rep_[v]];
        return v;
    }

    /// Tries the edges [begin, end) in order; true when one collapsed.
    bool run(std::size_t begin, std::size_t end, Scratch& sc) {
        bool changed = false;
        for (std::size_t ei = begin; ei < end; ++ei) {
            const std::uint64_t e = edges_[ei].second;
            const std::uint32_t a = find(std::uint32_t(e >> 32)), b = find(std::uint32_t(e));
            if (a == b) continue;
            const std::uint32_t keep = std::min(a, b), drop = std::max(a, b);
            if (!link_condition(keep, drop, sc)) continue;
            merge(keep, drop, sc.fd);
            changed = true;
        }
        return changed;
    }

private:
    /// The triangles (alive) of a merged group.
    void gather(std::uint32_t root, std::vector<std::uint32_t>& out) const {
        out.clear();
        for (std::uint32_t m = root; m != kNone; m = next_member_[m])
            for (std::uint32_t i = first_[m]; i < first_[m + 1]; ++i)
                if (alive_[incident_[i]]) out.push_back(incident_[i]);
        sort_unique(out);
    }

    /// Exactly two triangles share the edge, with distinct apexes, and the
    /// two ends have exactly those two neighbours in common. Leaves the
    /// triangles of keep in sc.fk and of drop in sc.fd.
    bool link_condition(std::uint32_t keep, std::uint32_t drop, Scratch& sc) const {
        gather(keep, sc.fk);
        gather(drop, sc.fd);
        sc.na.clear();
        sc.nb.clear();
        std::uint32_t apex[2] = {0, 0};
        int shared = 0;
        for (std::uint32_t t : sc.fk) {
            bool has_drop = false;
            for (int k = 0; k < 3; ++k) has_drop = has_drop || tris_[t][k] == drop;
            for (int k = 0; k < 3; ++k) {
                const std::uint32_t v = tris_[t][k];
                if (v == keep || v == drop) continue;
                sc.na.push_back(v);
                if (has_drop && shared < 2) apex[shared] = v;
            }
            if (has_drop) ++shared;
        }
        for (std::uint32_t t : sc.fd)
            for (int k = 0; k < 3; ++k)
                if (tris_[t][k] != keep && tris_[t][k] != drop) sc.nb.push_back(tris_[t][k]);
        if (shared != 2 || apex[0] == apex[1]) return false;
        sort_unique(sc.na);
        sort_unique(sc.nb);
        std::size_t common = 0;
        for (std::size_t i = 0, j = 0; i < sc.na.size() && j < sc.nb.size();) {
            if (sc.na[i] < sc.nb[j]) ++i;
            else if (sc.nb[j] < sc.na[i]) ++j;
            else {
                ++common;
                ++i;
                ++j;
            }
        }
        // The merged vertex keeps |na| + |nb| - 2 neighbours; fewer than 3
        // (a tetrahedron) would leave two faces on the same three vertices.
        return common == 2 && sc.na.size() + sc.nb.size() >= 5;
    }

    void merge(std::uint32_t keep, std::uint32_t drop, const std::vector<std::uint32_t>& drop_tris) {
        for (std::uint32_t t : drop_tris) {
            bool has_keep = false;
            for (int k = 0; k < 3; ++k) has_keep = has_keep || tris_[t][k] == keep;
            if (has_keep) {
                alive_[t] = 0;
                continue;
            }
            for (int k = 0; k < 3; ++k)
                if (tris_[t][k] == drop) tris_[t][k] = keep;
        }
        rep_[drop] = keep;
        next_member_[last_member_[keep]] = drop;
        last_member_[keep] = last_member_[drop];
    }

    std::vector<openvdb::Vec3I>& tris_;
    std::vector<std::uint32_t>& rep_;
    std::vector<std::uint8_t>& alive_;
    const std::vector<std::pair<std::uint64_t, std::uint64_t>>& edges_;
    std::vector<std::uint32_t> first_, incident_, next_member_, last_member_;
};

}  // namespace

void collapse_coincident_vertices(const std::vector<openvdb::Vec3d>& points, const std::vector<std::uint64_t>& tile,
                                  std::vector<openvdb::Vec3I>& tris, std::vector<std::uint32_t>& rep,
                                  std::vector<std::uint8_t>& alive, const detail::ProgressSpan& span) {
    const std::size_t nv = points.size();
    rep.resize(nv);
    std::iota(rep.begin(), rep.end(), 0u);
    alive.assign(tris.size(), 1);
    // (tile, edge) so that sorting groups the edges by tile in a fixed order.
    std::vector<std::pair<std::uint64_t, std::uint64_t>> edges;
    for (const auto& t : tris)
        for (int k = 0; k < 3; ++k) {
            const std::uint32_t a = t[k], b = t[(k + 1) % 3];
            if (a != b && points[a] == points[b]) edges.emplace_back(tile[a] == tile[b] ? tile[a] : kNoTile, pair_key(a, b));
        }
    if (edges.empty()) return;
    span.report(0.1);
    tbb::parallel_sort(edges.begin(), edges.end());
    edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
    span.report(0.2);
    Collapser collapser(nv, tris, rep, alive, edges);
    span.report(0.3);

    // Runs of edges per tile, grouped by the tile's parity class.
    struct Run {
        std::size_t begin, end;
    };
    std::array<std::vector<Run>, 8> by_color;
    std::size_t mixed_begin = edges.size();
    for (std::size_t i = 0; i < edges.size();) {
        const std::uint64_t t = edges[i].first;
        std::size_t j = i;
        while (j < edges.size() && edges[j].first == t) ++j;
        if (t == kNoTile) {
            mixed_begin = i;
        } else {
            const auto c = unmorton(t);
            by_color[(c[0] & 1) | (c[1] & 1) << 1 | (c[2] & 1) << 2].push_back({i, j});
        }
        i = j;
    }
    tbb::enumerable_thread_specific<Collapser::Scratch> scratch;
    for (int pass = 0; pass < 4; ++pass) {
        std::atomic<bool> changed{false};
        for (int color = 0; color < 8; ++color) {
            const auto& runs = by_color[std::size_t(color)];
            tbb::parallel_for(std::size_t(0), runs.size(), [&](std::size_t r) {
                if (collapser.run(runs[r].begin, runs[r].end, scratch.local())) changed = true;
            });
            span.report(0.3 + 0.4 * (pass * 8 + color + 1) / 32.0);
        }
        if (!changed) break;
    }
    // Then every edge in order, sequentially: a collapse across tiles joins
    // groups of two tiles, which the parallel passes must not see. Edges
    // already collapsed are skipped at the cost of two finds. (Chunks of the
    // sweep, for the progress reports, keep its order.)
    constexpr std::size_t kEdgesPerReport = 1 << 16;
    if (mixed_begin < edges.size())
        for (int pass = 0; pass < 4; ++pass) {
            bool changed = false;
            for (std::size_t b = 0; b < edges.size(); b += kEdgesPerReport) {
                changed = collapser.run(b, std::min(edges.size(), b + kEdgesPerReport), scratch.local()) || changed;
                span.report(0.7 + 0.075 * (pass + double(b) / double(edges.size())));
            }
            if (!changed) break;
        }
    for (std::uint32_t v = 0; v < rep.size(); ++v) rep[v] = collapser.find(v);
}

}  // namespace pqdc::adaptive_detail
