// Distances and normal deviation of a mesh against a field's zero set:
// a procedural field (Newton projection) or a level set (its zero crossing).
#include "pqdc/measure.hpp"

#include "measure/measure_common.hpp"
#include "pqdc/exceptions.hpp"

#include <openvdb/tools/Interpolation.h>

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

namespace {


/// Newton projection of p onto f = 0. Returns true when |f(q)| <= tolerance
/// and q stayed local: a projection that travels more than twice the
/// first-order distance |f(p)| / |grad f(p)| has jumped to another part of
/// the surface (where the gradient is small, a full step overshoots), and
/// the caller falls back to the first-order estimate.
bool project_to_surface(const ScalarField& field, const Vec3d& p, const FieldDistanceOptions& options, Vec3d& q) {
    q = p;
    double reach = -1.0;
    for (int step = 0;; ++step) {
        const double f = field.value(q);
        if (!std::isfinite(f)) return false;
        if (std::abs(f) <= options.tolerance) return reach < 0.0 || (q - p).length() <= reach;
        if (step == options.newton_steps) return false;
        const Vec3d g = field.gradient(q);
        const double g2 = g.lengthSqr();
        if (!(g2 > 0.0) || !std::isfinite(g2)) return false;
        if (reach < 0.0) reach = 2.0 * std::abs(f) / std::sqrt(g2) + options.tolerance;
        q -= g * (f / g2);
        if ((q - p).length() > reach) return false;
    }
}

/// Distance along the unit direction u from p to the first point where f
/// changes sign, searched up to t_max; -1 when there is none. Steps of
/// |f| / L (L: the field's Lipschitz bound) cannot jump over the surface, a
/// floor of t_min keeps the march finite where f nearly vanishes, and the
/// last bracket is bisected.
double first_crossing_along(const ScalarField& field, const Vec3d& p, const Vec3d& u, double f0, double lipschitz,
                            double t_min, double t_max) {
    double t = 0.0;
    for (int step = 0; step < 100000; ++step) {
        const double f = field.value(p + u * t);
        if (!std::isfinite(f)) return -1.0;
        if (f == 0.0) return t;
        if ((f < 0.0) != (f0 < 0.0)) {
            double a = std::max(0.0, t - std::max(std::abs(f) / lipschitz, t_min)), b = t;
            a = std::max(0.0, a);
            for (int i = 0; i < 60 && b - a > 1e-3 * t_min; ++i) {
                const double m = 0.5 * (a + b);
                const double fm = field.value(p + u * m);
                if ((fm < 0.0) == (f0 < 0.0)) a = m;
                else b = m;
            }
            return 0.5 * (a + b);
        }
        if (t >= t_max) return -1.0;
        t = std::min(t_max, t + std::max(std::abs(f) / lipschitz, t_min));
    }
    return -1.0;
}

/// Where Newton's projection fails (|grad f| tiny or misleading), the
/// distance to the nearest surface point found by marching along the
/// gradient and the 26 lattice directions: an upper bound that is a real
/// surface point, unlike |f| / |grad f|, which explodes where the gradient
/// nearly vanishes. Falls back to the lower bound |f| / L when no march
/// meets the surface.
double fallback_distance(const ScalarField& field, const Vec3d& p, double f) {
    const double lipschitz = field.lipschitz_bound();
    const double lower = std::abs(f) / lipschitz;
    if (!(lipschitz > 0.0) || !std::isfinite(lower)) return std::abs(f);
    if (lower == 0.0) return 0.0;
    std::vector<Vec3d> dirs;
    const Vec3d g = field.gradient(p);
    if (g.lengthSqr() > 0.0 && finite(g)) {
        dirs.push_back(g.unitSafe());
        dirs.push_back(-g.unitSafe());
    }
    for (int z = -1; z <= 1; ++z)
        for (int y = -1; y <= 1; ++y)
            for (int x = -1; x <= 1; ++x)
                if (x || y || z) dirs.push_back(Vec3d(x, y, z).unitSafe());
    double best = -1.0;
    Vec3d q;
    const double t_min = 1e-3 * lower;
    for (const Vec3d& u : dirs) {
        const double t_max = best >= 0.0 ? best : 1000.0 * lower;
        const double t = first_crossing_along(field, p, u, f, lipschitz, t_min, t_max);
        if (t >= 0.0 && (best < 0.0 || t < best)) {
            best = t;
            q = p + u * t;
        }
    }
    if (best < 0.0) return lower;
    // The hit nearest along a fixed direction is rarely the nearest point:
    // slide it along the surface, from each q to the Newton projection of p's
    // foot on the tangent plane at q, while that gets closer.
    for (int it = 0; it < 32; ++it) {
        const Vec3d n = field.gradient(q);
        if (!(n.lengthSqr() > 0.0) || !finite(n)) break;
        const Vec3d un = n.unitSafe();
        const Vec3d foot = p - un * (p - q).dot(un);
        Vec3d next = foot;
        for (int k = 0; k < 16; ++k) {  // plain Newton from the foot (it starts on the surface's tangent plane)
            const double fv = field.value(next);
            const Vec3d g = field.gradient(next);
            if (!std::isfinite(fv) || !(g.lengthSqr() > 0.0)) break;
            next -= g * (fv / g.lengthSqr());
        }
        if (!(std::abs(field.value(next)) <= 1e-6 * lower * lipschitz)) break;
        if (!((p - next).length() < (p - q).length() * (1.0 - 1e-9))) break;
        q = next;
    }
    return std::max((p - q).length(), lower);
}

void validate(const FieldDistanceOptions& options) {
    if (options.newton_steps < 1 || options.newton_steps > 100)
        throw option_error("FieldDistanceOptions::newton_steps = " + std::to_string(options.newton_steps) +
                           " is outside [1, 100]");
    if (!(options.tolerance > 0.0) || !std::isfinite(options.tolerance))
        throw option_error("FieldDistanceOptions::tolerance must be a positive finite number");
}

}  // namespace

