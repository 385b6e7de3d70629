// Per-vertex error quadrics and collapse costs.
//
// Garland & Heckbert, "Surface Simplification Using Quadric Error Metrics"
// (SIGGRAPH 1997): every vertex carries the sum of its faces' quadrics; a
// collapse a-b goes to the minimizer of Q_a + Q_b and costs Q(x_min), and
// the merged vertex keeps Q_a + Q_b.
// Trettner & Kobbelt, "Fast and Robust QEF Minimization using Probabilistic
// Quadrics" (EG 2020), section 4.2: with probabilistic plane or triangle
// quadrics A is positive definite, so x_min = A^-1 b needs no SVD and the
// placement is stable on flat regions (no zero-cost drift) and adapts to
// the stated noise.
// Curvature metric: "Mesh Simplification With Curvature Error Metric"
// (poster): an algebraic sphere per vertex from Algebraic Point Set
// Surfaces (Guennebaud & Gross 2007), interpolated along the edge; the cost
// is |S| integrated along the new edges. The poster places x on the edge;
// here the quadric minimizer is one more candidate position.

#include "decimate_internal.hpp"
#include "geometry/float_rounding.hpp"
#include "memory/huge_pages.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace pqdc::decimate_detail {
namespace {

Quadric face_quadric(const WorkMesh& m, const Tri& t, const DecimateOptions& o) {
    const vec p = m.local(m.pos[t[0]]), q = m.local(m.pos[t[1]]), r = m.local(m.pos[t[2]]);
    if (o.metric == DecimateMetric::plane) {
        const vec n = cross(q - p, r - p);
        const double len = length(n);
        if (!(len > 0)) return {};
        const Quadric pq = Quadric::probabilistic_plane((p + q + r) / 3.0, n / len, o.sigma_position_voxels,
                                                        o.sigma_normal);
        return pq * (0.5 * len);  // area-weighted
    }
    return Quadric::probabilistic_triangle(p, q, r, o.sigma_position_voxels);
}


/// APSS fit (Guennebaud & Gross 2007, eqs. for u4, u, u0) to the vertex
/// and its one-ring with their normals, then Pratt-normalized so that |S|
/// approximates the distance to the sphere near the surface.
Sphere fit_sphere(const WorkMesh& m, std::uint32_t v) {
    double W = 0, PN = 0, PP = 0;
    vec P{}, N{};
    auto add = [&](std::uint32_t w) {
        const vec p = m.local(m.pos[w]), n = vertex_normal(m, w);
        W += 1;
        P += p;
        N += n;
        PN += dot(p, n);
        PP += dot(p, p);
    };
    add(v);
    for (std::size_t i = 0; i < m.fan_size(v); ++i) {
        const Tri& t = m.tris[m.fan_of(v)[i]];
        for (int k = 0; k < 3; ++k)
            if (t[k] != v && t[(k + 1) % 3] == v) add(t[k]);  // each ring vertex once (closed fan)
    }
    Sphere s;
    const double den = PP / W - dot(P, P) / (W * W);
    s.u4 = den > 1e-12 ? 0.5 * (PN / W - dot(P, N) / (W * W)) / den : 0.0;
    s.u = (N - P * (2 * s.u4)) / W;
    s.u0 = -(dot(s.u, P) + s.u4 * PP) / W;
    const double pratt = dot(s.u, s.u) - 4 * s.u0 * s.u4;
    if (pratt > 0) {
        const double k = 1 / std::sqrt(pratt);
        s.u0 *= k;
        s.u = s.u * k;
        s.u4 *= k;
    }
    return s;
}

/// |S| integrated along the segment p-q (Simpson's rule), times its length.
double sphere_edge_cost(const Sphere& s, const vec& p, const vec& q) {
    const double l = length(q - p);
    return l * (std::fabs(s(p)) + 4 * std::fabs(s((p + q) * 0.5)) + std::fabs(s(q))) / 6;
}

Candidate curvature_collapse(const WorkMesh& m, std::uint32_t a, std::uint32_t b, const vec& quadric_x) {
    const vec pa = m.local(m.pos[a]), pb = m.local(m.pos[b]);
    const vec e = pb - pa;
    const double ee = dot(e, e);
    vec choices[6] = {m.local(quadric_x), pa, pa + e * 0.25, pa + e * 0.5, pa + e * 0.75, pb};
    Candidate best{a, b, m.pos[a], std::numeric_limits<double>::infinity()};
    for (const vec& x : choices) {
        const double t = ee > 0 ? std::clamp(dot(x - pa, e) / ee, 0.0, 1.0) : 0.5;
        const Sphere s = m.spheres[a].lerp(m.spheres[b], t);
        double cost = 0;
        for (std::uint32_t v : {a, b}) {
            for (std::size_t i = 0; i < m.fan_size(v); ++i) {
                const Tri& tri = m.tris[m.fan_of(v)[i]];
                for (int k = 0; k < 3; ++k) {
                    const std::uint32_t w = tri[k];
                    // Each new edge x-w once: w follows v in a face of v's fan.
                    if (w != a && w != b && tri[(k + 2) % 3] == v) cost += sphere_edge_cost(s, x, m.local(m.pos[w]));
                }
            }
        }
        if (cost < best.cost) best = {a, b, m.world(x), cost};
    }
    return best;
}

}  // namespace

