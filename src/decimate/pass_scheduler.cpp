// The parallel pass scheduler: collapses run in passes of independent sets,
// in the manner of meshoptimizer's simplifier (src/simplifier.cpp: rank all
// edges by cost, take the cheapest whose one-rings do not touch, stop a pass
// at 1.5x the cost of the goal-th cheapest) instead of one global heap.
// Every step is either a pure function of the mesh at the start of the pass
// evaluated in parallel, or a serial loop in (cost, edge index) order, so the
// result is the same for any thread count.
//
// Independence: accepting a-b locks every vertex of the faces around a and
// b; a later candidate may not have a locked end point. So no two collapses
// of a pass write the same face or vertex, and each one's topology and
// shape checks (made on the pass's starting mesh) still hold after the
// others. Their created faces may still meet each other (two sheets close
// together), so a collapse is dropped when its faces meet those of a
// cheaper accepted collapse of the same pass.

#include "decimate_internal.hpp"

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>

namespace pqdc::decimate_detail {
namespace {

constexpr std::uint32_t kDead = std::numeric_limits<std::uint32_t>::max();

template <class F>
void parallel_each(std::size_t n, std::size_t grain, F&& f) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, grain), [&](const auto& r) {
        for (std::size_t i = r.begin(); i < r.end(); ++i) f(i);
    });
}

/// Each undirected edge once: an interior edge of a consistently oriented
/// manifold is a -> b with a < b in exactly one of its two faces.
std::vector<std::array<std::uint32_t, 2>> collapsible_edges(const WorkMesh& m) {
    std::vector<std::array<std::uint32_t, 2>> edges;
    edges.reserve(m.tris.size() * 3 / 2);
    for (const Tri& t : m.tris)
        for (int k = 0; k < 3; ++k) {
            const std::uint32_t a = t[k], b = t[(k + 1) % 3];
            if (a < b && !m.locked[a] && !m.locked[b]) edges.push_back({a, b});
        }
    return edges;
}

/// Drops accepted collapses whose created faces meet the created faces of a
/// cheaper accepted one (rank = position in `accepted`). One grid entry per
/// collapse (the box of its created faces): neighbouring collapses are
/// found once, then their faces are paired through their boxes.
void drop_conflicting(const WorkMesh& m, const std::vector<Candidate>& accepted, std::vector<Verdict>& verdict) {
    // Ok collapses in vertex (space) order for cache locality; their rank
    // (cost order) is their index in `accepted`.
    std::vector<std::uint32_t> owners;
    for (std::size_t i = 0; i < accepted.size(); ++i)
        if (verdict[i] == Verdict::ok) owners.push_back(std::uint32_t(i));
    if (owners.size() < 2) return;
    std::sort(owners.begin(), owners.end(), [&](std::uint32_t i, std::uint32_t j) { return accepted[i].a < accepted[j].a; });
    std::vector<std::uint32_t> begin(owners.size() + 1, 0);
    std::vector<Tri> faces;
    std::vector<Tri> tmp;
    for (std::size_t o = 0; o < owners.size(); ++o) {
        new_faces(m, accepted[owners[o]], tmp);
        faces.insert(faces.end(), tmp.begin(), tmp.end());
        begin[o + 1] = std::uint32_t(faces.size());
    }
    std::vector<std::array<vec, 3>> fp(faces.size());
    std::vector<BoxPair> boxes(faces.size()), owner_box(owners.size());
    parallel_each(owners.size(), 256, [&](std::size_t o) {
        const Candidate& c = accepted[owners[o]];
        BoxPair all{c.x, c.x};
        for (std::uint32_t f = begin[o]; f < begin[o + 1]; ++f) {
            vec lo{}, hi{};
            for (int k = 0; k < 3; ++k) {
                const vec p = faces[f][k] == c.a ? c.x : m.pos[faces[f][k]];
                fp[f][k] = p;
                lo = k ? vec{std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)} : p;
                hi = k ? vec{std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)} : p;
            }
            boxes[f] = {lo, hi};
            all[0] = {std::min(all[0].x, lo.x), std::min(all[0].y, lo.y), std::min(all[0].z, lo.z)};
            all[1] = {std::max(all[1].x, hi.x), std::max(all[1].y, hi.y), std::max(all[1].z, hi.z)};
        }
        owner_box[o] = all;
    });
    const TriangleGrid grid(owner_box);
    std::vector<std::uint8_t> hit(owners.size(), 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, owners.size(), 64), [&](const auto& r) {
        std::vector<std::uint32_t> near;
        for (std::size_t o = r.begin(); o < r.end(); ++o) {
            grid.query(owner_box[o][0], owner_box[o][1], near);
            for (std::uint32_t q : near) {
                if (owners[q] >= owners[o]) continue;  // only cheaper collapses
                for (std::uint32_t g = begin[q]; g < begin[q + 1] && !hit[o]; ++g) {
                    if (!boxes_meet(boxes[g], owner_box[o])) continue;
                    for (std::uint32_t f = begin[o]; f < begin[o + 1]; ++f)
                        if (boxes_meet(boxes[f], boxes[g]) &&
                            !certainly_apart(exact::plane_filter(fp[f].data()), faces[f], faces[g], fp[g].data()) &&
                            faces_intersect(faces[f], fp[f].data(), faces[g], fp[g].data())) {
                            hit[o] = 1;
                            break;
                        }
                }
                if (hit[o]) break;
            }
        }
    });
    for (std::size_t o = 0; o < owners.size(); ++o)
        if (hit[o]) verdict[owners[o]] = Verdict::intersection;
}

