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
#include "memory/huge_pages.hpp"

#include <tbb/parallel_invoke.h>
#include <tbb/task_arena.h>
#include <tbb/task_group.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <utility>

namespace pqdc::decimate_detail {
namespace {

constexpr std::uint32_t kDead = std::numeric_limits<std::uint32_t>::max();

/// Where a pass is, as the share of its work done at the end of each stage:
/// the stages' shares of a pass's time on one thread (the 1.5 M-triangle
/// noisy sphere to 10%; two threads differ by a few percent). Progress only.
namespace share {
constexpr double edges = 0.02, costed = 0.10, sorted = 0.12, selected = 0.27, grid = 0.34, created = 0.40,
                 mesh_checked = 0.79, conflicts = 0.98;
}
/// The long parallel checks run in slices of at least this many
/// collapses (about 50 ms on one thread), at most 8, with a checkpoint
/// after each: small passes keep one slice, one wait for the threads.
constexpr std::size_t kSliceCollapses = 16384, kMaxSlices = 8;

/// f(begin, end) over [0, n) in slices, each in parallel chunks of about
/// `grain`, then after(finished share) from the calling thread. Items are
/// independent, so slicing changes no result.
template <class F>
void parallel_slices(std::size_t n, std::size_t grain, F&& f, const std::function<void(double)>& after) {
    const std::size_t slices = std::clamp<std::size_t>(n / kSliceCollapses, 1, kMaxSlices);
    for (std::size_t k = 0; k < slices; ++k) {
        const std::size_t begin = n * k / slices, end = n * (k + 1) / slices;
        tbb::parallel_for(tbb::blocked_range<std::size_t>(begin, end, grain),
                          [&](const auto& r) { f(r.begin(), r.end()); });
        after(double(k + 1) / double(slices));
    }
}

/// Each undirected edge once: an interior edge of a consistently oriented
/// manifold is a -> b with a < b in exactly one of its two faces.
void collect_collapsible_edges(const WorkMesh& m, std::vector<std::array<std::uint32_t, 2>>& edges) {
    edges.clear();
    detail::reserve_large(edges, m.tris.size() * 3 / 2);  // a closed mesh's edge count: no doubling growth
    for (const Tri& t : m.tris)
        for (int k = 0; k < 3; ++k) {
            const std::uint32_t a = t[k], b = t[(k + 1) % 3];
            if (a < b && !m.locked[a] && !m.locked[b]) edges.push_back({a, b});
        }
}

/// Sort keys: the cost rounded to float (costs are >= 0, so the bits order
/// like the values) above the edge index. A stable LSD radix sort of the
/// cost bits, from edge order, gives (cost, edge) order in three linear
/// passes; a comparison sort of double costs took about a tenth of the run.
std::uint64_t cost_key(double cost, std::uint32_t edge) {
    const float c = float(cost);
    std::uint32_t bits;
    std::memcpy(&bits, &c, sizeof bits);
    return (std::uint64_t(bits) << 32) | edge;
}

/// Stable LSD radix sort of the keys by their upper 32 bits. Each digit
/// pass: every chunk counts its digits (in parallel), the chunks' counts
/// become offsets in (digit, chunk) order, and every chunk scatters its keys
/// in order (in parallel): stable, so the order is the serial one.
void sort_by_high_word(std::vector<std::uint64_t>& keys, std::vector<std::uint64_t>& tmp) {
    constexpr int kDigitBits = 11;
    constexpr std::size_t kDigits = std::size_t(1) << kDigitBits;
    // Any number of chunks gives the same order; one thread takes one.
    const std::size_t kChunks = std::min<std::size_t>(16, 2 * std::size_t(tbb::this_task_arena::max_concurrency()) - 1);
    const std::size_t n = keys.size(), chunk = (n + kChunks - 1) / kChunks;
    detail::reserve_large(tmp, n);
    tmp.resize(n);
    std::vector<std::size_t> count(kChunks * kDigits);
    for (int shift = 32; shift < 64; shift += kDigitBits) {
        const std::uint64_t mask = kDigits - 1;
        std::fill(count.begin(), count.end(), 0);
        parallel_ranges(kChunks, 1, [&](std::size_t c0, std::size_t c1) {
            for (std::size_t c = c0; c < c1; ++c) {
                std::size_t* counts = count.data() + c * kDigits;
                const std::uint64_t* k = keys.data();
                for (std::size_t i = c * chunk, end = std::min(n, (c + 1) * chunk); i < end; ++i)
                    ++counts[(k[i] >> shift) & mask];
            }
        });
        std::size_t sum = 0;
        bool one_bucket = false;
        for (std::size_t d = 0; d < kDigits; ++d) {
            std::size_t in_digit = 0;
            for (std::size_t c = 0; c < kChunks; ++c) {
                in_digit += count[c * kDigits + d];
                sum += std::exchange(count[c * kDigits + d], sum);
            }
            one_bucket = one_bucket || in_digit == n;
        }
        if (one_bucket) continue;  // one digit value: already in order
        parallel_ranges(kChunks, 1, [&](std::size_t c0, std::size_t c1) {
            for (std::size_t c = c0; c < c1; ++c) {
                std::size_t* next = count.data() + c * kDigits;
                const std::uint64_t* k = keys.data();
                std::uint64_t* out = tmp.data();
                for (std::size_t i = c * chunk, end = std::min(n, (c + 1) * chunk); i < end; ++i)
                    out[next[(k[i] >> shift) & mask]++] = k[i];
            }
        });
        keys.swap(tmp);
    }
}

/// Marks every vertex of the faces around the end points of an edge busy;
/// with `marked`, lists the ones it marks (to undo them).
void lock_around(const WorkMesh& m, const std::array<std::uint32_t, 2>& ends, std::vector<std::uint8_t>& busy,
                 std::vector<std::uint32_t>* marked) {
    for (std::uint32_t w : ends)
        for (std::size_t k = 0; k < m.fan_size(w); ++k)
            for (std::uint32_t x : m.tris[m.fan_of(w)[k]])
                if (!busy[x]) {
                    busy[x] = 1;
                    if (marked) marked->push_back(x);
                }
}

/// The selection's walk over a pass's candidates in cost order. The order
/// scatters it over the mesh, and most of its steps only test two marks:
/// the end points are gathered in that order first (in parallel: independent
/// loads), so those steps read them in sequence. A block's candidates that
/// are free when it starts are listed (free_list); the walk then goes
/// through that short list, and prefetch(k) issues the loads that a taken
/// candidate needs (its quadrics, fans and faces) a few entries ahead. On
/// the 1.5 M-face sphere this made the walk 3.4x faster.
class CostOrderWalk {
public:
    CostOrderWalk(const WorkMesh& m, PassBuffers& b, std::size_t prefix) : m_(m), b_(b), prefix_(prefix) {
        b.ends.resize(prefix);
        parallel_ranges(prefix, 4096, [&](std::size_t begin, std::size_t end) {
            for (std::size_t i = begin; i < end; ++i) b.ends[i] = b.edges[std::uint32_t(b.order[i])];
        });
    }
    /// Whether the i-th cheapest candidate's end points are unmarked.
    bool free(std::size_t i) const { return !b_.busy[b_.ends[i][0]] && !b_.busy[b_.ends[i][1]]; }
    /// The candidates of [first, first + count) that are free now, into b.free_list.
    void list_free(std::size_t first, std::size_t count) {
        b_.free_list.clear();
        for (std::size_t i = first; i < first + count; ++i) {
            if (i + 16 < prefix_) {
                __builtin_prefetch(&b_.busy[b_.ends[i + 16][0]]);
                __builtin_prefetch(&b_.busy[b_.ends[i + 16][1]]);
            }
            if (free(i)) b_.free_list.push_back(std::uint32_t(i));
        }
    }
    /// Before visiting free_list[k]. always_inline: GCC takes a function of
    /// prefetches alone for a pure one and drops its calls.
    [[gnu::always_inline]] void prefetch(std::size_t k) const {
        const std::vector<std::uint32_t>& l = b_.free_list;
        if (k + 8 < l.size()) {
            for (std::uint32_t w : b_.ends[l[k + 8]]) {
                __builtin_prefetch(&m_.fan_begin[w]);
                __builtin_prefetch(&m_.quadrics[w]);
            }
        }
        if (k + 4 < l.size())
            for (std::uint32_t w : b_.ends[l[k + 4]]) __builtin_prefetch(m_.fan_of(w));
        if (k + 2 < l.size())
            for (std::uint32_t w : b_.ends[l[k + 2]])
                for (std::size_t f = 0, n = std::min<std::size_t>(m_.fan_size(w), 8); f < n; ++f)
                    __builtin_prefetch(&m_.tris[m_.fan_of(w)[f]]);
    }

private:
    const WorkMesh& m_;
    PassBuffers& b_;
    std::size_t prefix_;
};

/// Greedy in (cost, edge) order: a candidate is taken when its end points
/// are free and it passes the link and shape checks; taking it locks every
/// vertex of its faces. Block by block, a serial walk first takes every
/// free candidate as if its checks passed (they almost always do); the
/// checks of exactly those run in parallel (they are pure functions of the
/// pass's starting mesh); if one fails, the block's tentative locks are
/// undone and the walk resumes serially after it, reusing the checks already
/// made. So the decisions are those of a plain serial loop (which one
/// thread runs), and no check is made for a candidate the loop would not
/// have checked.
void select_independent(const WorkMesh& m, const CheckLimits& lim, DecimateMetric metric, PassBuffers& b,
                        std::size_t prefix, std::size_t goal, PassResult& res, const PassCheckpoint& checkpoint) {
    constexpr std::size_t kBlock = 1024;
    // Every 64 blocks: the walk's progress is whichever of the candidates
    // walked and the collapses taken is further.
    auto report = [&](std::size_t first) {
        if ((first / kBlock) % 64 != 63) return;
        const double walked = std::max(double(first) / double(prefix), double(b.accepted.size()) / double(goal));
        checkpoint(share::sorted + (share::selected - share::sorted) * std::min(walked, 1.0), 0);
    };
    b.busy.assign(m.pos.size(), 0);
    b.accepted.clear();
    b.block_verdict.resize(kBlock);
    b.block_known.resize(kBlock);
    b.block_candidate.resize(kBlock);
    CostOrderWalk walk(m, b, prefix);
    // Costed again where needed (the same function of the same data): a
    // stored candidate per edge took 40 bytes an edge at the run's peak.
    auto candidate = [&](std::size_t i) { return evaluate_collapse(m, b.ends[i][0], b.ends[i][1], metric); };
    auto verdict = [&](const Candidate& c) {
        return !link_condition_holds(m, c.a, c.b) ? Verdict::link : check_shape(m, c, lim);
    };
    if (tbb::this_task_arena::max_concurrency() == 1) {
        // One thread: check in the walk, while the candidate's faces are in cache.
        for (std::size_t first = 0; first < prefix && b.accepted.size() < goal; first += kBlock) {
            walk.list_free(first, std::min(kBlock, prefix - first));
            for (std::size_t k = 0; k < b.free_list.size() && b.accepted.size() < goal; ++k) {
                walk.prefetch(k);
                const std::size_t i = b.free_list[k];
                if (!walk.free(i)) continue;
                const Candidate c = candidate(i);
                const Verdict v = verdict(c);
                if (v != Verdict::ok) {
                    ++res.rejected[int(v)];
                    continue;
                }
                lock_around(m, b.ends[i], b.busy, nullptr);
                b.accepted.push_back(c);
            }
            report(first);
        }
        return;
    }
    for (std::size_t first = 0; first < prefix && b.accepted.size() < goal; first += kBlock) {
        const std::size_t count = std::min(kBlock, prefix - first);
        b.want.clear();
        b.marked.clear();
        walk.list_free(first, count);
        for (std::size_t k = 0; k < b.free_list.size() && b.accepted.size() + b.want.size() < goal; ++k) {
            walk.prefetch(k);
            const std::size_t i = b.free_list[k];
            if (!walk.free(i)) continue;
            b.want.push_back(std::uint32_t(i - first));
            lock_around(m, b.ends[i], b.busy, &b.marked);
        }
        parallel_ranges(b.want.size(), 32, [&](std::size_t begin, std::size_t end) {
            for (std::size_t k = begin; k < end; ++k) {
                const std::uint32_t i = b.want[k];
                b.block_candidate[i] = candidate(first + i);
                b.block_verdict[i] = verdict(b.block_candidate[i]);
            }
        });
        std::size_t k = 0;
        for (; k < b.want.size() && b.block_verdict[b.want[k]] == Verdict::ok; ++k)
            b.accepted.push_back(b.block_candidate[b.want[k]]);
        if (k == b.want.size()) {
            report(first);
            continue;
        }
        // A refusal: redo the block's locks up to it, then walk on serially.
        for (std::uint32_t v : b.marked) b.busy[v] = 0;
        for (std::size_t j = b.accepted.size() - k; j < b.accepted.size(); ++j)
            lock_around(m, {b.accepted[j].a, b.accepted[j].b}, b.busy, nullptr);
        ++res.rejected[int(b.block_verdict[b.want[k]])];
        std::fill(b.block_known.begin(), b.block_known.begin() + std::ptrdiff_t(count), 0);
        for (std::uint32_t i : b.want) b.block_known[i] = 1;
        for (std::size_t i = b.want[k] + 1; i < count && b.accepted.size() < goal; ++i) {
            if (!walk.free(first + i)) continue;
            if (!b.block_known[i]) {
                b.block_candidate[i] = candidate(first + i);
                b.block_verdict[i] = verdict(b.block_candidate[i]);
            }
            if (b.block_verdict[i] != Verdict::ok) {
                ++res.rejected[int(b.block_verdict[i])];
                continue;
            }
            lock_around(m, b.ends[first + i], b.busy, nullptr);
            b.accepted.push_back(b.block_candidate[i]);
        }
        report(first);
    }
}

/// From here on the accepted collapses are kept in vertex order (dual
/// contouring numbers vertices in space order), each with its rank in cost
/// order: neighbouring collapses then sit close in memory and share cached
/// faces and grid cells, where cost order scattered every access.
void order_by_vertex(PassBuffers& b) {
    // Keys (a << 32 | rank), sorted by a with the cost order's radix sort
    // (the buffers of the cost order, done with): the end points a are
    // distinct, the collapses being independent.
    const std::size_t n = b.accepted.size();
    b.order.resize(n);
    for (std::size_t k = 0; k < n; ++k) b.order[k] = std::uint64_t(b.accepted[k].a) << 32 | k;
    sort_by_high_word(b.order, b.order_tmp);
    b.rank.resize(n);
    b.scratch.resize(n);
    parallel_ranges(n, 4096, [&](std::size_t begin, std::size_t end) {
        for (std::size_t k = begin; k < end; ++k) {
            b.rank[k] = std::uint32_t(b.order[k]);
            b.scratch[k] = b.accepted[b.rank[k]];
        }
    });
    b.accepted.swap(b.scratch);
}

/// The created faces of every accepted collapse, once, for the checks
/// against the mesh and against each other.
void write_all_created_faces(const WorkMesh& m, PassBuffers& b) {
    const std::size_t n = b.accepted.size();
    b.created_begin.resize(n + 1);
    b.created_begin[0] = 0;
    for (std::size_t i = 0; i < n; ++i)
        b.created_begin[i + 1] = b.created_begin[i] + std::uint32_t(created_face_count(m, b.accepted[i]));
    detail::reserve_large(b.created_tris, b.created_begin[n]);
    detail::reserve_large(b.created_points, b.created_begin[n]);
    detail::reserve_large(b.created_boxes, b.created_begin[n]);
    b.created_tris.resize(b.created_begin[n]);
    b.created_points.resize(b.created_begin[n]);
    b.created_boxes.resize(b.created_begin[n]);
    b.created_all.resize(n);
    parallel_ranges(n, 256, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
            const std::uint32_t f = b.created_begin[i];
            b.created_all[i] = write_created_faces(m, b.accepted[i], b.created_tris.data() + f,
                                                   b.created_points.data() + f, b.created_boxes.data() + f);
        }
    });
}

