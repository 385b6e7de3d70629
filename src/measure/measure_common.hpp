// Helpers the measures share (internal): uniform face access, index-ordered
// parallel loops, and the serial reductions that keep sums independent of
// how TBB split the work.
#pragma once

#include "measure/mesh_internal.hpp"
#include "pqdc/measure.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

namespace pqdc::measure_detail {

using detail::BoxNode;
using detail::BoxTreeBuilder;
using detail::check_indices;
using detail::split_triangle;
using detail::split_triangle_count;
using detail::UnionFind;

constexpr double kDegreesPerRadian = 57.29577951308232;

using Vec3d = openvdb::Vec3d;

inline bool finite(const Vec3d& v) { return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]); }

/// Angle between two vectors in degrees, robust near 0 and 180.
inline double angle_degrees(const Vec3d& a, const Vec3d& b) {
    return std::atan2(a.cross(b).length(), a.dot(b)) * kDegreesPerRadian;
}

/// Uniform access to triangles and quads as faces 0..F-1 (triangles first).
class FaceView {
public:
    explicit FaceView(const Mesh& mesh) : mesh_(mesh) {}
    std::size_t size() const { return mesh_.triangles.size() + mesh_.quads.size(); }
    int corners(std::size_t f) const { return f < mesh_.triangles.size() ? 3 : 4; }
    unsigned vertex(std::size_t f, int k) const {
        return f < mesh_.triangles.size() ? mesh_.triangles[f][k] : mesh_.quads[f - mesh_.triangles.size()][k];
    }
    bool has_repeated_vertex(std::size_t f) const {
        const int n = corners(f);
        for (int i = 0; i < n; ++i)
            for (int j = i + 1; j < n; ++j)
                if (vertex(f, i) == vertex(f, j)) return true;
        return false;
    }
    /// Vector area times 2 (triangle: cross of two sides; quad: cross of the
    /// diagonals, the exact vector area of a non-planar quad).
    Vec3d area_vector2(std::size_t f) const {
        const auto& p = mesh_.points;
        if (corners(f) == 3) {
            const Vec3d& a = p[vertex(f, 0)];
            return (p[vertex(f, 1)] - a).cross(p[vertex(f, 2)] - a);
        }
        return (p[vertex(f, 2)] - p[vertex(f, 0)]).cross(p[vertex(f, 3)] - p[vertex(f, 1)]);
    }
    Vec3d centroid(std::size_t f) const {
        Vec3d c(0.0);
        const int n = corners(f);
        for (int k = 0; k < n; ++k) c += mesh_.points[vertex(f, k)];
        return c / double(n);
    }
    double longest_side(std::size_t f) const {
        const int n = corners(f);
        double l = 0;
        for (int k = 0; k < n; ++k)
            l = std::max(l, (mesh_.points[vertex(f, (k + 1) % n)] - mesh_.points[vertex(f, k)]).length());
        return l;
    }

private:
    const Mesh& mesh_;
};


template <typename Fn>
void parallel_indices(std::size_t n, Fn&& fn) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) fn(i);
    });
}

inline DistanceStats summarize_distances(const std::vector<double>& signed_distance, const std::vector<char>& valid,
                                  std::size_t unreliable) {
    DistanceStats s;
    double sum = 0, sum_sq = 0, sum_signed = 0;
    for (std::size_t i = 0; i < signed_distance.size(); ++i) {
        if (!valid[i]) {
            ++s.skipped_count;
            continue;
        }
        const double d = std::abs(signed_distance[i]);
        ++s.sample_count;
        sum += d;
        sum_sq += d * d;
        sum_signed += signed_distance[i];
        s.max = std::max(s.max, d);
    }
    if (s.sample_count > 0) {
        const double n = double(s.sample_count);
        s.mean = sum / n;
        s.rms = std::sqrt(sum_sq / n);
        s.mean_signed = sum_signed / n;
    } else {
        s.mean = s.rms = s.max = s.mean_signed = std::numeric_limits<double>::quiet_NaN();
    }
    s.unreliable_count = unreliable;
    return s;
}

inline NormalDeviation summarize_angles(const std::vector<double>& angles) {
    NormalDeviation d;
    double sum = 0, sum_sq = 0;
    for (double a : angles) {
        if (std::isnan(a)) {
            ++d.skipped_count;
            continue;
        }
        ++d.sample_count;
        sum += a;
        sum_sq += a * a;
        d.max_degrees = std::max(d.max_degrees, a);
    }
    if (d.sample_count > 0) {
        d.mean_degrees = sum / double(d.sample_count);
        d.rms_degrees = std::sqrt(sum_sq / double(d.sample_count));
    } else {
        d.mean_degrees = d.rms_degrees = d.max_degrees = std::numeric_limits<double>::quiet_NaN();
    }
    return d;
}

}  // namespace pqdc::measure_detail
