#include "uniform/quad_star_check.hpp"

#include "geometry/exact_predicates.hpp"
#include "lattice/resources.hpp"
#include "measure/default_init.hpp"
#include "measure/mesh_internal.hpp"
#include "pqdc/exceptions.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <limits>

namespace pqdc::detail {
namespace {

using Vec3d = openvdb::Vec3d;
using Quad = std::array<unsigned, 4>;
using Pair = std::pair<std::size_t, std::size_t>;

/// Slack on the max-norm bound, in voxels: the index-space positions are
/// computed in double, with errors below 1e-9 voxel up to 2^20 voxels.
constexpr double kMargin = 1e-6;

/// Larger stars (no surface vertex has them) get the pairwise tests.
constexpr std::size_t kMaxStarQuads = 12;

/// Vertices per parallel block; fixed, so the work per block is the same
/// for any thread count.
constexpr std::size_t kBlock = 4096;

/// Quad k's corners in cyclic order, from split triangles 2k and 2k+1: two
/// triangles with distinct corners sharing one diagonal, run the opposite
/// ways (one consistently oriented quad). False otherwise.
bool quad_of(const Mesh& mesh, std::size_t k, Quad& q) {
    const std::array<unsigned, 3> a = split_triangle(mesh, 2 * k), b = split_triangle(mesh, 2 * k + 1);
    // The two splits split_quads() and the 0-1-2 / 0-2-3 quad split write,
    // answered as the general rule below answers them (it is read about six
    // times per quad in a check).
    auto distinct = [](unsigned w, unsigned x, unsigned y, unsigned z) {
        return w != x && w != y && w != z && x != y && x != z && y != z;
    };
    if (a[0] == b[0] && a[2] == b[1] && distinct(a[0], a[1], a[2], b[2])) {
        q = {a[1], a[2], b[2], a[0]};
        return true;
    }
    if (a[1] == b[0] && a[2] == b[2] && distinct(a[0], a[1], a[2], b[1])) {
        q = {a[0], a[1], b[1], a[2]};
        return true;
    }
    if (a[0] == a[1] || a[1] == a[2] || a[2] == a[0] || b[0] == b[1] || b[1] == b[2] || b[2] == b[0]) return false;
    auto only = [](const std::array<unsigned, 3>& s, const std::array<unsigned, 3>& t) {
        int found = -1, count = 0;
        for (int i = 0; i < 3; ++i)
            if (s[i] != t[0] && s[i] != t[1] && s[i] != t[2]) {
                found = i;
                ++count;
            }
        return count == 1 ? found : -1;
    };
    const int ya = only(a, b), xb = only(b, a);
    if (ya < 0 || xb < 0) return false;
    const unsigned s1 = a[(ya + 1) % 3], s2 = a[(ya + 2) % 3];
    if (b[(xb + 1) % 3] != s2 || b[(xb + 2) % 3] != s1) return false;
    q = {a[ya], s1, b[xb], s2};
    return true;
}

/// The quads around each vertex (vertex -> first, count into one array),
/// ascending.
struct QuadIncidence {
    const Mesh* mesh = nullptr;
    std::size_t quads = 0;
    std::vector<std::uint32_t> begin;  ///< points + 1 offsets
    UninitializedVector<std::uint32_t> quad;  ///< filled in full by build_incidence

