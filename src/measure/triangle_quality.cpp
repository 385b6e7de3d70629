// Triangle shape: angles, aspect ratios, degenerate faces.
#include "pqdc/measure.hpp"

#include "measure/measure_common.hpp"
#include "pqdc/exceptions.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <string>
#include <utility>
#include <vector>

namespace pqdc {

using namespace measure_detail;

TriangleQuality measure_triangle_quality(const Mesh& mesh) {
    check_indices(mesh);
    const std::size_t nt = split_triangle_count(mesh);
    std::vector<double> min_angle(nt);
    auto corner_angle = [](const Vec3d& a, const Vec3d& b, const Vec3d& c) {
        const Vec3d u = b - a, v = c - a;
        if (!(u.lengthSqr() > 0.0) || !(v.lengthSqr() > 0.0)) return 0.0;
        const double angle = angle_degrees(u, v);
        return std::isfinite(angle) ? angle : 0.0;
    };
    auto tri_min_angle = [&](unsigned i, unsigned j, unsigned k) {
        const Vec3d &a = mesh.points[i], &b = mesh.points[j], &c = mesh.points[k];
        return std::min({corner_angle(a, b, c), corner_angle(b, c, a), corner_angle(c, a, b)});
    };
    parallel_indices(nt, [&](std::size_t t) {
        const auto c = split_triangle(mesh, t);
        min_angle[t] = tri_min_angle(c[0], c[1], c[2]);
    });
    TriangleQuality out;
    out.triangle_count = nt;
    if (nt == 0) {
        out.min_angle_mean_degrees = out.min_angle_min_degrees = out.min_angle_p05_degrees =
            out.fraction_below_10_degrees = std::numeric_limits<double>::quiet_NaN();
        return out;
    }
    double sum = 0;
    std::size_t below = 0;
    out.min_angle_min_degrees = min_angle[0];
    for (double a : min_angle) {
        sum += a;
        if (a < 10.0) ++below;
        out.min_angle_min_degrees = std::min(out.min_angle_min_degrees, a);
    }
    out.min_angle_mean_degrees = sum / double(nt);
    out.fraction_below_10_degrees = double(below) / double(nt);
    const std::size_t rank = std::max<std::size_t>(1, static_cast<std::size_t>(std::ceil(0.05 * double(nt))));
    std::nth_element(min_angle.begin(), min_angle.begin() + std::ptrdiff_t(rank - 1), min_angle.end());
    out.min_angle_p05_degrees = min_angle[rank - 1];
    return out;
}

}  // namespace pqdc
