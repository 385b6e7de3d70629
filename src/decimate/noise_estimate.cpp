// The input's vertex noise, for sigma_position_auto.
//
// Trettner & Kobbelt (EG 2020, section 4.2) state the probabilistic
// quadrics' sigma as the standard deviation of the input's positions; a
// fixed default is right for one kind of input only (bench_decimate: 0.1
// voxel rounds clean CAD edges at low budgets, and is half the noise of a
// scanned surface). The estimate: with i.i.d. noise of deviation s along the
// normals, a vertex's offset from the centroid of its k one-ring neighbours,
// along its normal, has deviation s sqrt(1 + 1/k); its median absolute value
// is 0.6745 times that. The median ignores the minority of vertices on
// sharp edges and corners, whose offsets are geometry, not noise; curvature
// adds about (edge length)^2 / (2 radius), 0.0125 voxel on a sphere of
// radius 40 voxels, under the floor below.

#include "decimate_internal.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

namespace pqdc::decimate_detail {

double estimate_vertex_noise_voxels(const WorkMesh& m) {
    std::vector<double> offsets;  // per movable vertex, scaled to the noise's deviation
    offsets.reserve(m.pos.size());
    for (std::uint32_t v = 0; v < m.pos.size(); ++v) {
        const std::size_t k = m.fan_size(v);  // a closed fan has as many neighbours as faces
        if (m.locked[v] || k < 3) continue;
        const vec n = vertex_normal(m, v);
        if (!(length(n) > 0)) continue;
        vec centroid{};
        for (std::size_t i = 0; i < k; ++i) {
            const Tri& t = m.tris[m.fan_of(v)[i]];
            for (std::uint32_t w : t)
                if (w != v) centroid += m.pos[w];  // every neighbour twice: two faces each
        }
        centroid = centroid / double(2 * k);
        const double offset = std::abs(dot(m.pos[v] - centroid, n)) / m.voxel;
        offsets.push_back(offset / std::sqrt(1.0 + 1.0 / double(k)));
    }
    if (offsets.empty()) return 0;
    auto mid = offsets.begin() + std::ptrdiff_t(offsets.size() / 2);
    std::nth_element(offsets.begin(), mid, offsets.end());
    return *mid / 0.6745;
}

double sigma_position_for_noise(double noise_voxels) {
    // Measured on bench_decimate's inputs at 1-20% budgets: clean box and
    // sphere were best at 0.01-0.03, 0.3-voxel noise at 0.2-0.3 (0.2 at the
    // lowest budgets, where approximation error dominates).
    constexpr double kFloor = 0.02, kFactor = 0.7;
    return std::max(kFloor, kFactor * noise_voxels);
}

}  // namespace pqdc::decimate_detail
