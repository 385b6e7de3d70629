#include "lattice/untangle.hpp"

#include "geometry/float_rounding.hpp"
#include "measure/mesh_internal.hpp"
#include "pqdc/exceptions.hpp"
#include "pqdc/self_intersections.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <limits>

namespace pqdc::detail {
namespace {

using Vec3d = openvdb::Vec3d;
using Tri = std::array<std::uint32_t, 3>;

/// The mesh as find_self_intersections numbers its triangles: triangles,
/// then each quad as (0, 1, 2) and (0, 2, 3).
std::vector<Tri> split_all(const Mesh& mesh) {
    std::vector<Tri> tris;
    tris.reserve(mesh.triangles.size() + 2 * mesh.quads.size());
    for (const auto& t : mesh.triangles) tris.push_back({t[0], t[1], t[2]});
    for (const auto& q : mesh.quads) {
        tris.push_back({q[0], q[1], q[2]});
        tris.push_back({q[0], q[2], q[3]});
    }
    return tris;
}

/// Hashed grid cells of bounding boxes. A box spanning more than kMaxSpan
/// cells per axis (or beyond the integer range) is "big": it counts as
/// touching every cell.
class CellHash {
public:
    explicit CellHash(double cell) : inv_(1.0 / cell), bits_(kWords, 0) {}

    template <class Visit>
    bool for_cells(const Vec3d& lo, const Vec3d& hi, Visit&& visit) const {
        std::int64_t a[3], b[3];
        for (int k = 0; k < 3; ++k) {
            const double l = std::floor(lo[k] * inv_), h = std::floor(hi[k] * inv_);
            if (!(l > -kRange && h < kRange) || h - l >= kMaxSpan) return false;
            a[k] = std::int64_t(l);
            b[k] = std::int64_t(h);
        }
        for (std::int64_t x = a[0]; x <= b[0]; ++x)
            for (std::int64_t y = a[1]; y <= b[1]; ++y)
                for (std::int64_t z = a[2]; z <= b[2]; ++z)
                    if (visit(slot(x, y, z))) return true;
        return true;
    }
    void set(std::size_t s) { bits_[s >> 6] |= std::uint64_t(1) << (s & 63); }
    bool test(std::size_t s) const { return (bits_[s >> 6] >> (s & 63)) & 1; }
    void clear() { std::fill(bits_.begin(), bits_.end(), 0); }

private:
    static constexpr std::size_t kSlots = std::size_t(1) << 22, kWords = kSlots / 64;
    static constexpr double kMaxSpan = 4, kRange = 1e15;
    static std::size_t slot(std::int64_t x, std::int64_t y, std::int64_t z) {
        const std::uint64_t h = std::uint64_t(x) * 0x9E3779B97F4A7C15ull ^ std::uint64_t(y) * 0xC2B2AE3D27D4EB4Full ^
                                std::uint64_t(z) * 0x165667B19E3779F9ull;
        return std::size_t((h ^ (h >> 29)) & (kSlots - 1));
    }
    double inv_;
    std::vector<std::uint64_t> bits_;
};

void bounds(const std::vector<Vec3d>& p, const Tri& t, Vec3d& lo, Vec3d& hi) {
    lo = hi = p[t[0]];
    for (int k = 1; k < 3; ++k) {
        lo = openvdb::math::minComponent(lo, p[t[k]]);
        hi = openvdb::math::maxComponent(hi, p[t[k]]);
    }
}

struct Found {
    std::vector<std::uint32_t> triangles;  ///< offending triangle ids, with repeats
    std::uint64_t pairs = 0, degenerate = 0, non_finite = 0;
};

using ProgressHook = std::function<bool(double)>;

Found to_found(const SelfIntersections& si, const std::vector<std::uint32_t>* subset);

/// Exact check of the triangles `subset` (all of them when null) among
/// themselves, at the points' own precision or, with `to_float`, at the
/// points rounded to float (only the subset's points are rounded).
Found check_at(const Mesh& mesh, const std::vector<std::uint32_t>* subset,
               std::vector<std::uint32_t>& remap, bool to_float, const ProgressHook& progress,
               const UntangleSettings& settings) {
    SelfIntersections si;
    SelfIntersectionOptions options;
    options.progress = progress;
    auto whole = [&](const std::vector<Vec3d>& points) {
        return settings.whole_mesh_check ? settings.whole_mesh_check(mesh, points, options)
                                         : find_self_intersections_at(mesh, points, options);
    };
    if (!subset && !to_float) {
        si = whole(mesh.points);
    } else if (!subset) {
        si = whole(points_as_stored(mesh.points, VertexPrecision::float32));
    } else {
        const Mesh sub = split_triangles_mesh(
            mesh, *subset, [&](unsigned v) { return to_float ? rounded_to_float(mesh.points[v]) : mesh.points[v]; },
            remap);
        si = find_self_intersections(sub, options);
    }
    return to_found(si, subset);
}

/// check_at's result from the finder's, numbered in the subset's triangles
/// (the mesh's when null).
Found to_found(const SelfIntersections& si, const std::vector<std::uint32_t>* subset) {
    Found f;
    auto id = [&](std::size_t t) { return subset ? (*subset)[t] : std::uint32_t(t); };
    f.pairs = si.pair_count;
    f.degenerate = si.degenerate_triangles.size();
    f.non_finite = si.non_finite_triangle_count;
    for (const auto& pr : si.pairs) {
        f.triangles.push_back(id(pr.first));
        f.triangles.push_back(id(pr.second));
    }
    for (std::size_t t : si.degenerate_triangles) f.triangles.push_back(id(t));
    return f;
}

/// The triangles that may meet one touching a moved vertex; null (check
/// everything) when a moved triangle is too big for the hash.
bool candidates(const std::vector<Vec3d>& p, const std::vector<Tri>& tris, const std::vector<std::uint8_t>& moved,
                CellHash& hash, std::vector<std::uint32_t>& out) {
    hash.clear();
    out.clear();
    for (std::size_t t = 0; t < tris.size(); ++t) {
        const Tri& tri = tris[t];
        if (!moved[tri[0]] && !moved[tri[1]] && !moved[tri[2]]) continue;
        Vec3d lo, hi;
        bounds(p, tri, lo, hi);
        if (!hash.for_cells(lo, hi, [&](std::size_t s) {
                hash.set(s);
                return false;
            }))
            return false;
    }
    const std::size_t n = tris.size(), block = 16384, blocks = (n + block - 1) / block;
    std::vector<std::vector<std::uint32_t>> found(blocks);
    tbb::parallel_for(std::size_t(0), blocks, [&](std::size_t b) {
        for (std::size_t t = b * block; t < std::min(n, (b + 1) * block); ++t) {
            Vec3d lo, hi;
            bounds(p, tris[t], lo, hi);
            bool hit = false;
            if (!hash.for_cells(lo, hi, [&](std::size_t s) { return hit = hash.test(s); })) hit = true;
            if (hit) found[b].push_back(std::uint32_t(t));
        }
    });
    for (const auto& f : found) out.insert(out.end(), f.begin(), f.end());
    return true;
}

/// check_at() of the points as they will be stored: rounded to float when
/// the caller stores float32 (the double-precision points are then not
/// checked: only what is stored is promised, at the cost of one check).
Found check(const Mesh& mesh, const std::vector<std::uint32_t>* subset,
            std::vector<std::uint32_t>& remap, const UntangleSettings& settings, double from) {
    ProgressHook part;
    if (settings.progress) part = [&settings, from](double f) { return settings.progress(from + (1.0 - from) * f); };
    return check_at(mesh, subset, remap, settings.stored == VertexPrecision::float32, part, settings);
}

Vec3d as_stored(const Vec3d& p, const UntangleSettings& settings) {
    return settings.stored == VertexPrecision::float32 ? rounded_to_float(p) : p;
}

bool finite(const Vec3d& v) { return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]); }

}  // namespace

