// Stage "choose parameters": the automatic settings of ExtractOptions
// (sigma_n_auto, GridNormals::automatic, Denoise::automatic) made concrete
// from the volume's estimated noise, one rule for both extractors.
//
// The rule, measured with bench/bench_quality (README, "Noisy volumes"):
//   clean (noise < kNoisyVoxels): sharp (ENO) gradients for distance
//     fields (central for fog volumes), no filter, sigma_n 0.1: distance
//     fields keep their edges and corners;
//   noisy: the feature-preserving smoothed field (smooth_field.hpp), sharp
//     gradients on it, the bilateral quadric filter (uniform/place_vertices.hpp)
//     and sigma_n 0.25. Over noise 0.1-0.3 voxel the measures varied little
//     with sigma_n in [0.15, 0.4] (smaller: sharper edges, larger: smoother
//     faces); 0.25 meets both. normal_width 0.05 beat 0.1 and 0.2 on every
//     measure but edge error (+0.01 voxel).
#pragma once

#include "lattice/interior.hpp"
#include "lattice/noise_estimate.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/stats.hpp"

#include <openvdb/openvdb.h>

namespace pqdc::detail {

/// Noise, in voxels, from which a volume counts as noisy: clean distance
/// fields estimate 0.005-0.02, a fog volume's 3-voxel ramp about 0.07 (its
/// clamped ends), 0.1 voxel of added noise 0.1.
inline constexpr double kNoisyVoxels = 0.08;
inline constexpr double kSigmaClean = 0.1;
inline constexpr double kSigmaNoisy = 0.25;
inline constexpr double kNormalWidth = 0.05;

/// Denoising strength (uniform/place_vertices.hpp); radius 0 = off.
struct QuadricFilter {
    int radius = 0;             ///< cells: 0 (off) or 1 (the 3x3x3 neighbourhood filtered_quadric sums)
    double normal_width = 0.05;  ///< 1 - cos of the normal deviation that divides a weight by e
};

struct ChosenParameters {
    ExtractOptions options;  ///< the given options with sigma_n and normals made concrete
    QuadricFilter filter;
    bool smooth_field = false;  ///< mesh the smoothed field (smooth_field.hpp)
    NoiseEstimate noise;
};

/// What kind of field the crossings come from.
enum class FieldKind {
    distance,  ///< level sets and unknown classes: one-sided stencils keep their edges
    density,   ///< fog volumes: ramps clamped at both ends, where one-sided stencils see false kinks
    analytic,  ///< procedural fields: exact crossings and normals, never noisy
};

ChosenParameters choose_parameters(const ExtractOptions& given, const NoiseEstimate& noise, FieldKind kind);

/// FieldKind of a grid: inside above the isovalue (fog volumes, CT and
/// other densities) means a density; so does a distance field on non-cubic
/// voxels, whose index-space field is not one (one-sided stencils measured
/// worse there: 0.29 vs 0.12 world worst error on a 0.5 x 1 x 2 sphere).
inline FieldKind field_kind(const Signing& signing, bool cubic_voxels) {
    return signing.sign < 0 || !cubic_voxels ? FieldKind::density : FieldKind::distance;
}

/// Writes the estimate and the chosen values into stats.
void record_parameters(const ChosenParameters& chosen, FieldKind kind, ExtractStats& stats);

}  // namespace pqdc::detail