vec vertex_normal(const WorkMesh& m, std::uint32_t v) {
    vec n{};
    for (std::size_t i = 0; i < m.fan_size(v); ++i) {
        const Tri& t = m.tris[m.fan_of(v)[i]];
        n += cross(m.pos[t[1]] - m.pos[t[0]], m.pos[t[2]] - m.pos[t[0]]);
    }
    const double len = length(n);
    return len > 0 ? n / len : n;
}

void build_vertex_quadrics(WorkMesh& m, const DecimateOptions& o) {
    std::vector<Quadric> faces;
    detail::reserve_large(faces, m.tris.size());
    faces.resize(m.tris.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, m.tris.size(), 4096), [&](const auto& r) {
        for (std::size_t i = r.begin(); i < r.end(); ++i) faces[i] = face_quadric(m, m.tris[i], o);
    });
    detail::reserve_large(m.quadrics, m.pos.size());
    m.quadrics.assign(m.pos.size(), Quadric{});
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, m.pos.size(), 4096), [&](const auto& r) {
        for (std::size_t v = r.begin(); v < r.end(); ++v)
            for (std::size_t i = 0; i < m.fan_size(std::uint32_t(v)); ++i)
                m.quadrics[v] += faces[m.fan_of(std::uint32_t(v))[i]];  // fan order: ascending face id
    });
}

void build_vertex_spheres(WorkMesh& m) {
    m.spheres.assign(m.pos.size(), Sphere{});
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, m.pos.size(), 1024), [&](const auto& r) {
        for (std::size_t v = r.begin(); v < r.end(); ++v)
            if (m.fan_size(std::uint32_t(v)) > 0) m.spheres[v] = fit_sphere(m, std::uint32_t(v));
    });
}

Candidate evaluate_collapse(const WorkMesh& m, std::uint32_t a, std::uint32_t b, DecimateMetric metric) {
    const Quadric q = m.quadrics[a] + m.quadrics[b];
    vec x;
    if (auto pd = minimizer_positive_definite(q)) {
        x = *pd;
    } else {
        x = minimizer_pseudo_inverse(q, (m.local(m.pos[a]) + m.local(m.pos[b])) * 0.5).point;
    }
    Candidate c = metric == DecimateMetric::curvature ? curvature_collapse(m, a, b, m.world(x))
                                                      : Candidate{a, b, m.world(x), std::max(0.0, q(x))};
    if (m.float_positions) c.x = detail::rounded_to_float(c.x);
    return c;
}

}  // namespace pqdc::decimate_detail