CreatedFaces created_faces(const PassBuffers& b, std::size_t i) {
    const std::uint32_t f = b.created_begin[i];
    return {b.created_tris.data() + f, b.created_points.data() + f, b.created_boxes.data() + f,
            std::size_t(b.created_begin[i + 1] - f), b.created_all[i]};
}

/// The exact checks against the live mesh, in vertex order; each verdict
/// depends on its candidate only.
void check_against_mesh(const WorkMesh& m, const CheckLimits& lim, PassBuffers& b,
                        const std::function<void(double)>& after_slice) {
    const std::size_t n = b.accepted.size();
    b.verdict.resize(n);
    parallel_slices(
        n, 64,
        [&](std::size_t begin, std::size_t end) {
            std::vector<exact::plane_filter> planes;
            std::vector<std::uint32_t> near;
            for (std::size_t i = begin; i < end; ++i)
                b.verdict[i] = check_intersection_and_distance(m, b.faces_grid, b.accepted[i], created_faces(b, i),
                                                               lim, planes, near);
        },
        after_slice);
}

/// Drops accepted collapses whose created faces meet the created faces of a
/// cheaper accepted one (lower rank). The verdicts of the mesh check decide
/// who takes part, so a drop does not cascade.
void drop_conflicting(PassBuffers& b, const std::function<void(double)>& after_slice) {
    const std::size_t n = b.accepted.size();
    b.collapse_boxes.resize(n);
    for (std::size_t i = 0; i < n; ++i) b.collapse_boxes[i] = float_box(b.created_all[i]);
    b.created_grid.build(b.collapse_boxes);
    b.conflict.assign(n, 0);
    parallel_slices(n, 64, [&](std::size_t begin, std::size_t end) {
        std::vector<std::uint32_t> near;
        std::vector<exact::plane_filter> planes;
        for (std::size_t o = begin; o < end; ++o) {
            if (b.verdict[o] != Verdict::ok) continue;
            const CreatedFaces mine = created_faces(b, o);
            b.created_grid.query(mine.all[0], mine.all[1], near);
            planes.clear();
            for (std::uint32_t q : near) {
                if (b.rank[q] >= b.rank[o] || b.verdict[q] != Verdict::ok) continue;  // only cheaper ones that stand
                if (planes.empty())
                    for (std::size_t f = 0; f < mine.count; ++f) planes.emplace_back(mine.points[f].data());
                const CreatedFaces theirs = created_faces(b, q);
                for (std::size_t g = 0; g < theirs.count && !b.conflict[o]; ++g) {
                    if (!boxes_meet(theirs.boxes[g], mine.all)) continue;
                    for (std::size_t f = 0; f < mine.count; ++f)
                        if (boxes_meet(mine.boxes[f], theirs.boxes[g]) &&
                            !certainly_apart(planes[f], mine.tris[f], theirs.tris[g], theirs.points[g].data()) &&
                            faces_intersect(mine.tris[f], mine.points[f].data(), theirs.tris[g],
                                            theirs.points[g].data())) {
                            b.conflict[o] = 1;
                            break;
                        }
                }
                if (b.conflict[o]) break;
            }
        }
    }, after_slice);
    for (std::size_t o = 0; o < n; ++o)
        if (b.conflict[o]) b.verdict[o] = Verdict::intersection;
}

