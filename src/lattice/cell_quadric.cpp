#include "lattice/cell_quadric.hpp"

#include <algorithm>
#include <cmath>

namespace pqdc::detail {

PointSum PointSum::relative_to(const vec3<double>& origin) const {
    using W = long double;
    const vec3<W> s(sum), o(origin);
    const vec3<W> Ao = o * W(count);
    PointSum r;
    r.count = count;
    r.sum = vec3<double>(s - Ao);
    r.sum_sq = double(W(sum_sq) - W(2) * dot(s, o) + dot(o, Ao));
    return r;
}

CellVertex solve_cell_vertex(const CellQuadric& q, double cell_size, const ExtractOptions& o, Clamp clamp) {
    CellVertex v;
    const vec3<double> mass = q.points.mass_point();
    // A sigma_n whose square overflows (above about 1e154) is infinite here:
    // the minimizer's limit, the mass point, not a fallback from a failed solve.
    const double variance = o.sigma_n * o.sigma_n / cell_size;
    if (std::isinf(variance)) {
        v.local = mass;
    } else if (o.sigma_n == 0.0) {
        v.local = minimizer_pseudo_inverse(q.classical, mass, o.pseudo_inverse_cutoff).point;
    } else if (const auto x = minimizer_positive_definite(q.classical + q.points.as_quadric() * variance)) {
        v.local = *x;
    } else {
        v.local = mass;
        v.fallback = true;
    }
    if (!is_finite(v.local)) {
        v.local = mass;
        v.fallback = true;
    }
    if (clamp == Clamp::inside_cell) {
        // A hair inside, so vertices of neighbouring cells never coincide.
        const double lo = 1e-4 * cell_size, hi = cell_size - lo;
        for (int a = 0; a < 3; ++a) {
            if (v.local[a] < 0.0 || v.local[a] > cell_size) v.clamped = true;
            v.local[a] = std::min(hi, std::max(lo, v.local[a]));
        }
    }
    return v;
}

}  // namespace pqdc::detail
