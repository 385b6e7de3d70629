#include "lattice/noise_estimate.hpp"

namespace pqdc::detail {

double linear_fit_residual_voxels(const DenseBlock& b, int x, int y, int z) {
    // The 27 offsets are symmetric, so the fit decouples: mean, and per axis
    // sum(v * offset) / 18 (sum of offset^2 over the stencil).
    double sum = 0, sum_sq = 0, gx = 0, gy = 0, gz = 0;
    for (int i = -1; i <= 1; ++i)
        for (int j = -1; j <= 1; ++j)
            for (int k = -1; k <= 1; ++k) {
                const double v = b.at(x + i, y + j, z + k);
                sum += v;
                sum_sq += v * v;
                gx += v * i;
                gy += v * j;
                gz += v * k;
            }
    gx /= 18.0;
    gy /= 18.0;
    gz /= 18.0;
    const double g2 = gx * gx + gy * gy + gz * gz;
    const double ss = sum_sq - sum * sum / 27.0 - 18.0 * g2;
    if (!std::isfinite(ss) || !(g2 > 0)) return -1.0;
    return std::sqrt(std::max(0.0, ss) / 23.0 / g2);
}

NoiseEstimate median_noise(std::vector<double>& residuals) {
    NoiseEstimate e;
    e.samples = residuals.size();
    if (residuals.empty()) return e;
    const auto mid = residuals.begin() + std::ptrdiff_t(residuals.size() / 2);
    std::nth_element(residuals.begin(), mid, residuals.end());
    e.voxels = *mid;
    return e;
}

}  // namespace pqdc::detail