void apply_collapses(WorkMesh& m, const PassBuffers& b, bool spheres) {
    parallel_ranges(b.accepted.size(), 256, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
            if (b.verdict[i] != Verdict::ok) continue;
            const Candidate& c = b.accepted[i];
            if (spheres) {
                const vec e = m.pos[c.b] - m.pos[c.a];
                const double ee = dot(e, e);
                const double t = ee > 0 ? std::clamp(dot(c.x - m.pos[c.a], e) / ee, 0.0, 1.0) : 0.5;
                m.spheres[c.a] = m.spheres[c.a].lerp(m.spheres[c.b], t);
            }
            m.pos[c.a] = c.x;
            m.quadrics[c.a] += m.quadrics[c.b];
            if (!m.merged_into.empty()) m.merged_into[c.b] = c.a;
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
        }
    });
    m.tris.erase(std::remove_if(m.tris.begin(), m.tris.end(), [](const Tri& t) { return t[0] == kDead; }),
                 m.tris.end());
}

}  // namespace

void build_fans(const std::vector<Tri>& tris, std::size_t vertices, std::vector<std::uint32_t>& begin,
                std::vector<std::uint32_t>& fan) {
    detail::reserve_large(begin, vertices + 1);
    begin.assign(vertices + 1, 0);
    for (const Tri& t : tris)
        for (std::uint32_t v : t) ++begin[v + 1];
    std::partial_sum(begin.begin(), begin.end(), begin.begin());
    detail::reserve_large(fan, tris.size() * 3);
    fan.resize(tris.size() * 3);
    std::vector<std::uint32_t> fill(begin.begin(), begin.end() - 1);
    for (std::size_t i = 0; i < tris.size(); ++i)
        for (std::uint32_t v : tris[i]) fan[fill[v]++] = std::uint32_t(i);
}