void apply_collapses(WorkMesh& m, const std::vector<Candidate>& accepted, const std::vector<Verdict>& verdict,
                     bool spheres) {
    parallel_each(accepted.size(), 256, [&](std::size_t i) {
        if (verdict[i] != Verdict::ok) return;
        const Candidate& c = accepted[i];
        if (spheres) {
            const vec e = m.pos[c.b] - m.pos[c.a];
            const double ee = dot(e, e);
            const double t = ee > 0 ? std::clamp(dot(c.x - m.pos[c.a], e) / ee, 0.0, 1.0) : 0.5;
            m.spheres[c.a] = m.spheres[c.a].lerp(m.spheres[c.b], t);
        }
        m.pos[c.a] = c.x;
        m.quadrics[c.a] += m.quadrics[c.b];
        for (std::size_t k = 0; k < m.fan_size(c.b); ++k) {
            Tri& t = m.tris[m.fan_of(c.b)[k]];
            const bool has_a = t[0] == c.a || t[1] == c.a || t[2] == c.a;
            if (has_a) {
                t = {kDead, kDead, kDead};
                continue;
            }
            for (auto& v : t)
                if (v == c.b) v = c.a;
        }
    });
    m.tris.erase(std::remove_if(m.tris.begin(), m.tris.end(), [](const Tri& t) { return t[0] == kDead; }),
                 m.tris.end());
}

}  // namespace

void rebuild_fans(WorkMesh& m) {
    m.fan_begin.assign(m.pos.size() + 1, 0);
    for (const Tri& t : m.tris)
        for (std::uint32_t v : t) ++m.fan_begin[v + 1];
    std::partial_sum(m.fan_begin.begin(), m.fan_begin.end(), m.fan_begin.begin());
    m.fan.resize(m.tris.size() * 3);
    std::vector<std::uint32_t> fill(m.fan_begin.begin(), m.fan_begin.end() - 1);
    for (std::size_t i = 0; i < m.tris.size(); ++i)
        for (std::uint32_t v : m.tris[i]) m.fan[fill[v]++] = std::uint32_t(i);
}

