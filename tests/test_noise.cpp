#include "cli_runner.hpp"
#include "pqdc/noise.hpp"

#include <catch2/catch.hpp>

#include <nlohmann/json.hpp>
#include <openvdb/io/File.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <tbb/global_control.h>

#include <cmath>
#include <filesystem>

TEST_CASE("add_gaussian_noise: seeded, per voxel, any thread count", "[noise]") {
    const openvdb::FloatGrid::Ptr clean = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(10.0f, {0, 0, 0}, 0.5f);
    const double sigma = 0.3 * 0.5;
    openvdb::FloatGrid::Ptr a = clean->deepCopy(), b = clean->deepCopy(), c = clean->deepCopy();
    const pqdc::NoiseSummary sa = pqdc::add_gaussian_noise(*a, sigma, 7);
    pqdc::NoiseSummary sb;
    {
        tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
        sb = pqdc::add_gaussian_noise(*b, sigma, 7);
    }
    pqdc::add_gaussian_noise(*c, sigma, 8);
    REQUIRE(sa.voxels == clean->activeVoxelCount());
    CHECK(sa.voxels == sb.voxels);
    CHECK(sa.sum_squares == sb.sum_squares);
    // The measured rms is sigma (thousands of samples: within 5%), the mean about 0.
    CHECK(std::sqrt(sa.sum_squares / double(sa.voxels)) == Approx(sigma).epsilon(0.05));
    double sum = 0;
    std::size_t same_as_b = 0, same_as_c = 0, n = 0;
    openvdb::FloatGrid::ConstAccessor ca = clean->getConstAccessor(), ab = b->getConstAccessor(), ac = c->getConstAccessor();
    for (auto it = a->cbeginValueOn(); it; ++it, ++n) {
        const double noise = double(*it) - double(ca.getValue(it.getCoord()));
        sum += noise;
        same_as_b += *it == ab.getValue(it.getCoord());
        same_as_c += *it == ac.getValue(it.getCoord());
    }
    CHECK(std::abs(sum / double(n)) < 0.05 * sigma);
    CHECK(same_as_b == n);   // same seed: the same value at every voxel
    CHECK(same_as_c < n / 100);  // another seed: other values

    openvdb::DoubleGrid::Ptr d = openvdb::DoubleGrid::create(0.0);
    d->tree().addTile(1, openvdb::Coord(0), 0.0, true);  // an active tile is voxelized first
    const pqdc::NoiseSummary sd = pqdc::add_gaussian_noise(*d, 1.0, 1);
    CHECK(sd.voxels == 512);
    CHECK(d->tree().leafCount() == 1);

    // Refused, the grid untouched: NaN or infinity would replace every value.
    for (const double bad : {std::nan(""), HUGE_VAL, -HUGE_VAL, -0.1}) {
        INFO("sigma " << bad);
        openvdb::FloatGrid::Ptr e = clean->deepCopy();
        CHECK_THROWS_WITH(pqdc::add_gaussian_noise(*e, bad, 1), Catch::Contains("sigma must be a finite number >= 0"));
        CHECK(e->tree().hasSameTopology(clean->tree()));
        CHECK(e->tree().leafCount() == clean->tree().leafCount());
        std::size_t changed = 0;
        for (auto it = e->cbeginValueOn(); it; ++it) changed += !(*it == ca.getValue(it.getCoord()));
        CHECK(changed == 0);
    }
}

#ifdef PQDC_ADD_NOISE_PATH
TEST_CASE("pqdc-add-noise: its JSON summary, the noisy file, and clear errors", "[noise]") {
    openvdb::initialize();
    pqdc_test::ScratchDir dir("add_noise_cli");
    const std::string in = dir.path("sphere.vdb"), out = dir.path("noisy.vdb"), fog = dir.path("fog.vdb");
    openvdb::FloatGrid::Ptr sdf = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(8.0f, {0, 0, 0}, 0.5f);
    sdf->setName("sdf");
    openvdb::io::File(in).write({sdf});
    openvdb::FloatGrid::Ptr density = sdf->deepCopy();
    density->setGridClass(openvdb::GRID_FOG_VOLUME);
    density->setName("density");
    openvdb::io::File(fog).write({density});
    auto run = [](std::vector<std::string> args) {
        pqdc_test::RunSpec spec;
        spec.args = std::move(args);
        return pqdc_test::run_program(PQDC_ADD_NOISE_PATH, spec);
    };

    const auto info = run({in, "--info"});
    REQUIRE(info.exit_code == 0);
    const nlohmann::json i = nlohmann::json::parse(info.out);
    CHECK(i["grid"] == "sdf");
    CHECK(i["grid_class"] == "level set");
    CHECK(i["voxel_size"] == 0.5);
    CHECK(i["active_voxels"] == sdf->activeVoxelCount());
    CHECK_FALSE(i.contains("output"));

    const auto noisy = run({in, "-o", out, "--sigma-voxels", "0.3", "--seed", "5"});
    REQUIRE(noisy.exit_code == 0);
    const nlohmann::json n = nlohmann::json::parse(noisy.out);
    CHECK(n["output"] == out);
    CHECK(n["seed"] == 5);
    CHECK(n["noise_sigma_world"] == Approx(0.15));
    CHECK(n["noise_sigma_voxels"] == Approx(0.3));
    CHECK(n["noised_voxels"] == sdf->activeVoxelCount());
    CHECK(n["noise_rms_world"].get<double>() == Approx(0.15).epsilon(0.1));
    CHECK(std::filesystem::exists(out));

    // A fog volume's values are no distances: --sigma-voxels is refused, nothing written.
    const std::string refused = dir.path("refused.vdb");
    const auto wrong = run({fog, "-o", refused, "--sigma-voxels", "0.3"});
    CHECK(wrong.exit_code == 1);
    CHECK_THAT(wrong.err, Catch::Contains("'density'") && Catch::Contains("--sigma-value"));
    CHECK_FALSE(std::filesystem::exists(refused));
    const auto both = run({in, "-o", refused, "--sigma-voxels", "0.3", "--sigma-value", "1"});
    CHECK(both.exit_code == 2);
    CHECK_THAT(both.err, Catch::Contains("exactly one of --sigma-voxels and --sigma-value"));
    // Noise beyond float's range was stored as infinities, with exit 0.
    const auto huge = run({in, "-o", refused, "--sigma-value", "1e40"});
    CHECK(huge.exit_code == 2);
    CHECK_THAT(huge.err, Catch::Contains("beyond the range of the float values of grid 'sdf'"));
    CHECK_FALSE(std::filesystem::exists(refused));
    // Given in voxels, the message names that option (it named --sigma-value).
    const auto huge_voxels = run({in, "-o", refused, "--sigma-voxels", "1e40"});
    CHECK(huge_voxels.exit_code == 2);
    CHECK_THAT(huge_voxels.err, Catch::StartsWith("pqdc-add-noise: --sigma-voxels 1e+40 (") &&
                                    Catch::Contains("in world units) reaches beyond the range"));
    CHECK_FALSE(std::filesystem::exists(refused));
    // A fog volume's noise has value units, not voxels.
    const auto fog_noise = run({fog, "-o", refused, "--sigma-value", "0.1"});
    REQUIRE(fog_noise.exit_code == 0);
    CHECK(nlohmann::json::parse(fog_noise.out)["noise_sigma_voxels"].is_null());
}
#endif
