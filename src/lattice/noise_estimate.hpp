// Stage "noise estimate": how noisy the volume is, from the data alone, so
// that sigma_n, the gradient stencil and the quadric filter can be chosen
// for it (ExtractOptions' automatic settings, see auto_parameters.hpp).
//
// Around lattice points next to the surface (a sign change to a +x, +y or +z
// neighbour) the signed values of the 3x3x3 neighbourhood are fitted with a
// quadratic function by least squares. On a clean distance field or a smooth
// density the fit is nearly exact (a linear fit would leave about 1/(2R)
// voxel on a sphere of radius R: 0.08 at R = 6, which reads as noise);
// i.i.d. noise of standard deviation s leaves residuals whose mean square
// over the 17 degrees of freedom is s^2. Divided by the fitted gradient's
// length the residual is a distance, in voxels, for level sets and densities
// alike. The median over the sampled points ignores the few points on edges
// and corners, whose kink also leaves residuals.
#pragma once

#include "lattice/interior.hpp"
#include "lattice/value_block.hpp"

#include <openvdb/openvdb.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

namespace pqdc::detail {

struct NoiseEstimate {
    double voxels = 0;          ///< median residual of the local quadratic fits, voxels
    std::uint64_t samples = 0;  ///< surface points it is taken from
};

/// Residual of the quadratic least-squares fit of the 27 values around
/// block point (x, y, z), divided by the fitted gradient's length (voxels);
/// a negative value when the neighbourhood is not finite or flat.
double fit_residual_voxels(const DenseBlock& b, int x, int y, int z);

/// Whether the 27 points around block point (x, y, z) are all active: a
/// narrow band's inactive points hold the clamped background, a kink that
/// is no noise.
inline bool all_active_around(const DenseBlock& b, int x, int y, int z) {
    for (int i = -1; i <= 1; ++i)
        for (int j = -1; j <= 1; ++j)
            if (((b.active_row[x + i][y + j] >> (z - 1)) & 7u) != 7u) return false;
    return true;
}

/// The median of `residuals` (any order); 0 for none.
NoiseEstimate median_noise(std::vector<double>& residuals);

/// At most about kNoiseMaxLeaves blocks, evenly spread over `blocks` (candidate
/// origins in tree order), are sampled, so the estimate costs a bounded
/// fraction of the extraction. Deterministic: the same blocks and points for
/// any thread count.
constexpr std::size_t kNoiseMaxLeaves = 1024;

/// The blocks estimate_noise(tree, signing, blocks) reads, in its order:
/// every stride-th, the stride 1 for at most kNoiseMaxLeaves blocks (so
/// sampling a sample keeps it whole).
inline std::vector<openvdb::Coord> noise_sample(const std::vector<openvdb::Coord>& blocks) {
    const std::size_t stride = std::max<std::size_t>(1, (blocks.size() + kNoiseMaxLeaves - 1) / kNoiseMaxLeaves);
    std::vector<openvdb::Coord> out;
    for (std::size_t i = 0; i < blocks.size(); i += stride) out.push_back(blocks[i]);
    return out;
}

/// Each sampled block reads the points origin - 1 .. origin + 9.
inline openvdb::CoordBBox noise_block_points(const openvdb::Coord& origin) {
    return openvdb::CoordBBox(origin - openvdb::Coord(1), origin + openvdb::Coord(9));
}

template <class TreeT>
NoiseEstimate estimate_noise(const TreeT& tree, const Signing& signing, const std::vector<openvdb::Coord>& blocks) {
    constexpr int L = int(TreeT::LeafNodeType::DIM);
    const std::vector<openvdb::Coord> sample = noise_sample(blocks);
    std::vector<std::vector<double>> per_block(sample.size());
    tbb::parallel_for(std::size_t(0), sample.size(), [&](std::size_t i) {
        openvdb::tree::ValueAccessor<const TreeT, false> acc(tree);
        DenseBlock block;
        const openvdb::CoordBBox points = noise_block_points(sample[i]);
        fetch_block(acc, points.min(), points.dim().x(), signing, block);
        std::vector<double>& out = per_block[i];
        for (int x = 1; x <= L; ++x)
            for (int y = 1; y <= L; ++y)
                for (int z = 1; z <= L; ++z) {
                    const double v = block.at(x, y, z);
                    if (!block.on(x, y, z)) continue;
                    const bool crosses = (v < 0) != (block.at(x + 1, y, z) < 0) ||
                                         (v < 0) != (block.at(x, y + 1, z) < 0) ||
                                         (v < 0) != (block.at(x, y, z + 1) < 0);
                    if (!crosses || !all_active_around(block, x, y, z)) continue;
                    const double r = fit_residual_voxels(block, x, y, z);
                    if (r >= 0) out.push_back(r);
                }
    });
    std::vector<double> all;
    for (const auto& v : per_block) all.insert(all.end(), v.begin(), v.end());
    return median_noise(all);
}

}  // namespace pqdc::detail
