#include "adaptive/simplify.hpp"

namespace pqdc::adaptive_detail {

bool balanced(const std::vector<std::uint64_t>& internal_children, std::uint64_t parent_code) {
    if (internal_children.empty()) return true;
    const auto p = unmorton(parent_code);
    for (int dz = -1; dz <= 2; ++dz)
        for (int dy = -1; dy <= 2; ++dy)
            for (int dx = -1; dx <= 2; ++dx) {
                if (dx >= 0 && dx <= 1 && dy >= 0 && dy <= 1 && dz >= 0 && dz <= 1) continue;
                const std::int64_t x = 2 * std::int64_t(p[0]) + dx, y = 2 * std::int64_t(p[1]) + dy,
                                   z = 2 * std::int64_t(p[2]) + dz;
                if (x < 0 || y < 0 || z < 0) continue;
                if (std::binary_search(internal_children.begin(), internal_children.end(),
                                       morton(std::uint32_t(x), std::uint32_t(y), std::uint32_t(z))))
                    return false;
            }
    return true;
}

double collapse_error(const Level& cur, std::size_t i0, std::size_t i1, int h, const openvdb::Vec3d& x,
                      const CellQuadrics& sum, const openvdb::Coord& origin, FieldProbe& probe,
                      const AdaptiveOptions& options) {
    const double bound = options.max_error_voxels;
    // (a) RMS distance to each child's Hermite planes: the classical part, a
    // distance free of the sigma_n regularization.
    double error = 0;
    for (std::size_t i = i0; i < i1 && error < bound; ++i) {
        const unsigned o = unsigned(cur.code[i] & 7);
        const vec3<double> y(x.x() - double((o & 1) * h), x.y() - double((o >> 1 & 1) * h),
                             x.z() - double((o >> 2 & 1) * h));
        const CellQuadrics& q = cur.quadrics[i];
        error = std::max(error, std::sqrt(std::max(0.0, q.classical(y)) / q.points.count));
    }
    // (c) sigma_n pulls the vertex off weakly sampled features (a box corner
    // seen by one sample of its third face): keep it within half the bound
    // of the classical minimizer, taken with a small cutoff so that such
    // directions count.
    if (options.base.sigma_n > 0 && error < bound) {
        const vec3<double> xp(x.x(), x.y(), x.z());
        const auto classical = minimizer_pseudo_inverse(sum.classical, xp, 0.01);
        error = std::max(error, 2 * length(classical.point - xp));
    }
    // (b) The planes bound the vertex's distance to the sampled surface only
    // in the mean; check the field itself at the vertex too. (d) Faces will
    // join this vertex to its neighbours' vertices, about twice as far as its
    // children's: their sagitta is about four times the depth of the
    // midpoints towards the children's vertices. Those lie within a cell of
    // the vertex, so the vertex's gradient converts their field values to
    // distances (one probe each instead of seven).
    if (error < bound) {
        const openvdb::Vec3d px = origin.asVec3d() + x;
        const double gradient = field_gradient_length(probe, px);
        error = std::max(error, field_distance_voxels(probe, px, gradient));
        for (std::size_t i = i0; i < i1 && error < bound; ++i)
            error = std::max(error, 4 * field_distance_voxels(probe, 0.5 * (px + cur.vertex[i]), gradient));
    }
    return error;
}

}  // namespace pqdc::adaptive_detail