    /// Quad k's corners in cyclic order (quad_of, which build_incidence()
    /// found true for every quad): worked out where read rather than held,
    /// 16 bytes a quad less at the run's peak.
    Quad cycle(std::size_t k) const {
        Quad q;
        quad_of(*mesh, k, q);
        return q;
    }
};

/// False when a quad is not one (see quad_of) or the mesh is too large for
/// 32-bit offsets.
bool build_incidence(const Mesh& mesh, std::size_t quads, QuadIncidence& inc) {
    if (4 * quads >= std::numeric_limits<std::uint32_t>::max()) return false;
    inc.mesh = &mesh;
    inc.quads = quads;
    // Each quad's four corners, in any order: the first triangle's three and
    // the second's corner off the diagonal (cheaper than the cycle).
    auto corners = [&](std::size_t k, const auto& visit) {
        const std::array<unsigned, 3> a = split_triangle(mesh, 2 * k), b = split_triangle(mesh, 2 * k + 1);
        for (unsigned v : a) visit(v);
        for (unsigned v : b)
            if (v != a[0] && v != a[1] && v != a[2]) visit(v);
    };
    // Counted (checking that every quad is one) and filled by quads in
    // parallel, with relaxed atomic increments: a vertex's count and its
    // slots do not depend on the order. Then each vertex's list is sorted,
    // so the lists are the same for any thread count. Serial, these passes
    // were a quarter of the check of a clean sphere on two threads.
    const std::size_t nv = mesh.points.size();
    reserve_large(inc.begin, nv + 1);
    inc.begin.assign(nv + 1, 0);
    std::uint32_t* begin = inc.begin.data();
    auto for_quads = [&](const auto& f) {
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, quads, 1 << 14), [&](const auto& r) {
            for (std::size_t k = r.begin(); k != r.end(); ++k) f(k);
        });
    };
    std::atomic<bool> all_quads{true};
    for_quads([&](std::size_t k) {
        Quad q;
        if (!quad_of(mesh, k, q)) {
            all_quads.store(false, std::memory_order_relaxed);
            return;
        }
        for (unsigned v : q) __atomic_fetch_add(&begin[v + 1], 1u, __ATOMIC_RELAXED);
    });
    if (!all_quads) return false;
    for (std::size_t v = 0; v < nv; ++v) begin[v + 1] += begin[v];
    reserve_large(inc.quad, begin[nv]);
    inc.quad.resize(begin[nv]);
    // begin[v] serves as v's fill position, ending at begin[v + 1]; shifted back after.
    for_quads([&](std::size_t k) {
        corners(k, [&](unsigned v) { inc.quad[__atomic_fetch_add(&begin[v], 1u, __ATOMIC_RELAXED)] = std::uint32_t(k); });
    });
    std::copy_backward(begin, begin + nv, begin + nv + 1);
    begin[0] = 0;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 1 << 14), [&](const auto& r) {
        for (std::size_t v = r.begin(); v != r.end(); ++v) {
            // A handful of quads per vertex: insertion sort.
            std::uint32_t* list = inc.quad.data() + begin[v];
            const std::size_t n = begin[v + 1] - begin[v];
            for (std::size_t i = 1; i < n; ++i)
                for (std::size_t j = i; j > 0 && list[j - 1] > list[j]; --j) std::swap(list[j - 1], list[j]);
        }
    });
    return true;
}

/// Max-norm distance of a checked point from its cell's center, in index
/// space; infinite for a non-finite point.
double center_offset(const openvdb::math::Transform& xf, const Vec3d& point, const Vec3d& center) {
    const Vec3d p = xf.worldToIndex(point);
    double d = 0.0;
    for (int k = 0; k < 3; ++k) {
        const double e = std::abs(p[k] - center[k]);
        if (!std::isfinite(e)) return std::numeric_limits<double>::infinity();
        d = std::max(d, e);
    }
    return d;
}

/// The quad star of a lone vertex v, as the certificate reads it.
struct Star {
    std::array<unsigned, 2 * kMaxStarQuads> boundary;  ///< a_1 b_1 a_2 b_2 ...
    std::size_t size = 0;                              ///< boundary corners (2 per quad)
    std::array<std::uint32_t, kMaxStarQuads> quad;     ///< the quad of a_i b_i (quad_of's number)
};

/// Chains the quads (v, a, b, c) around v into one closed fan, c of each the
/// a of the next: false when they are not one disc around v.
bool chain_fan(const QuadIncidence& inc, unsigned v, const std::uint32_t* quads, std::size_t n, Star& star) {
    if (n < 3 || n > kMaxStarQuads) return false;
    std::array<std::array<unsigned, 4>, kMaxStarQuads> fan;  // (a, b, c) after v, and the quad
    for (std::size_t i = 0; i < n; ++i) {
        const Quad q = inc.cycle(quads[i]);
        int at = 0;
        while (q[at] != v) ++at;
        fan[i] = {q[(at + 1) % 4], q[(at + 2) % 4], q[(at + 3) % 4], quads[i]};
    }
    for (std::size_t i = 0; i + 1 < n; ++i) {
        std::size_t next = n;
        for (std::size_t j = i + 1; j < n; ++j)
            if (fan[j][0] == fan[i][2]) {
                if (next != n) return false;
                next = j;
            }
        if (next == n) return false;
        std::swap(fan[i + 1], fan[next]);
    }
    if (fan[n - 1][2] != fan[0][0]) return false;
    star.size = 2 * n;
    for (std::size_t i = 0; i < n; ++i) {
        star.boundary[2 * i] = fan[i][0];
        star.boundary[2 * i + 1] = fan[i][1];
        star.quad[i] = fan[i][3];
    }
    for (std::size_t i = 0; i < star.size; ++i) {  // a disc: no corner twice, v not on its boundary
        if (star.boundary[i] == v) return false;
        for (std::size_t j = i + 1; j < star.size; ++j)
            if (star.boundary[i] == star.boundary[j]) return false;
    }
    return true;
}

