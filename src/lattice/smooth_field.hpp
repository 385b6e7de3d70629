// Stage "smooth field" (denoising, part one): the values that decide a noisy
// volume's topology and its Hermite samples.
//
// On noisy data the signs of single lattice points flip (noise of 0.3 voxel
// flips most points within half a voxel of the surface), so the cells the
// surface crosses wander by a voxel around the true surface and no vertex
// placement inside those cells can be smooth. Denoising therefore meshes a
// smoothed copy of the field, in which every value within kBandVoxels of the
// surface becomes
//   s(p) = sum_k w_k u(p, p+k) [v(p+k) - (g(p) + g(p+k))/2 . k] / sum_k w_k u(p, p+k)
// over the 3x3x3 neighbourhood: w the binomial kernel [1 2 1]/4 per axis, g
// the least-squares gradient (crossings.hpp), u = max(0, <g^(p), g^(p+k)>)^8
// for unit gradients g^. Each neighbour predicts the value at p by the
// trapezoidal rule along the segment, exact for quadratic fields whatever
// the weights (so curvature does not move the surface, as tangent planes
// alone would by |k|^2 / 2R), or near edges by its own tangent plane;
// the normal weight u drops neighbours on the other face of a sharp edge, so
// the kink survives where a Gaussian blur moves a 90-degree edge of a
// distance field half a voxel inwards. Noise falls to about a quarter.
// Values are signed (Signing) for the computation and stored back in the
// grid's own units; the tree's topology is the input's.
#pragma once

#include "lattice/crossings.hpp"
#include "lattice/interior.hpp"
#include "lattice/resources.hpp"
#include "lattice/value_block.hpp"

#include <openvdb/openvdb.h>
#include <openvdb/tree/LeafManager.h>

#include <cmath>
#include <memory>
#include <vector>

