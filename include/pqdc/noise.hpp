// Seeded i.i.d. Gaussian noise on the active values of a grid, for
// experiments and benchmarks on noisy input (pqdc-add-noise, bench_quality).
//
//   pqdc::NoiseSummary s = pqdc::add_gaussian_noise(*grid, 0.3 * grid->voxelSize()[0], 1);
//
// The noise of a voxel is a function of (seed, voxel coordinate) only, so
// the result is the same for any thread count and traversal order.
#pragma once

#include <openvdb/openvdb.h>

#include <cstdint>

namespace pqdc {

struct NoiseSummary {
    std::uint64_t voxels = 0;  ///< active voxels that received noise
    double sum_squares = 0;    ///< sum of the squared added values (grid value units squared)
};

/// Adds sigma * N(0, 1) to every active voxel (active tiles are split into
/// voxels first). sigma is in the grid's value units (world units for a
/// level set). Sums are taken per leaf in leaf order, so the summary is
/// deterministic too. Throws option_error, leaving the grid untouched, when
/// sigma is negative, NaN or infinite.
NoiseSummary add_gaussian_noise(openvdb::FloatGrid& grid, double sigma, std::uint64_t seed);
NoiseSummary add_gaussian_noise(openvdb::DoubleGrid& grid, double sigma, std::uint64_t seed);

}  // namespace pqdc