/// The certificate's signs in the projection that drops axis `drop`.
bool star_shaped_in(const Mesh& mesh, const std::vector<Vec3d>& P, unsigned v, const Star& star, int drop) {
    const int i = (drop + 1) % 3, j = (drop + 2) % 3;
    const Vec3d& c = P[v];
    auto corner = [&](std::size_t k) -> const Vec3d& { return P[star.boundary[k]]; };
    // Every corner of the star's triangles is v or on its boundary: one box for all signs.
    const BoxOrient2d orient = orient_in_box_of(i, j, c, star.size, corner);
    const int o = turns_once_around(orient, c, star.size, corner);
    if (o == 0) return false;
    for (std::size_t k = 0; k < star.size / 2; ++k) {
        const unsigned b = star.boundary[2 * k + 1];
        for (std::size_t t = 2 * std::size_t(star.quad[k]); t < 2 * std::size_t(star.quad[k]) + 2; ++t) {
            const std::array<unsigned, 3> tri = split_triangle(mesh, t);
            auto has = [&](unsigned x) { return tri[0] == x || tri[1] == x || tri[2] == x; };
            // (v, a, b) and (v, b, c) are boundary sectors, tested above.
            if (has(v) && has(b)) continue;
            if (orient(P[tri[0]], P[tri[1]], P[tri[2]]) != o) return false;
        }
    }
    return true;
}

/// The certificate of the header for the quad star of lone vertex v, in
/// each of the three coordinate projections until one proves it (a crease
/// along a coordinate axis can be seen edge-on in one). `first` is tried
/// first and becomes the one that worked: neighbouring stars face alike, so
/// the caller passes the previous star's. Whether a star is certified does
/// not depend on the order, only the time does.
bool certified(const Mesh& mesh, const std::vector<Vec3d>& P, const QuadIncidence& inc, unsigned v, int& first) {
    const std::uint32_t* quads = &inc.quad[inc.begin[v]];
    const std::size_t n = inc.begin[v + 1] - inc.begin[v];
    Star star;
    if (!chain_fan(inc, v, quads, n, star)) return false;
    for (int k = 0; k < 3; ++k)
        if (star_shaped_in(mesh, P, v, star, (first + k) % 3)) {
            first = (first + k) % 3;
            return true;
        }
    return false;
}

/// Every intersecting pair among the triangles of the quads around the
/// vertices [first, first + count) (one cell), appended to `pairs`.
void test_star_pairs(const Mesh& mesh, const std::vector<Vec3d>& P, const QuadIncidence& inc,
                     const std::vector<char>& skip, std::size_t first, std::size_t count,
                     std::vector<std::uint32_t>& triangles, std::vector<Pair>& pairs) {
    triangles.clear();
    for (std::size_t v = first; v < first + count; ++v)
        for (std::uint32_t e = inc.begin[v]; e < inc.begin[v + 1]; ++e) {
            triangles.push_back(2 * inc.quad[e]);
            triangles.push_back(2 * inc.quad[e] + 1);
        }
    std::sort(triangles.begin(), triangles.end());
    triangles.erase(std::unique(triangles.begin(), triangles.end()), triangles.end());
    triangles.erase(std::remove_if(triangles.begin(), triangles.end(), [&](std::uint32_t t) { return skip[t]; }),
                    triangles.end());
    intersecting_pairs_among(mesh, P, triangles, pairs);
}