void rebuild_fans(WorkMesh& m) { build_fans(m.tris, m.pos.size(), m.fan_begin, m.fan); }

PassResult run_pass(WorkMesh& m, const DecimateOptions& o, const CheckLimits& lim, std::size_t target_faces,
                    bool unlimited, PassBuffers& b, const PassCheckpoint& checkpoint) {
    PassResult res;
    // Two serial loops over the faces that need nothing from each other.
    tbb::parallel_invoke([&] { rebuild_fans(m); }, [&] { collect_collapsible_edges(m, b.edges); });
    if (b.edges.empty() || m.tris.size() <= target_faces) return res;
    checkpoint(share::edges, 0);

    // The faces grid of the mesh check depends only on the pass's starting
    // mesh: it is built alongside the costing, the sort and the selection's
    // serial walk, which leave the other threads idle.
    tbb::task_group grid_task;
    grid_task.run([&] {
        b.boxes = b.faces_grid.take_boxes();  // the previous pass's buffer: large enough, its pages mapped
        triangle_boxes(m.pos, m.tris, b.boxes);
        b.faces_grid.build(b.boxes);
    });

    // Cost every edge, order by (cost, edge).
    const std::size_t n = b.edges.size();
    detail::reserve_large(b.order, n);  // given back each pass (run_pass's end): its pages are new ones
    b.order.resize(n);
    auto cost = [&](std::size_t edge) { return evaluate_collapse(m, b.edges[edge][0], b.edges[edge][1], o.metric).cost; };
    parallel_ranges(n, 1024, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) b.order[i] = cost_key(cost(i), std::uint32_t(i));
    });
    checkpoint(share::costed, 0);
    sort_by_high_word(b.order, b.order_tmp);
    checkpoint(share::sorted, 0);

    // Look only at the candidates up to 1.5x the goal-th cost (a prefix).
    const std::size_t goal = (m.tris.size() - target_faces + 1) / 2;
    std::size_t prefix = n;
    if (goal < n && !unlimited) {
        const std::uint64_t limit = cost_key(1.5 * cost(std::uint32_t(b.order[goal])), 0) | 0xffffffffu;
        prefix = std::size_t(std::upper_bound(b.order.begin(), b.order.end(), limit) - b.order.begin());
    }

    select_independent(m, lim, o.metric, b, prefix, goal, res, checkpoint);
    const std::size_t planned = b.accepted.size();
    checkpoint(share::selected, planned);
    grid_task.wait();
    if (b.accepted.empty()) return res;
    checkpoint(share::grid, planned);
    order_by_vertex(b);
    // The sort's buffers (16 bytes an edge) are done with until the next
    // pass; given back, they leave room for the created faces' checks, the
    // pass's peak.
    std::vector<std::uint64_t>().swap(b.order);
    std::vector<std::uint64_t>().swap(b.order_tmp);
    write_all_created_faces(m, b);
    checkpoint(share::created, planned);
    check_against_mesh(m, lim, b, [&](double f) {
        checkpoint(share::created + (share::mesh_checked - share::created) * f, planned);
    });
    drop_conflicting(b, [&](double f) {
        checkpoint(share::mesh_checked + (share::conflicts - share::mesh_checked) * f, planned);
    });
    for (Verdict v : b.verdict) {
        if (v == Verdict::ok) ++res.collapses;
        else ++res.rejected[int(v)];
    }
    apply_collapses(m, b, o.metric == DecimateMetric::curvature);
    return res;
}

}  // namespace pqdc::decimate_detail