std::vector<Vec3d> points_as_stored(const std::vector<Vec3d>& points, VertexPrecision stored) {
    std::vector<Vec3d> out(points.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, out.size(), 1 << 14), [&](const auto& r) {
        for (std::size_t v = r.begin(); v != r.end(); ++v)
            out[v] = stored == VertexPrecision::float32 ? rounded_to_float(points[v]) : points[v];
    });
    return out;
}

bool untangle(Mesh& mesh, const std::vector<Vec3d>& safe, double cell_size, const UntangleSettings& settings,
              UntangleCounters& counters) {
    return untangle(mesh, SafePosition([&safe](std::uint32_t v) { return safe[v]; }), cell_size, settings, counters);
}

bool untangle(Mesh& mesh, const SafePosition& safe, double cell_size, const UntangleSettings& settings,
              UntangleCounters& counters) {
    std::vector<Tri> tris;  // split when a round first needs untangle's own check
    const std::size_t nv = mesh.points.size();
    std::vector<std::uint8_t> step(nv, 0), moved(nv, 0);
    std::unordered_map<std::uint32_t, Vec3d> original;  // of the vertices moved so far
    std::vector<std::uint32_t> remap, subset, to_move;
    std::vector<Vec3d> stored;  // the points as stored, for settings.moved_check

    // Non-finite corners (none from the drivers today) go straight to safety:
    // the segment from them has no usable points.
    for (std::size_t v = 0; v < nv; ++v)
        if (!finite(mesh.points[v])) step[v] = kPartialSteps;
    Found found = check(mesh, nullptr, remap, settings, 0.0);
    counters.pairs_before = found.pairs;
    counters.degenerate_before = found.degenerate;
    for (std::size_t v = 0; v < nv; ++v)
        if (step[v] == kPartialSteps) to_move.push_back(std::uint32_t(v));
    counters.degenerate_before += found.non_finite;
    if (found.triangles.empty() && to_move.empty()) return true;
    CellHash hash(cell_size);
    while (!found.triangles.empty() || !to_move.empty()) {
        for (std::uint32_t t : found.triangles)
            for (std::uint32_t v : split_triangle(mesh, t))  // split_all's numbering
                if (step[v] <= kPartialSteps) to_move.push_back(v);
        std::sort(to_move.begin(), to_move.end());
        to_move.erase(std::unique(to_move.begin(), to_move.end()), to_move.end());
        if (to_move.empty()) {
            counters.unresolved = found.pairs + found.degenerate;
            return false;
        }
        ++counters.rounds;
        for (std::uint32_t v : to_move) {
            if (step[v] == 0) ++counters.moved_vertices;
            const Vec3d from = original.try_emplace(v, mesh.points[v]).first->second;
            const int s = ++step[v];
            moved[v] = 1;
            const Vec3d to = safe(v);
            if (s > kPartialSteps) {
                mesh.points[v] = to;
                ++counters.snapped_vertices;
            } else {
                const double keep = std::ldexp(1.0, -s);  // 1/2, 1/4
                mesh.points[v] = to + (from - to) * keep;
            }
        }
        if (settings.moved_check) {
            // Float output is checked at the rounded points, kept up to date
            // here; double output at the points themselves (no copy).
            const bool rounded = settings.stored == VertexPrecision::float32;
            if (rounded && stored.empty()) stored = points_as_stored(mesh.points, settings.stored);
            else if (rounded)
                for (std::uint32_t v : to_move) stored[v] = as_stored(mesh.points[v], settings);
            SelfIntersections near;
            if (settings.moved_check(rounded ? stored : mesh.points, to_move, near)) {
                for (std::uint32_t v : to_move) moved[v] = 0;
                to_move.clear();
                if (settings.progress && !settings.progress(1.0))  // the cancellation point of a round
                    throw cancelled_error("self-intersection search cancelled by the caller");
                found = to_found(near, nullptr);
                continue;
            }
        }
        if (tris.empty()) {  // untangle's own check needs the triangles' corners at hand
            tris = split_all(mesh);
            remap.assign(nv, std::numeric_limits<std::uint32_t>::max());
        }
        const bool local = candidates(mesh.points, tris, moved, hash, subset);
        for (std::uint32_t v : to_move) moved[v] = 0;
        to_move.clear();
        found = check(mesh, local ? &subset : nullptr, remap, settings, 1.0);  // cancellation points only
    }
    return true;
}