namespace pqdc::detail {

/// Values farther from the surface than this (|v| / |g|, voxels) keep their
/// sign under any noise the filter is meant for and are copied unchanged.
inline constexpr double kSmoothBandVoxels = 2.0;

/// Neighbours whose unit gradient is closer than this (cosine) to the
/// point's predict by the trapezoidal rule; the others, across an edge or
/// corner, by their own tangent plane (the point's gradient is a blend of
/// both faces there).
inline constexpr double kSmoothCosine = 0.98;

/// Lattice points around a leaf whose raw values its smoothed values read:
/// one for the gradients, one more for the neighbours' gradients.
inline constexpr int kSmoothReach = 2;

/// The smoothed value at block point (x, y, z), given the block's gradients
/// and unit gradients (index b.index(...)); the point needs two points of
/// margin. Returns the value itself outside the band.
inline double smoothed_value(const DenseBlock& b, const std::vector<vec3<double>>& grad,
                             const std::vector<vec3<double>>& unit, int x, int y, int z) {
    const int c = b.index(x, y, z), sx = b.dim * b.dim, sy = b.dim;
    const double v = b.value[c], glen = length(grad[c]);
    if (!b.on(x, y, z) || !(glen > 0) || !(std::abs(v) < kSmoothBandVoxels * glen)) return v;
    double sum = 0, wsum = 0;
    for (int i = -1; i <= 1; ++i)
        for (int j = -1; j <= 1; ++j)
            for (int k = -1; k <= 1; ++k) {
                const int q = c + i * sx + j * sy + k;
                if (!b.on(x + i, y + j, z + k)) continue;  // a narrow band's clamped background
                const double cosine = dot(unit[c], unit[q]);
                if (!(cosine > 0)) continue;
                const double c2 = cosine * cosine, c4 = c2 * c2;
                const double w = double((i ? 1 : 2) * (j ? 1 : 2) * (k ? 1 : 2)) * c4 * c4;
                const vec3<double> g = cosine > kSmoothCosine ? (grad[q] + grad[c]) * 0.5 : grad[q];
                sum += w * (b.value[q] - (g.x * i + g.y * j + g.z * k));
                wsum += w;
            }
    return wsum > 0 ? sum / wsum : v;
}

/// Writes into `leaf` (a copy of a leaf of `raw`) its smoothed values, read
/// from `raw`'s values within kSmoothReach of it; a point with NaN or
/// infinity within kSmoothReach keeps its value. (Per point: a whole leaf
/// left unsmoothed for one NaN in its neighbourhood made the mesh depend on
/// where the leaves fell, e.g. along a Python array's border.)
template <class TreeT>
void smooth_leaf(const TreeT& raw, typename TreeT::LeafNodeType& leaf, const Signing& signing) {
    using ValueT = typename TreeT::ValueType;
    constexpr int L = int(TreeT::LeafNodeType::DIM);
    openvdb::tree::ValueAccessor<const TreeT, false> acc(raw);
    DenseBlock b;
    fetch_block(acc, leaf.origin() - openvdb::Coord(kSmoothReach), L + 2 * kSmoothReach, signing, b);
    const std::size_t n = std::size_t(b.dim) * b.dim * b.dim;
    // Per block point, when the block holds NaN or infinity: whether the 3^3
    // values around it are finite (its gradient is then the least-squares
    // one); a point is smoothed only where its 3^3 neighbours all are.
    std::vector<char> finite3;
    if (!b.all_finite) {
        finite3.assign(n, 0);
        for (int x = 1; x + 1 < b.dim; ++x)
            for (int y = 1; y + 1 < b.dim; ++y)
                for (int z = 1; z + 1 < b.dim; ++z) finite3[b.index(x, y, z)] = neighbourhood_finite(b, x, y, z);
    }
    auto smoothable = [&](int x, int y, int z) {
        if (finite3.empty()) return true;
        for (int i = -1; i <= 1; ++i)
            for (int j = -1; j <= 1; ++j)
                for (int k = -1; k <= 1; ++k)
                    if (!finite3[b.index(x + i, y + j, z + k)]) return false;
        return true;
    };
    std::vector<vec3<double>> grad(n, vec3<double>{0, 0, 0}), unit(n, vec3<double>{0, 0, 0});
    for (int x = 1; x + 1 < b.dim; ++x)
        for (int y = 1; y + 1 < b.dim; ++y)
            for (int z = 1; z + 1 < b.dim; ++z) {
                const int i = b.index(x, y, z);
                grad[i] = least_squares_gradient(b, x, y, z);
                unit[i] = normalized_or_zero(grad[i]);
            }
    ValueT* data = leaf.buffer().data();
    for (int x = 0; x < L; ++x)
        for (int y = 0; y < L; ++y)
            for (int z = 0; z < L; ++z) {
                const int bx = x + kSmoothReach, by = y + kSmoothReach, bz = z + kSmoothReach;
                if (!smoothable(bx, by, bz)) continue;  // keeps its raw value
                const double s = smoothed_value(b, grad, unit, bx, by, bz);
                data[(x * L + y) * L + z] = ValueT(signing.isovalue + signing.sign * s);
            }
}

/// The smoothed copy of `tree` (see the file comment). Leaf-parallel;
/// each leaf reads only the input, so the result is the same for any
/// thread count. Points with NaN or infinity within kSmoothReach keep their
/// values. With a span, it reports (and cancels) every 512 leaves.
template <class TreeT>
std::unique_ptr<TreeT> smooth_field(const TreeT& tree, const Signing& signing, const ProgressSpan* span = nullptr) {
    auto out = std::make_unique<TreeT>(tree);
    openvdb::tree::LeafManager<TreeT> leaves(*out);
    auto smooth_leaf = [&](typename TreeT::LeafNodeType& leaf) { detail::smooth_leaf(tree, leaf, signing); };
    if (!span) {
        leaves.foreach([&](typename TreeT::LeafNodeType& leaf, std::size_t) { smooth_leaf(leaf); });
        return out;
    }
    parallel_ranges(leaves.leafCount(), 1, 512, *span, [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) smooth_leaf(leaves.leaf(i));
    });
    return out;
}

}  // namespace pqdc::detail
