// Stage "solve": the quadric of a cell's Hermite samples and its minimizer,
// one implementation for the uniform extractor and every octree level.
//
// A cell's samples are kept as two sums in cell-local coordinates (crossing
// points relative to the cell's minimum corner, in voxels), so that sums of
// far-away cells stay exact and sigma_n can be applied after summing:
//   classical: plane quadrics <x - q, n>^2 of the samples with a unit normal;
//   points:    point quadrics |x - q|^2 of every sample.
// classical + sigma_n^2 points is the sum of the isotropic probabilistic
// plane quadrics of Trettner & Kobbelt 2020 (eqs. 6-8 with Sigma_q = 0,
// Sigma_n = sigma_n^2 I); samples without a normal (zero or non-finite
// gradient) contribute their point term only. The classical part alone is
// the squared distance to the sample planes: the octree's collapse error.
#pragma once

#include "pqdc/extract.hpp"
#include "pqdc/quadric.hpp"

namespace pqdc::detail {

/// A sum of point quadrics |x - q_i|^2 kept as its five independent numbers
/// (its matrix is count * I): 40 bytes instead of a quadricd's 80.
struct PointSum {
    double count = 0;
    vec3<double> sum{};
    double sum_sq = 0;

    void add(const vec3<double>& q) {
        count += 1;
        sum += q;
        sum_sq += dot(q, q);
    }
    /// The point quadric of q, weighted by w > 0.
    void add(const vec3<double>& q, double w) {
        count += w;
        sum += q * w;
        sum_sq += w * dot(q, q);
    }
    PointSum& operator+=(const PointSum& o) {
        count += o.count;
        sum += o.sum;
        sum_sq += o.sum_sq;
        return *this;
    }
    /// The same sum with the points expressed relative to `origin`, with the
    /// arithmetic of quadric::relative_to (long double), so both stay exact
    /// to the same degree.
    PointSum relative_to(const vec3<double>& origin) const;
    quadricd as_quadric() const { return {sym3<double>::identity(count), sum, sum_sq}; }
    vec3<double> mass_point() const { return sum / count; }
};

struct CellQuadric {
    quadricd classical;
    PointSum points;

    /// One Hermite sample: crossing point q (cell-local) and unit normal n,
    /// or n == 0 for a sample without a usable gradient.
    void add(const vec3<double>& q, const vec3<double>& n) {
        if (!(n == vec3<double>{0, 0, 0})) classical += quadricd::plane(q, n);
        points.add(q);
    }
    /// The same sample weighted by w > 0 (filtered quadrics, denoising).
    void add(const vec3<double>& q, const vec3<double>& n, double w) {
        if (!(n == vec3<double>{0, 0, 0})) classical += quadricd::plane(q, n) * w;
        points.add(q, w);
    }
    CellQuadric& operator+=(const CellQuadric& o) {
        classical += o.classical;
        points += o.points;
        return *this;
    }
    /// The sum re-expressed relative to `origin` (cell-local coordinates of a parent).
    CellQuadric relative_to(const vec3<double>& origin) const {
        return {classical.relative_to(origin), points.relative_to(origin)};
    }
};

enum class Clamp {
    none,         ///< the minimizer as it is (the caller judges where it lies)
    inside_cell,  ///< moved into the cell, a hair (1e-4 of its size) away from its faces
};

struct CellVertex {
    vec3<double> local;     ///< cell-local position (0 .. cell size)
    bool clamped = false;   ///< the minimizer lay outside the cell and was moved in
    bool fallback = false;  ///< the solve failed and the mass point was taken
};

/// The vertex of a cell of edge `cell_size` voxels: the minimizer of
/// classical + (sigma_n^2 / cell_size) points. sigma_n = 0 minimizes the
/// classical part with the pseudo-inverse relative to the mass point
/// (options.pseudo_inverse_cutoff); infinity is the mass point. On a cell of
/// edge s the normal variance is sigma_n^2 / s: the regularization's pull at
/// a feature grows with the cell, and this keeps it at the finest level's
/// sigma_n^2 / 4 voxel at any size (see adaptive.hpp).
CellVertex solve_cell_vertex(const CellQuadric& q, double cell_size, const ExtractOptions& options, Clamp clamp);

}  // namespace pqdc::detail