void warn_unresolved(const UntangleCounters& c, VertexPrecision stored, ExtractStats& stats) {
    if (c.unresolved == 0) return;
    const std::string left = std::to_string(c.unresolved) +
                             " intersecting triangle pairs or degenerate triangles are left in the mesh as stored";
    if (stored == VertexPrecision::float32)
        stats.warnings.push_back(left + ", in float: its coordinates are too large for float's spacing against the "
                                        "voxel size (float output stays intersection-free up to 2^20 voxels from "
                                        "the origin); store it in double precision (--precision double)");
    else
        stats.warnings.push_back(left + " after the untangle stage; please report this with the input and options");
}

bool untangle_mesh(Mesh& mesh, const SafePosition& safe, const LatticeTransform& xf,
                   const UntangleSettings& settings, ExtractStats& stats) {
    UntangleCounters c;
    const bool ok = untangle(mesh, safe, xf.transform->voxelSize()[0], settings, c);
    c.add_to(stats);
    warn_unresolved(c, settings.stored, stats);
    return ok;
}

OffendingCorners find_offending_corners(const Mesh& mesh, const UntangleSettings& settings) {
    std::vector<std::uint32_t> remap;  // only for subsets
    const Found found = check(mesh, nullptr, remap, settings, 0.0);
    OffendingCorners out;
    out.pairs = found.pairs;
    out.degenerate = found.degenerate + found.non_finite;
    for (std::uint32_t t : found.triangles) {
        const std::array<unsigned, 3> corners = split_triangle(mesh, t);
        out.vertices.insert(out.vertices.end(), corners.begin(), corners.end());
    }
    std::sort(out.vertices.begin(), out.vertices.end());
    out.vertices.erase(std::unique(out.vertices.begin(), out.vertices.end()), out.vertices.end());
    return out;
}

std::uint64_t count_unsafe(const Mesh& mesh, const std::vector<Vec3d>& safe) {
    Mesh m;
    m.points = safe;
    m.triangles = mesh.triangles;
    m.quads = mesh.quads;
    const SelfIntersections si = find_self_intersections(m);
    return si.pair_count + si.degenerate_triangles.size() + si.non_finite_triangle_count;
}

}  // namespace pqdc::detail
