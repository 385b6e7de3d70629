#include "pqdc/components.hpp"

#include "pqdc/exceptions.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/measure.hpp"
#include "pqdc/procedural.hpp"

#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <random>

namespace {

using openvdb::Vec3d;

/// An axis-aligned cube of edge s at c as 6 quads (its diagonal is s sqrt(3)).
void add_cube(pqdc::Mesh& m, const Vec3d& c, double s) {
    const unsigned base = unsigned(m.points.size());
    for (int i = 0; i < 8; ++i)
        m.points.push_back(c + Vec3d(i & 1 ? s / 2 : -s / 2, i & 2 ? s / 2 : -s / 2, i & 4 ? s / 2 : -s / 2));
    for (const openvdb::Vec4I& q : {openvdb::Vec4I(0, 2, 3, 1), openvdb::Vec4I(4, 5, 7, 6), openvdb::Vec4I(0, 1, 5, 4),
                                    openvdb::Vec4I(2, 6, 7, 3), openvdb::Vec4I(0, 4, 6, 2), openvdb::Vec4I(1, 3, 7, 5)})
        m.quads.emplace_back(q[0] + base, q[1] + base, q[2] + base, q[3] + base);
}

}  // namespace

TEST_CASE("remove_small_components: threshold in voxels, order kept", "[components]") {
    pqdc::Mesh m;
    const double voxel = 0.5;
    add_cube(m, Vec3d(0, 0, 0), 0.5);   // diagonal 0.87 world = 1.73 voxels
    m.points.emplace_back(9, 9, 9);     // unreferenced: kept
    add_cube(m, Vec3d(5, 0, 0), 2.0);   // 6.93 voxels
    m.triangles.emplace_back(17, 18, 19);  // a triangle of the big cube's points joins it
    add_cube(m, Vec3d(0, 5, 0), 1.25);  // 4.33 voxels

    pqdc::ComponentFilterStats stats;
    const pqdc::Mesh out = pqdc::remove_small_components(m, voxel, {}, &stats);  // default: below 3.5 voxels
    CHECK(stats.components == 3);
    CHECK(stats.removed_components == 1);
    CHECK(stats.removed_faces == 6);
    CHECK(stats.removed_points == 8);
    CHECK(stats.largest_removed_diagonal_voxels == Approx(std::sqrt(3.0)));
    CHECK(stats.smallest_kept_diagonal_voxels == Approx(1.25 * std::sqrt(3.0) / voxel));
    REQUIRE(out.points.size() == m.points.size() - 8);
    CHECK(out.points[0] == Vec3d(9, 9, 9));
    CHECK(out.quads.size() == 12);
    REQUIRE(out.triangles.size() == 1);
    // Same faces in the same order, renumbered.
    for (std::size_t f = 0; f < out.quads.size(); ++f)
        for (int k = 0; k < 4; ++k) CHECK(out.quads[f][k] + 8 == m.quads[f + 6][k]);
    CHECK(out.triangles[0] == openvdb::Vec3I(9, 10, 11));
    CHECK(pqdc::measure_topology(out).connected_component_count == 2);
    CHECK(out.normals.empty());  // none given, none made

    // Normals stay with their points.
    pqdc::Mesh with_normals = m;
    for (std::size_t i = 0; i < m.points.size(); ++i) with_normals.normals.emplace_back(double(i), 0, 0);
    const pqdc::Mesh kept = pqdc::remove_small_components(with_normals, voxel);
    REQUIRE(kept.normals.size() == out.points.size());
    CHECK(kept.normals[0] == Vec3d(8, 0, 0));                     // the unreferenced point (9, 9, 9)
    CHECK(kept.normals.back() == Vec3d(double(m.points.size() - 1), 0, 0));

    pqdc::ComponentFilterOptions keep_all;
    keep_all.min_diagonal_voxels = 0;
    const pqdc::Mesh same = pqdc::remove_small_components(m, voxel, keep_all, &stats);
    CHECK(same.points == m.points);
    CHECK(same.quads == m.quads);
    CHECK(same.triangles == m.triangles);
    CHECK(stats.removed_components == 0);

    pqdc::ComponentFilterOptions big;
    big.min_diagonal_voxels = 5;  // the 4.33-voxel cube goes too
    CHECK(pqdc::remove_small_components(m, voxel, big).quads.size() == 6);
    big.min_diagonal_voxels = std::numeric_limits<double>::infinity();
    const pqdc::Mesh none = pqdc::remove_small_components(m, voxel, big);
    CHECK(none.face_count() == 0);
    CHECK(none.points.size() == 1);  // the unreferenced point

    pqdc::Mesh with_nan = m;
    with_nan.points[0][0] = std::numeric_limits<double>::quiet_NaN();  // a corner of the small cube
    CHECK(pqdc::remove_small_components(with_nan, voxel).quads.size() == 18);  // kept: its size is unknown

    CHECK_THROWS_AS(pqdc::remove_small_components(m, 0.0), pqdc::option_error);
    CHECK_THROWS_AS(pqdc::remove_small_components(m, std::numeric_limits<double>::infinity()), pqdc::option_error);
    pqdc::ComponentFilterOptions negative;
    negative.min_diagonal_voxels = -1;
    CHECK_THROWS_AS(pqdc::remove_small_components(m, voxel, negative), pqdc::option_error);
    negative.min_diagonal_voxels = std::numeric_limits<double>::quiet_NaN();
    CHECK_THROWS_AS(pqdc::remove_small_components(m, voxel, negative), pqdc::option_error);
    pqdc::Mesh few_normals = m;
    few_normals.normals.assign(3, openvdb::Vec3d(0, 0, 1));  // neither none nor one per point
    CHECK_THROWS_WITH(pqdc::remove_small_components(few_normals, voxel),
                      Catch::Contains("3 vertex normals for") && Catch::Contains("one normal per point"));
    m.triangles.emplace_back(0, 1, 99);
    CHECK_THROWS_AS(pqdc::remove_small_components(m, voxel), pqdc::input_error);
}