/// The intersecting pairs among the usable triangles with a loose corner,
/// by the general finder on them alone; returns how many there are.
std::size_t test_loose_pairs(const Mesh& mesh, const std::vector<Vec3d>& P, const std::vector<char>& skip,
                             const std::vector<std::uint8_t>& loose, std::vector<std::uint32_t>& remap,
                             std::vector<Pair>& pairs) {
    std::vector<std::uint32_t> ids;
    for (std::size_t t = 0; t < skip.size(); ++t) {
        if (skip[t]) continue;
        const std::array<unsigned, 3> c = split_triangle(mesh, t);
        if (loose[c[0]] || loose[c[1]] || loose[c[2]]) ids.push_back(std::uint32_t(t));
    }
    if (ids.size() < 2) return ids.size();
    if (remap.empty()) remap.assign(mesh.points.size(), std::numeric_limits<std::uint32_t>::max());  // first need
    const Mesh sub = split_triangles_mesh(mesh, ids, [&](unsigned v) { return P[v]; }, remap);
    // Ascending ids: the sub-mesh's pair order is the mesh's.
    for (const auto& pr : find_self_intersections(sub).pairs) pairs.emplace_back(ids[pr.first], ids[pr.second]);
    return ids.size();
}

void report(const SelfIntersectionOptions& options, double fraction) { report_progress(options, fraction); }

}  // namespace

/// What whole() learned that near() reuses.
struct QuadStarCheck::State {
    QuadIncidence inc;
    std::vector<char> skip;            ///< per triangle: classify_split_triangle
    std::vector<std::uint8_t> loose;   ///< per vertex
    std::vector<std::uint32_t> remap;  ///< split_triangles_mesh's, kept from round to round; made at first need
    double largest = 0.0;              ///< the largest offset from a cell center (an upper bound after moves)
    double loose_from = 0.0;           ///< offsets from here on are loose
};

QuadStarCheck::QuadStarCheck(const Mesh& mesh, const LatticeVertices& lattice) : mesh_(mesh), lattice_(lattice) {}

namespace {

/// What certify_stars() found: per fixed block of cells, the first
/// vertices of the cells whose pairs are left to test; every other cell it
/// looked at is a lone vertex with a certified star.
struct StarPlan {
    std::vector<std::vector<std::uint32_t>> to_test;  ///< per block
    std::uint64_t certified_cells = 0;
};

/// Runs f(block) for blocks [0, blocks) in parallel, in batches with a
/// report between them from this thread (the cancellation points), the
/// fractions from `from` to `to`.
template <class F>
void in_batches(std::size_t blocks, const SelfIntersectionOptions* options, double from, double to, const F& f) {
    constexpr std::size_t kBatches = 16;
    const std::size_t step = std::max<std::size_t>(1, (blocks + kBatches - 1) / kBatches);
    for (std::size_t first = 0; first < blocks; first += step) {
        tbb::parallel_for(first, std::min(blocks, first + step), f);
        if (options) report(*options, from + (to - from) * double(std::min(blocks, first + step)) / double(blocks));
    }
}

/// The certificate for the stars of the cells listed by their first vertex
/// (all cells when `cells` is null), in fixed blocks so that the plan does
/// not depend on the threads.
StarPlan certify_stars(const Mesh& mesh, const std::vector<Vec3d>& points, const std::vector<std::uint8_t>& patches,
                       const QuadIncidence& inc, const std::vector<std::uint32_t>* cells,
                       const SelfIntersectionOptions* options) {
    const std::size_t n = cells ? cells->size() : mesh.points.size();
    StarPlan plan;
    plan.to_test.resize((n + kBlock - 1) / kBlock);
    std::vector<std::uint32_t> certified_in(plan.to_test.size(), 0);
    in_batches(plan.to_test.size(), options, 0.2, 0.75, [&](std::size_t b) {
        int projection = 0;
        for (std::size_t i = b * kBlock; i < std::min(n, (b + 1) * kBlock); ++i) {
            const std::size_t v = cells ? (*cells)[i] : i;
            if ((patches[v] & 15) != 0) continue;  // a cell is handled at its first vertex
            if ((patches[v] >> 4) <= 1 && certified(mesh, points, inc, unsigned(v), projection)) ++certified_in[b];
            else plan.to_test[b].push_back(std::uint32_t(v));
        }
    });
    for (std::uint32_t c : certified_in) plan.certified_cells += c;
    return plan;
}

/// The pairs of the stars the plan left to test, appended to `all` in block
/// order (the same for any thread count).
void test_stars(const Mesh& mesh, const std::vector<Vec3d>& points, const std::vector<std::uint8_t>& patches,
                const QuadIncidence& inc, const std::vector<char>& skip, const StarPlan& plan,
                const SelfIntersectionOptions* options, std::vector<Pair>& all, QuadStarCounts& tally) {
    const std::size_t nv = mesh.points.size();
    std::vector<std::vector<Pair>> found(plan.to_test.size());
    in_batches(plan.to_test.size(), options, 0.75, 0.9, [&](std::size_t b) {
        std::vector<std::uint32_t> triangles;
        for (std::uint32_t v : plan.to_test[b]) {
            const std::size_t in_cell = std::max(1, patches[v] >> 4);
            test_star_pairs(mesh, points, inc, skip, v, std::min(in_cell, nv - v), triangles, found[b]);
        }
    });
    for (std::size_t b = 0; b < found.size(); ++b) {
        all.insert(all.end(), found[b].begin(), found[b].end());
        tally.tested_cells += plan.to_test[b].size();
    }
    tally.certified_cells += plan.certified_cells;
}

/// Per vertex, whether the plan of every cell (certify_stars(..., nullptr))
/// certified its star: the lone first vertices it did not leave to test.
std::vector<std::uint8_t> certified_vertices(const std::vector<std::uint8_t>& patches, const StarPlan& plan) {
    std::vector<std::uint8_t> certified(patches.size());
    for (std::size_t v = 0; v < patches.size(); ++v) certified[v] = (patches[v] & 15) == 0 && (patches[v] >> 4) <= 1;
    for (const auto& block : plan.to_test)
        for (std::uint32_t v : block) certified[v] = 0;
    return certified;
}

/// classify_split_triangle() of every triangle, into `skip`, except those
/// of a quad with a certified corner: the certificate found every triangle
/// of that corner's star with a non-zero area in a projection, so they are
/// neither degenerate nor (the points being finite here) non-finite.
void classify_uncertified(const Mesh& mesh, const std::vector<Vec3d>& points, const QuadIncidence& inc,
                          const std::vector<std::uint8_t>& certified, std::vector<char>& skip) {
    reserve_large(skip, 2 * inc.quads);
    skip.assign(2 * inc.quads, 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, inc.quads, 1 << 13), [&](const auto& r) {
        for (std::size_t q = r.begin(); q != r.end(); ++q) {
            const Quad c = inc.cycle(q);
            if (certified[c[0]] || certified[c[1]] || certified[c[2]] || certified[c[3]]) continue;
            skip[2 * q] = char(classify_split_triangle(mesh, points, 2 * q));
            skip[2 * q + 1] = char(classify_split_triangle(mesh, points, 2 * q + 1));
        }
    });
}

