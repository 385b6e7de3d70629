// Interior detection and input warnings (issue 12, items 1 and 2): density
// and CT grids of unknown class come out outward, the stats say which side
// was inside and why, and a fog volume meshed at its background is flagged.
#include "pqdc/adaptive.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/measure.hpp"
#include "pqdc/volume_io.hpp"

#include "mesh_checks.hpp"

#include <catch2/catch.hpp>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <openvdb/tools/LevelSetUtil.h>

#include <cmath>
#include <functional>
#include <limits>
#include <string>

using openvdb::Vec3d;

namespace {

struct Init {
    Init() { openvdb::initialize(); }
} init_openvdb;

/// An unknown-class grid with value v(r) (r = distance from the origin, in
/// voxels) active on every point of [-n, n]^3 and `background` elsewhere.
openvdb::FloatGrid::Ptr radial_grid(float background, int n, const std::function<double(double)>& v) {
    auto g = openvdb::FloatGrid::create(background);
    g->setName("density");
    auto acc = g->getAccessor();
    for (int i = -n; i <= n; ++i)
        for (int j = -n; j <= n; ++j)
            for (int k = -n; k <= n; ++k) acc.setValue(openvdb::Coord(i, j, k), float(v(std::sqrt(double(i * i + j * j + k * k)))));
    return g;
}

/// A CT-like density: 1000 HU inside a ball of radius 8, -1000 outside, a
/// smooth step of about 2 voxels, air (-1000) as the background.
openvdb::FloatGrid::Ptr ct_ball() {
    return radial_grid(-1000.f, 14, [](double r) { return 1000.0 * std::tanh((8.0 - r) / 1.5); });
}

std::string lower(std::string s) {
    for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
    return s;
}

}  // namespace

TEST_CASE("a CT-like density of unknown class comes out outward in both modes", "[interior]") {
    const auto g = ct_ball();
    pqdc::ExtractOptions o;
    o.isovalue = 300;
    const double r300 = 8.0 - 1.5 * std::atanh(0.3);
    const double expected = 4.0 / 3.0 * M_PI * r300 * r300 * r300;
    pqdc::ExtractStats s;
    const pqdc::Mesh m = pqdc::extract(*g, o, &s);
    pqdc_test::require_watertight(m, "CT ball, uniform");
    CHECK(pqdc_test::signed_volume(m) == Approx(expected).epsilon(0.03));
    CHECK(s.interior == "above");
    CHECK(s.interior_reason.find("background -1000 is below the isovalue 300") != std::string::npos);
    CHECK(s.warnings.empty());
    pqdc::AdaptiveOptions ao;
    ao.base = o;
    pqdc::AdaptiveStats as;
    const pqdc::Mesh a = pqdc::extract_adaptive(*g, ao, &as);
    pqdc_test::require_watertight(a, "CT ball, adaptive");
    CHECK(as.interior == "above");
    // An explicit choice wins and is reported as such (inside-out on purpose).
    o.interior = pqdc::Interior::below_isovalue;
    const pqdc::Mesh inverted = pqdc::extract(*g, o, &s);
    CHECK(pqdc_test::signed_volume(inverted) < 0);
    CHECK(s.interior == "below");
    CHECK(lower(s.interior_reason).find("interior option") != std::string::npos);
}

TEST_CASE("interior of unknown-class grids: background first, then the active boundary", "[interior]") {
    // An MRI-like "darker inside" grid: background above the isovalue, inside below.
    const auto dark = radial_grid(5.f, 12, [](double r) { return r < 7 ? 0.0 : 5.0; });
    pqdc::ExtractOptions o;
    o.isovalue = 2.5;
    CHECK(pqdc::choose_interior(*dark, o).side == pqdc::Interior::below_isovalue);
    CHECK(pqdc_test::signed_volume(pqdc::extract(*dark, o)) > 0);

    // Background equal to the isovalue: the boundary of the active box
    // decides. Values 8 - r: the box's boundary is below 0, so outside is
    // below and inside above.
    o.isovalue = 0;
    const auto peak = radial_grid(0.f, 12, [](double r) { return 8.0 - r; });
    const pqdc::InteriorChoice c = pqdc::choose_interior(*peak, o);
    CHECK(c.side == pqdc::Interior::above_isovalue);
    CHECK(c.reason.find("boundary") != std::string::npos);
    pqdc::ExtractStats s;
    const pqdc::Mesh m = pqdc::extract(*peak, o, &s);
    pqdc_test::require_watertight(m, "peak");
    CHECK(s.interior == "above");
    // The same with r - 8 (a distance field of unknown class): inside below.
    const auto well = radial_grid(0.f, 12, [](double r) { return r - 8.0; });
    CHECK(pqdc::choose_interior(*well, o).side == pqdc::Interior::below_isovalue);
    CHECK(pqdc_test::signed_volume(pqdc::extract(*well, o)) > 0);
    // A NaN background decides nothing either, and the reason says NaN (it
    // said "the background equals the isovalue").
    const auto nan_well = radial_grid(std::numeric_limits<float>::quiet_NaN(), 12, [](double r) { return r - 8.0; });
    const pqdc::InteriorChoice n = pqdc::choose_interior(*nan_well, o);
    CHECK(n.side == pqdc::Interior::below_isovalue);
    CHECK(n.reason.find("the background is NaN") != std::string::npos);

    // The grid class decides before the background.
    auto fog = radial_grid(0.f, 12, [](double r) { return r - 8.0; });
    fog->setGridClass(openvdb::GRID_FOG_VOLUME);
    CHECK(pqdc::choose_interior(*fog, o).side == pqdc::Interior::above_isovalue);
    CHECK(pqdc::choose_interior(*fog, o).reason.find("fog") != std::string::npos);
}

