#include "lattice/auto_parameters.hpp"

#include <algorithm>
#include <cmath>

namespace pqdc::detail {

ChosenParameters choose_parameters(const ExtractOptions& given, const NoiseEstimate& noise, FieldKind kind) {
    const bool analytic = kind == FieldKind::analytic;
    ChosenParameters c;
    c.options = given;
    c.noise = noise;
    const bool noisy = !analytic && noise.voxels >= kNoisyVoxels;
    const bool denoise = given.denoise == Denoise::on || (given.denoise == Denoise::automatic && noisy);
    if (denoise) {
        c.smooth_field = !analytic;
        c.filter.radius = 1;
        c.filter.normal_width = kNormalWidth;
    }
    // On the smoothed field the one-sided (ENO) stencils see little noise
    // and keep edges; on a noisy field without denoising they would
    // amplify it.
    if (given.normals == GridNormals::automatic) {
        if (noisy && !denoise) c.options.normals = GridNormals::least_squares;
        else c.options.normals = kind == FieldKind::density ? GridNormals::central : GridNormals::sharp;
    }
    if (given.sigma_n == sigma_n_auto) c.options.sigma_n = noisy ? kSigmaNoisy : kSigmaClean;
    return c;
}

void record_parameters(const ChosenParameters& chosen, FieldKind kind, ExtractStats& stats) {
    const bool analytic = kind == FieldKind::analytic;
    stats.noise_voxels = chosen.noise.voxels;
    stats.noise_samples = chosen.noise.samples;
    stats.sigma_n = chosen.options.sigma_n;
    stats.denoise_radius = chosen.filter.radius;
    if (analytic) stats.gradient = "analytic";
    else if (chosen.options.normals == GridNormals::sharp) stats.gradient = "sharp";
    else if (chosen.options.normals == GridNormals::least_squares) stats.gradient = "least_squares";
    else stats.gradient = "central";
}

}  // namespace pqdc::detail
