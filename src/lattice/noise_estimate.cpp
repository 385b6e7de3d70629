#include "lattice/noise_estimate.hpp"

namespace pqdc::detail {

double fit_residual_voxels(const DenseBlock& b, int x, int y, int z) {
    // Least squares over the 27 points with the basis 1, x, y, z, xy, yz,
    // zx, x^2 - 2/3, y^2 - 2/3, z^2 - 2/3, orthogonal on {-1, 0, 1}^3 (norms
    // 27, 18, 12, 6): the residual is what the ten projections leave.
    double sum = 0, sum_sq = 0, g[3] = {0, 0, 0}, mixed[3] = {0, 0, 0}, square[3] = {0, 0, 0};
    for (int i = -1; i <= 1; ++i)
        for (int j = -1; j <= 1; ++j)
            for (int k = -1; k <= 1; ++k) {
                const double v = b.at(x + i, y + j, z + k);
                const int o[3] = {i, j, k};
                sum += v;
                sum_sq += v * v;
                for (int a = 0; a < 3; ++a) {
                    g[a] += v * o[a];
                    mixed[a] += v * o[a] * o[(a + 1) % 3];
                    square[a] += v * (o[a] * o[a] - 2.0 / 3.0);
                }
            }
    double ss = sum_sq - sum * sum / 27.0, g2 = 0;
    for (int a = 0; a < 3; ++a) {
        ss -= g[a] * g[a] / 18.0 + mixed[a] * mixed[a] / 12.0 + square[a] * square[a] / 6.0;
        g2 += (g[a] / 18.0) * (g[a] / 18.0);
    }
    if (!std::isfinite(ss) || !(g2 > 0)) return -1.0;
    return std::sqrt(std::max(0.0, ss) / 17.0 / g2);
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
