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

/// In the projection that drops axis `drop`, the sectors turn around v once,
/// each the same way by less than a half turn.
bool flat_in(const Vec3d& v, const std::vector<Sector>& fan, const std::vector<Vec3d>& points, int drop) {
    auto corner = [&](std::size_t k) -> const Vec3d& { return points[fan[k].a]; };
    const BoxOrient2d orient = orient_in_box_of((drop + 1) % 3, (drop + 2) % 3, v, fan.size(), corner);
    return turns_once_around(orient, v, fan.size(), corner) != 0;
}

/// Flat in some coordinate projection: `first` is tried first and becomes
/// the one that worked (neighbouring vertices face alike). Whether a vertex
/// is flat does not depend on the order, only the time does.
bool flat(const Vec3d& v, const std::vector<Sector>& fan, const std::vector<Vec3d>& points, int& first) {
    for (int k = 0; k < 3; ++k)
        if (flat_in(v, fan, points, (first + k) % 3)) {
            first = (first + k) % 3;
            return true;
        }
    return false;
}

}  // namespace

std::vector<std::uint8_t> find_flat_vertices(const Mesh& mesh, const std::vector<Vec3d>& points,
                                             const std::vector<char>& skip) {
    const Incidence inc = build_incidence(mesh);
    std::vector<std::uint8_t> result(points.size(), 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points.size(), 4096), [&](const tbb::blocked_range<std::size_t>& r) {
        std::vector<Sector> fan;
        int projection = 0;
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
            result[v] = usable && close_fan(fan) && flat(points[v], fan, points, projection);
        }
    });
    return result;
}

}  // namespace pqdc::detail