/// Sorted and unique, at most `max_pairs` kept, into `result`.
void finish_pairs(std::vector<Pair>& all, std::size_t max_pairs, SelfIntersections& result) {
    tbb::parallel_sort(all.begin(), all.end());
    all.erase(std::unique(all.begin(), all.end()), all.end());
    result.pair_count = all.size();
    if (all.size() > max_pairs) all.resize(max_pairs);
    result.pairs = std::move(all);
}

}  // namespace

SelfIntersections QuadStarCheck::whole(const std::vector<Vec3d>& points, const SelfIntersectionOptions& options,
                                       QuadStarCounts* counts) {
    const Mesh& mesh = mesh_;
    const std::size_t count = split_triangle_count(mesh), nv = mesh.points.size();
    QuadStarCounts tally;
    state_.reset();
    auto general = [&] {
        tally.general = true;
        if (counts) *counts = tally;
        return find_self_intersections_at(mesh, points, options);
    };
    const LatticeVertices& lattice = lattice_;
    if (!(lattice.safe || lattice.cells) || !lattice.patches || !lattice.xf || lattice.size() != nv ||
        lattice.patches->size() != nv || points.size() != nv || count % 2 != 0 || count == 0)
        return general();
    check_indices(mesh);
    report(options, 0.0);

    // The farthest vertex from its cell's center sets which vertices are loose.
    auto state = std::make_shared<State>();
    const openvdb::math::Transform& xf = *lattice.xf->transform;
    std::vector<double> offset;
    reserve_large(offset, nv);
    offset.resize(nv);
    state->largest = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, nv, 1 << 14), 0.0,
        [&](const auto& r, double m) {
            for (std::size_t v = r.begin(); v != r.end(); ++v) {
                offset[v] = center_offset(xf, points[v], lattice.cell_center(v));
                m = std::max(m, offset[v]);
            }
            return m;
        },
        [](double a, double b) { return std::max(a, b); });
    state->loose_from = 1.0 - state->largest - kMargin;
    // Non-finite points, or vertices far outside their cells: the argument does not apply.
    if (!(state->loose_from > kMargin)) return general();
    reserve_large(state->loose, nv);
    state->loose.resize(nv);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 1 << 14), [&](const auto& r) {
        for (std::size_t v = r.begin(); v != r.end(); ++v) state->loose[v] = offset[v] >= state->loose_from;
    });
    std::vector<double>().swap(offset);  // before the incidence lists: not part of the check's peak
    if (!build_incidence(mesh, count / 2, state->inc)) return general();
    report(options, 0.1);

    SelfIntersections result;
    result.triangle_count = count;
    result.broad_phase = BroadPhase::grid;
    std::vector<Pair> all;
    const StarPlan plan = certify_stars(mesh, points, *lattice.patches, state->inc, nullptr, &options);
    std::vector<char>& skip = state->skip;
    classify_uncertified(mesh, points, state->inc, certified_vertices(*lattice.patches, plan), skip);
    for (std::size_t t = 0; t < count; ++t) {
        if (skip[t] == 1) result.degenerate_triangles.push_back(t);
        if (skip[t] == 2) ++result.non_finite_triangle_count;
    }
    test_stars(mesh, points, *lattice.patches, state->inc, skip, plan, &options, all, tally);
    tally.loose_triangles = test_loose_pairs(mesh, points, skip, state->loose, state->remap, all);
    if (counts) *counts = tally;
    finish_pairs(all, options.max_pairs, result);
    state_ = std::move(state);
    report(options, 1.0);
    return result;
}