DistanceStats measure_distance(const Mesh& mesh, const ScalarField& field, const FieldDistanceOptions& options) {
    validate(options);
    const std::size_t n = mesh.points.size();
    std::vector<double> signed_distance(n, 0.0);
    std::vector<char> valid(n, 0), unreliable(n, 0);
    parallel_indices(n, [&](std::size_t i) {
        const Vec3d& p = mesh.points[i];
        if (!finite(p)) return;
        const double f = field.value(p);
        if (!std::isfinite(f)) return;
        valid[i] = 1;
        Vec3d q;
        double d;
        if (project_to_surface(field, p, options, q)) {
            d = (p - q).length();
        } else {
            d = fallback_distance(field, p, f);
            unreliable[i] = 1;
        }
        signed_distance[i] = f < 0.0 ? -d : d;
    });
    const std::size_t unreliable_count = static_cast<std::size_t>(std::count(unreliable.begin(), unreliable.end(), 1));
    return summarize_distances(signed_distance, valid, unreliable_count);
}

DistanceStats measure_distance(const Mesh& mesh, const openvdb::FloatGrid& level_set) {
    if (level_set.getGridClass() == openvdb::GRID_FOG_VOLUME) {
        throw input_error("grid '" + level_set.getName() +
                          "' is a fog volume; distances need a level set (values = signed world distance)");
    }
    const std::size_t n = mesh.points.size();
    const double background = std::abs(double(level_set.background()));
    std::vector<double> signed_distance(n, 0.0);
    std::vector<char> valid(n, 0), unreliable(n, 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096), [&](const tbb::blocked_range<std::size_t>& r) {
        openvdb::FloatGrid::ConstAccessor accessor = level_set.getConstAccessor();
        openvdb::tools::GridSampler<openvdb::FloatGrid::ConstAccessor, openvdb::tools::BoxSampler> sampler(
            accessor, level_set.transform());
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            const Vec3d& p = mesh.points[i];
            if (!finite(p)) continue;
            const double v = double(sampler.wsSample(p));
            if (!std::isfinite(v)) continue;
            valid[i] = 1;
            signed_distance[i] = v;
            if (background > 0.0 && std::abs(v) >= background * (1.0 - 1e-6)) unreliable[i] = 1;
        }
    });
    const std::size_t unreliable_count = static_cast<std::size_t>(std::count(unreliable.begin(), unreliable.end(), 1));
    return summarize_distances(signed_distance, valid, unreliable_count);
}

NormalDeviation measure_normal_deviation(const Mesh& mesh, const ScalarField& field, NormalSampling sampling,
                                         const FieldDistanceOptions& options) {
    validate(options);
    check_indices(mesh);
    const FaceView faces(mesh);
    const double nan = std::numeric_limits<double>::quiet_NaN();
    auto deviation = [&](const Vec3d& normal, const Vec3d& p) {
        if (!(normal.lengthSqr() > 0.0) || !finite(normal) || !finite(p)) return nan;
        Vec3d q;
        if (!project_to_surface(field, p, options, q)) q = p;
        const Vec3d g = field.gradient(q);
        if (!(g.lengthSqr() > 0.0) || !finite(g)) return nan;
        return angle_degrees(normal, g);
    };
    std::vector<double> angles;
    if (sampling == NormalSampling::per_face) {
        angles.resize(faces.size());
        parallel_indices(faces.size(), [&](std::size_t f) {
            angles[f] = deviation(faces.area_vector2(f), faces.centroid(f));
        });
    } else {
        // Serial accumulation keeps the sums' rounding independent of threads.
        std::vector<Vec3d> normals(mesh.points.size(), Vec3d(0.0));
        std::vector<char> referenced(mesh.points.size(), 0);
        for (std::size_t f = 0; f < faces.size(); ++f) {
            const Vec3d a = faces.area_vector2(f);
            for (int k = 0; k < faces.corners(f); ++k) {
                normals[faces.vertex(f, k)] += a;
                referenced[faces.vertex(f, k)] = 1;
            }
        }
        angles.resize(mesh.points.size());
        parallel_indices(mesh.points.size(), [&](std::size_t v) {
            angles[v] = referenced[v] ? deviation(normals[v], mesh.points[v]) : -1.0;
        });
        angles.erase(std::remove(angles.begin(), angles.end(), -1.0), angles.end());
    }
    return summarize_angles(angles);
}

}  // namespace pqdc