TEST_CASE("remove_small_components: noise islands go, the surface and a droplet stay", "[components]") {
    // A sphere of radius 10 voxels and a droplet of radius 1 voxel, sampled
    // with Gaussian noise of 0.3 voxel: the noise adds islands, the default
    // removes exactly those and keeps both real components.
    class TwoSpheres : public pqdc::ScalarField {
    public:
        double value(const Vec3d& p) const override {
            return std::min((p - Vec3d(0, 0, 0)).length() - 10.0, (p - Vec3d(14, 0, 0)).length() - 1.0);
        }
        Vec3d gradient(const Vec3d& p) const override {
            const Vec3d a = p - Vec3d(0, 0, 0), b = p - Vec3d(14, 0, 0);
            return a.length() - 10.0 < b.length() - 1.0 ? a.unitSafe() : b.unitSafe();
        }
        double lipschitz_bound() const override { return 1; }
        openvdb::BBoxd bounds() const override { return openvdb::BBoxd(Vec3d(-10, -10, -10), Vec3d(15, 10, 10)); }
    } field;
    pqdc::ProceduralSampling sampling;
    sampling.resolution = 25;  // voxel size 1
    openvdb::FloatGrid::Ptr grid = pqdc::sample_field(field, sampling);
    REQUIRE(grid->voxelSize()[0] == Approx(1.0));
    const pqdc::Mesh clean = pqdc::extract(*grid, pqdc::ExtractOptions{});
    REQUIRE(pqdc::measure_topology(clean).connected_component_count == 2);

    std::mt19937 rng(2);
    std::normal_distribution<float> noise(0.0f, 0.3f);
    for (auto it = grid->beginValueOn(); it; ++it) it.setValue(*it + noise(rng));
    // Without denoising (which already removes the islands: see [denoise]).
    pqdc::ExtractOptions raw;
    raw.denoise = pqdc::Denoise::off;
    raw.sigma_n = 0.1;
    raw.normals = pqdc::GridNormals::central;
    const pqdc::Mesh noisy = pqdc::extract(*grid, raw);
    const std::size_t before = pqdc::measure_topology(noisy).connected_component_count;
    INFO("components of the noisy mesh: " << before);
    REQUIRE(before > 2);
    pqdc::ComponentFilterStats stats;
    const pqdc::Mesh out = pqdc::remove_small_components(noisy, grid->voxelSize()[0], {}, &stats);
    CHECK(pqdc::measure_topology(out).connected_component_count == 2);
    CHECK(stats.smallest_kept_diagonal_voxels > 3.5);  // the droplet: about 2 sqrt(3) voxels
    CHECK(stats.largest_removed_diagonal_voxels < 3.5);
}