PassResult run_pass(WorkMesh& m, const DecimateOptions& o, const CheckLimits& lim, std::size_t target_faces,
                    bool unlimited) {
    PassResult res;
    rebuild_fans(m);
    const auto edges = collapsible_edges(m);
    if (edges.empty() || m.tris.size() <= target_faces) return res;
    std::vector<Candidate> cand(edges.size());
    parallel_each(edges.size(), 1024, [&](std::size_t i) { cand[i] = evaluate_collapse(m, edges[i][0], edges[i][1], o.metric); });
    // Sort (cost, edge index) pairs directly: costs are >= 0, so their bit
    // patterns order like the values; edge indices follow the face order.
    struct Key {
        std::uint64_t cost;
        std::uint32_t edge;
        bool operator<(const Key& o) const { return cost != o.cost ? cost < o.cost : edge < o.edge; }
    };
    std::vector<Key> keys(edges.size());
    parallel_each(edges.size(), 4096, [&](std::size_t i) {
        std::uint64_t bits;
        const double c = cand[i].cost;
        std::memcpy(&bits, &c, sizeof bits);
        keys[i] = {bits, std::uint32_t(i)};
    });
    // Only the candidates up to the cost limit are ever looked at: find the
    // goal-th key, keep the keys up to 1.5x its cost, sort those. The result
    // is the prefix of the full (cost, edge) order.
    const std::size_t goal = (m.tris.size() - target_faces + 1) / 2;
    if (goal < keys.size() && !unlimited) {
        std::nth_element(keys.begin(), keys.begin() + std::ptrdiff_t(goal), keys.end());
        const double limit = 1.5 * cand[keys[goal].edge].cost;
        keys.erase(std::partition(keys.begin(), keys.end(), [&](const Key& k) { return cand[k.edge].cost <= limit; }),
                   keys.end());
    }
    tbb::parallel_sort(keys.begin(), keys.end());
    std::vector<std::uint32_t> order(keys.size());
    for (std::size_t i = 0; i < keys.size(); ++i) order[i] = keys[i].edge;
    const std::size_t prefix = order.size();

    // Serial in cost order: the cheap checks run only for candidates whose
    // end points are still free, so their cost follows the accepted count.
    std::vector<std::uint8_t> busy(m.pos.size(), 0);
    std::vector<Candidate> accepted;
    for (std::size_t i = 0; i < prefix && accepted.size() < goal; ++i) {
        const Candidate& c = cand[order[i]];
        if (busy[c.a] || busy[c.b]) continue;
        const Verdict v = !link_condition_holds(m, c.a, c.b) ? Verdict::link : check_shape(m, c, lim);
        if (v != Verdict::ok) {
            ++res.rejected[int(v)];
            continue;
        }
        for (std::uint32_t w : {c.a, c.b})
            for (std::size_t k = 0; k < m.fan_size(w); ++k)
                for (std::uint32_t x : m.tris[m.fan_of(w)[k]]) busy[x] = 1;
        accepted.push_back(c);
    }
    if (accepted.empty()) return res;

    const TriangleGrid grid(triangle_boxes(m.pos, m.tris));
    std::vector<Verdict> verdict(accepted.size());
    // Checked in vertex order (dual contouring numbers vertices in space
    // order), so neighbouring checks share cached grid cells and faces;
    // each verdict depends on its candidate only.
    std::vector<std::uint32_t> by_vertex(accepted.size());
    std::iota(by_vertex.begin(), by_vertex.end(), 0u);
    std::sort(by_vertex.begin(), by_vertex.end(), [&](std::uint32_t i, std::uint32_t j) { return accepted[i].a < accepted[j].a; });
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, accepted.size(), 64), [&](const auto& r) {
        CheckScratch scratch;
        for (std::size_t k = r.begin(); k < r.end(); ++k) {
            const std::uint32_t i = by_vertex[k];
            verdict[i] = check_intersection_and_distance(m, grid, accepted[i], lim, scratch);
        }
    });
    drop_conflicting(m, accepted, verdict);
    for (Verdict v : verdict) {
        if (v == Verdict::ok) ++res.collapses;
        else ++res.rejected[int(v)];
    }
    apply_collapses(m, accepted, verdict, o.metric == DecimateMetric::curvature);
    return res;
}

}  // namespace pqdc::decimate_detail