bool QuadStarCheck::near(const std::vector<Vec3d>& points, const std::vector<std::uint32_t>& moved,
                         SelfIntersections& out) {
    if (!state_ || points.size() != mesh_.points.size()) return false;
    State& state = *state_;
    const Mesh& mesh = mesh_;
    const std::vector<std::uint8_t>& patches = *lattice_.patches;
    const openvdb::math::Transform& xf = *lattice_.xf->transform;
    // The moved vertices' offsets: still within the bound (a move runs
    // towards the safe position, inside the cell; rounding may break it).
    bool loose_moved = false;
    for (std::uint32_t v : moved) {
        const double d = center_offset(xf, points[v], lattice_.cell_center(v));
        if (!(d <= state.largest)) {
            state_.reset();
            return false;
        }
        state.loose[v] = d >= state.loose_from;
        loose_moved = loose_moved || state.loose[v];
    }
    // The moved triangles, classified again, and the cells of their quads' corners.
    std::vector<std::uint32_t> triangles, cells;
    for (std::uint32_t v : moved)
        for (std::uint32_t e = state.inc.begin[v]; e < state.inc.begin[v + 1]; ++e) {
            const std::uint32_t q = state.inc.quad[e];
            triangles.push_back(2 * q);
            triangles.push_back(2 * q + 1);
            for (unsigned u : state.inc.cycle(q)) cells.push_back(u - (patches[u] & 15));
        }
    std::sort(triangles.begin(), triangles.end());
    triangles.erase(std::unique(triangles.begin(), triangles.end()), triangles.end());
    std::sort(cells.begin(), cells.end());
    cells.erase(std::unique(cells.begin(), cells.end()), cells.end());
    out = SelfIntersections();
    out.triangle_count = state.skip.size();
    out.broad_phase = BroadPhase::grid;
    for (std::uint32_t t : triangles) {
        state.skip[t] = char(classify_split_triangle(mesh, points, t));
        if (state.skip[t] == 1) out.degenerate_triangles.push_back(t);
        if (state.skip[t] == 2) ++out.non_finite_triangle_count;
        const std::array<unsigned, 3> c = split_triangle(mesh, t);
        loose_moved = loose_moved || state.loose[c[0]] || state.loose[c[1]] || state.loose[c[2]];
    }
    std::vector<Pair> all;
    QuadStarCounts tally;
    test_stars(mesh, points, patches, state.inc, state.skip, certify_stars(mesh, points, patches, state.inc, &cells, nullptr),
               nullptr, all, tally);
    if (loose_moved) test_loose_pairs(mesh, points, state.skip, state.loose, state.remap, all);
    finish_pairs(all, std::numeric_limits<std::size_t>::max(), out);
    return true;
}

SelfIntersections find_self_intersections_by_quad_stars(const Mesh& mesh, const std::vector<Vec3d>& points,
                                                         const LatticeVertices& lattice,
                                                         const SelfIntersectionOptions& options,
                                                         QuadStarCounts* counts) {
    return QuadStarCheck(mesh, lattice).whole(points, options, counts);
}

}  // namespace pqdc::detail
