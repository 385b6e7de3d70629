#include <pqdc/extract.hpp>
#include <pqdc/quadric.hpp>

#include <openvdb/tools/LevelSetSphere.h>

#include <cstdio>

int main() {
    openvdb::initialize();
    const auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(5.0f, openvdb::Vec3f(0.0f), 0.5f);
    pqdc::ExtractOptions options;
    options.sigma_n = 0.1;
    const pqdc::Mesh mesh = pqdc::extract(*grid, options);
    const auto q = pqdc::quadricd::probabilistic_plane({0, 0, 0}, {0, 0, 1}, 0.0, 0.1);
    std::printf("consumer: %zu points, %zu triangles, Q(0) = %g\n", mesh.points.size(), mesh.triangles.size(), q({0, 0, 0}));
    return mesh.triangles.empty() ? 1 : 0;
}
