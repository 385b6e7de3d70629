#include "adaptive/field_probe.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace pqdc::adaptive_detail {

openvdb::Vec3d field_gradient(FieldProbe& probe, const openvdb::Vec3d& p, double h) {
    openvdb::Vec3d g;
    for (int d = 0; d < 3; ++d) {
        openvdb::Vec3d a = p, b = p;
        a[d] -= h;
        b[d] += h;
        g[d] = (probe.value(b) - probe.value(a)) / (2 * h);
    }
    return g;
}

namespace {

/// |g|, also where its squares overflow (values from about 1e154 on: the
/// length was infinite, every distance 0, and the octree collapsed to a
/// cube) or fall below the normal range; the plain length elsewhere.
double length_of(const openvdb::Vec3d& g) {
    const double len2 = g.lengthSqr();
    if (len2 >= std::numeric_limits<double>::min() && std::isfinite(len2)) return std::sqrt(len2);
    const double m = std::max({std::abs(g[0]), std::abs(g[1]), std::abs(g[2])});
    if (!(m > 0) || !std::isfinite(m)) return m;  // 0, or not finite as it is
    return m * (g / m).length();
}

}  // namespace

double field_gradient_length(FieldProbe& probe, const openvdb::Vec3d& p) {
    return length_of(field_gradient(probe, p, 0.5));
}

double field_distance_voxels(FieldProbe& probe, const openvdb::Vec3d& p, double gradient_length) {
    const double g = probe.value(p);
    if (!(gradient_length > 0) || !std::isfinite(g)) return std::numeric_limits<double>::infinity();
    return std::fabs(g) / gradient_length;
}

openvdb::Vec3d project_to_surface(FieldProbe& probe, const openvdb::Vec3d& p, double reach) {
    const double g = probe.value(p);
    const openvdb::Vec3d grad = field_gradient(probe, p, 0.5);
    const double len2 = grad.lengthSqr();
    if (!std::isfinite(g)) return p;
    openvdb::Vec3d step;
    if (len2 >= std::numeric_limits<double>::min() && std::isfinite(len2)) {
        step = grad * (g / len2);
    } else {  // the squares overflow or underflow (see length_of)
        const double len = length_of(grad);
        if (!(len > 0) || !std::isfinite(len)) return p;
        step = (grad / len) * (g / len);
    }
    if (!(step.length() <= reach)) return p;
    return p - step;
}
}  // namespace pqdc::adaptive_detail
