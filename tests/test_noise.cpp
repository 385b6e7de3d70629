#include "pqdc/noise.hpp"

#include <catch2/catch.hpp>

#include <openvdb/tools/LevelSetSphere.h>
#include <tbb/global_control.h>

#include <cmath>

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
}
