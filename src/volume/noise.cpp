// Seeded per-voxel Gaussian noise (include/pqdc/noise.hpp).
#include "pqdc/noise.hpp"

#include "pqdc/exceptions.hpp"

#include <openvdb/tree/LeafManager.h>

#include <cmath>
#include <sstream>
#include <vector>

namespace pqdc {

namespace {

std::uint64_t splitmix64(std::uint64_t x) {
    x += 0x9E3779B97F4A7C15ull;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
    return x ^ (x >> 31);
}

/// A standard normal sample that depends only on (seed, ijk): Box-Muller on
/// two uniforms hashed from the coordinate, so no RNG state is shared.
double gaussian_at(std::uint64_t seed, const openvdb::Coord& ijk) {
    std::uint64_t h = splitmix64(seed);
    for (int a = 0; a < 3; ++a) h = splitmix64(h ^ std::uint64_t(std::uint32_t(ijk[a])));
    const std::uint64_t h2 = splitmix64(h ^ 0xD1B54A32D192ED03ull);
    // 53-bit uniforms; u1 in (0, 1] keeps the log finite.
    const double u1 = (double(h >> 11) + 1.0) * 0x1.0p-53;
    const double u2 = double(h2 >> 11) * 0x1.0p-53;
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * M_PI * u2);
}

template <typename GridT>
NoiseSummary add_noise(GridT& grid, double sigma, std::uint64_t seed) {
    // NaN or infinity would replace every active value (and a negative
    // sigma is a caller's mistake, not another noise): refuse before any is touched.
    if (!(sigma >= 0.0) || !std::isfinite(sigma)) {
        std::ostringstream text;
        text << sigma;
        throw option_error("add_gaussian_noise: sigma must be a finite number >= 0 (the grid's value units), got " +
                           text.str());
    }
    using ValueT = typename GridT::ValueType;
    grid.tree().voxelizeActiveTiles();
    openvdb::tree::LeafManager<typename GridT::TreeType> leaves(grid.tree());
    std::vector<NoiseSummary> per_leaf(leaves.leafCount());
    leaves.foreach([&](typename GridT::TreeType::LeafNodeType& leaf, std::size_t index) {
        NoiseSummary s;
        for (auto it = leaf.beginValueOn(); it; ++it) {
            const double n = sigma * gaussian_at(seed, it.getCoord());
            it.setValue(ValueT(double(*it) + n));
            ++s.voxels;
            s.sum_squares += n * n;
        }
        per_leaf[index] = s;
    });
    NoiseSummary total;
    for (const NoiseSummary& s : per_leaf) {
        total.voxels += s.voxels;
        total.sum_squares += s.sum_squares;
    }
    return total;
}

}  // namespace

NoiseSummary add_gaussian_noise(openvdb::FloatGrid& grid, double sigma, std::uint64_t seed) {
    return add_noise(grid, sigma, seed);
}

NoiseSummary add_gaussian_noise(openvdb::DoubleGrid& grid, double sigma, std::uint64_t seed) {
    return add_noise(grid, sigma, seed);
}

}  // namespace pqdc
