#include "measure/flat_stars.hpp"

#include "geometry/exact_predicates.hpp"
#include "measure/default_init.hpp"
#include "measure/mesh_internal.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

namespace pqdc::detail {
namespace {

using Vec3d = openvdb::Vec3d;

/// Stars larger than this are left to the pairwise test (no real surface
/// vertex has them; the bound keeps the quadratic fan walk cheap).
constexpr std::size_t kMaxStar = 32;

/// The triangles around each vertex, as (vertex -> first, count) into one
/// array, in ascending triangle order (the order does not change the
/// answer, but keeps the work the same for any thread count).
struct Incidence {
    std::vector<std::uint32_t> begin;  ///< points + 1 offsets
    UninitializedVector<std::uint32_t> triangle;
};

Incidence build_incidence(const Mesh& mesh) {
    Incidence inc;
    const std::size_t triangle_count = split_triangle_count(mesh);
    std::vector<std::uint32_t> count(mesh.points.size() + 1, 0);
    for (std::size_t t = 0; t < triangle_count; ++t)
        for (unsigned v : split_triangle(mesh, t)) ++count[v + 1];
    for (std::size_t v = 0; v < mesh.points.size(); ++v) count[v + 1] += count[v];
    inc.begin = count;
    inc.triangle.resize(count.back());
    for (std::size_t t = 0; t < triangle_count; ++t)
        for (unsigned v : split_triangle(mesh, t)) inc.triangle[count[v]++] = std::uint32_t(t);
    return inc;
}

struct Sector {
    unsigned a, b;  ///< the corners after v, in the triangle's order
};

/// The star's sectors as one closed fan, each b the next one's a; false if
/// they are not one consistently oriented cycle.
bool close_fan(std::vector<Sector>& fan) {
    const std::size_t k = fan.size();
    if (k < 3) return false;
    for (std::size_t i = 0; i + 1 < k; ++i) {
        std::size_t next = k;
        for (std::size_t j = i + 1; j < k; ++j)
            if (fan[j].a == fan[i].b) {
                if (next != k) return false;  // two sectors start at one edge: not a disc
                next = j;
            }
        if (next == k) return false;
        std::swap(fan[i + 1], fan[next]);
    }
    if (fan[k - 1].b != fan[0].a) return false;
    for (std::size_t i = 0; i < k; ++i)  // no corner visited twice
        for (std::size_t j = i + 1; j < k; ++j)
            if (fan[i].a == fan[j].a) return false;
    return true;
}

/// The coordinate plane most nearly facing the star (a heuristic: any
/// plane that passes the exact tests below is a proof).
int facing_axis(const Vec3d& v, const std::vector<Sector>& fan, const std::vector<Vec3d>& points) {
    Vec3d n(0.0);
    for (const Sector& s : fan) n += (points[s.a] - v).cross(points[s.b] - v);
    const Vec3d m(std::abs(n[0]), std::abs(n[1]), std::abs(n[2]));
    return m[0] >= m[1] ? (m[0] >= m[2] ? 0 : 2) : (m[1] >= m[2] ? 1 : 2);
}

bool flat(const Vec3d& v, const std::vector<Sector>& fan, const std::vector<Vec3d>& points) {
    const int drop = facing_axis(v, fan, points);
    const int i = (drop + 1) % 3, j = (drop + 2) % 3;
    auto orient = [&](const Vec3d& p, const Vec3d& q, const Vec3d& r) {
        return orient2d(p[i], p[j], q[i], q[j], r[i], r[j]);
    };
    const Vec3d& a0 = points[fan[0].a];
    const int o = orient(v, a0, points[fan[0].b]);
    if (o == 0) return false;
    // Each sector turns the same way by less than a half turn, so the fan
    // turns around v once iff its corners pass the ray opposite a0 once:
    // from the left of the line v a0 (side > 0) to the right or onto it.
    int passes = 0, previous_side = 0;
    for (const Sector& s : fan) {
        if (orient(v, points[s.a], points[s.b]) != o) return false;
        const int side = s.b == fan[0].a ? 0 : o * orient(v, a0, points[s.b]);
        passes += previous_side > 0 && side <= 0;
        previous_side = side;
    }
    return passes == 1;
}

}  // namespace

std::vector<std::uint8_t> find_flat_vertices(const Mesh& mesh, const std::vector<Vec3d>& points,
                                             const std::vector<char>& skip) {
    const Incidence inc = build_incidence(mesh);
    std::vector<std::uint8_t> result(points.size(), 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points.size(), 4096), [&](const tbb::blocked_range<std::size_t>& r) {
        std::vector<Sector> fan;
        for (std::size_t v = r.begin(); v != r.end(); ++v) {
            const std::size_t first = inc.begin[v], last = inc.begin[v + 1];
            if (last - first > kMaxStar) continue;
            fan.clear();
            bool usable = true;
            for (std::size_t e = first; e < last && usable; ++e) {
                const std::uint32_t t = inc.triangle[e];
                const std::array<unsigned, 3> c = split_triangle(mesh, t);
                const int k = c[0] == v ? 0 : c[1] == v ? 1 : 2;
                usable = !skip[t] && c[(k + 1) % 3] != v && c[(k + 2) % 3] != v;
                fan.push_back({c[(k + 1) % 3], c[(k + 2) % 3]});
            }
            result[v] = usable && close_fan(fan) && flat(points[v], fan, points);
        }
    });
    return result;
}

}  // namespace pqdc::detail
