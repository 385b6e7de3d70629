#include <pqdc/extract.hpp>
#include <pqdc/quadric.hpp>
#include <pqdc/version.hpp>

#include <openvdb/tools/LevelSetSphere.h>

#include <cstdio>

// The installed version header: what a caller tests to use newer API.
#if !defined(PQDC_VERSION) || PQDC_VERSION < PQDC_VERSION_OF(0, 1, 0)
#error "pqdc/version.hpp: PQDC_VERSION is missing or below 0.1.0"
#endif
static_assert(PQDC_VERSION == PQDC_VERSION_MAJOR * 10000 + PQDC_VERSION_MINOR * 100 + PQDC_VERSION_PATCH);

int main() {
    openvdb::initialize();
    const auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(5.0f, openvdb::Vec3f(0.0f), 0.5f);
    pqdc::ExtractOptions options;
    options.sigma_n = 0.1;
    const pqdc::Mesh mesh = pqdc::extract(*grid, options);
    const auto q = pqdc::quadricd::probabilistic_plane({0, 0, 0}, {0, 0, 1}, 0.0, 0.1);
    std::printf("consumer: pqdc %s, %zu points, %zu triangles, Q(0) = %g\n", pqdc::version_string, mesh.points.size(),
                mesh.triangles.size(), q({0, 0, 0}));
    return mesh.triangles.empty() ? 1 : 0;
}
