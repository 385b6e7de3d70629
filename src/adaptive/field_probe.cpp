#include "adaptive/field_probe.hpp"

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

double field_gradient_length(FieldProbe& probe, const openvdb::Vec3d& p) {
    return field_gradient(probe, p, 0.5).length();
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
    if (!(len2 > 0) || !std::isfinite(g)) return p;
    const openvdb::Vec3d step = grad * (g / len2);
    if (!(step.length() <= reach)) return p;
    return p - step;
}
}  // namespace pqdc::adaptive_detail