TEST_CASE("a fog volume meshed at its background value is flagged with advice", "[interior]") {
    auto fog = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(12.f, openvdb::Vec3f(0.3f), 1.f, 3.f);
    openvdb::tools::sdfToFogVolume(*fog);
    REQUIRE(fog->getGridClass() == openvdb::GRID_FOG_VOLUME);
    pqdc::ExtractOptions o;  // isovalue 0 = the fog's background
    pqdc::ExtractStats s;
    const pqdc::Mesh m = pqdc::extract(*fog, o, &s);
    REQUIRE(!m.empty());
    INFO("clamped " << s.clamped_vertices << " of " << s.vertices);
    CHECK(double(s.clamped_vertices) > 0.2 * double(s.vertices));  // the terraces the warning explains
    REQUIRE(s.warnings.size() == 1);
    CHECK(s.warnings[0].find("equals the background") != std::string::npos);
    CHECK(s.warnings[0].find("isovalue 0.5") != std::string::npos);  // halfway to the fog's 1
    CHECK(s.warnings[0].find("of the vertices (" + std::to_string(s.clamped_vertices)) != std::string::npos);
    pqdc::AdaptiveStats as;
    pqdc::extract_adaptive(*fog, pqdc::AdaptiveOptions{o}, &as);
    REQUIRE(as.warnings.size() == 1);
    // Adaptive clamps count finest cells, more than the mesh's vertices: named so.
    CHECK(as.vertices < as.active_cells);
    CHECK(as.warnings[0].find("of the finest cells' vertices (" + std::to_string(as.clamped_vertices) + " of " +
                              std::to_string(as.active_cells) + ")") != std::string::npos);

    // Just above the background: the surface still hugs the edge; the clamp
    // rule catches it (42% clamped, 98% of the vertices in edge cells).
    o.isovalue = 0.01;
    pqdc::extract(*fog, o, &s);
    REQUIRE(s.warnings.size() == 1);
    CHECK(s.warnings[0].find("edge of the active region") != std::string::npos);
    // At the advised level: no warning, few clamps.
    o.isovalue = 0.5;
    const pqdc::Mesh good = pqdc::extract(*fog, o, &s);
    pqdc_test::require_watertight(good, "fog at 0.5");
    CHECK(s.warnings.empty());
    CHECK(double(s.clamped_vertices) < 0.01 * double(s.vertices));
}

TEST_CASE("ordinary level sets get no warning, even where many vertices clamp", "[interior]") {
    // The shipped armadillo clamps 7% of its vertices (thin features), all
    // inside the band: no warning.
    const pqdc::LoadedGrid armadillo = pqdc::read_scalar_grid(std::string(PQDC_SOURCE_DIR) + "/volumes/armadillo.vdb");
    pqdc::ExtractStats as;
    pqdc::extract(*armadillo.grid, pqdc::ExtractOptions{}, &as);
    CHECK(double(as.clamped_vertices) > 0.05 * double(as.vertices));
    CHECK(as.warnings.empty());
    const auto sphere = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(20.f, openvdb::Vec3f(0.3f), 1.f, 3.f);
    for (double sigma : {0.0, 0.1}) {
        pqdc::ExtractOptions o;
        o.sigma_n = sigma;
        pqdc::ExtractStats s;
        pqdc::extract(*sphere, o, &s);
        INFO("sigma_n " << sigma << ": clamped " << s.clamped_vertices << " of " << s.vertices);
        CHECK(double(s.clamped_vertices) < 0.01 * double(s.vertices));
        CHECK(s.warnings.empty());
        CHECK(s.interior == "below");
    }
}
