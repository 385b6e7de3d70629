// Affine voxel-to-world maps (issue 12, item 3): anisotropic voxels, shear,
// rotation and mirror are meshed in index space and mapped exactly; normals
// transform as covectors; non-affine (frustum) and singular maps are refused.
#include "lattice/transform.hpp"

#include "pqdc/adaptive.hpp"
#include "pqdc/exceptions.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/measure.hpp"
#include "pqdc/procedural.hpp"
#include "pqdc/vertex_normals.hpp"

#include "mesh_checks.hpp"

#include <catch2/catch.hpp>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetUtil.h>
#include <openvdb/tools/SignedFloodFill.h>

#include <cmath>
#include <limits>
#include <string>

using openvdb::Mat4d;
using openvdb::Vec3d;
using pqdc_test::require_watertight;

namespace {

struct Init {
    Init() { openvdb::initialize(); }
} init_openvdb;

/// The field sampled at the lattice points of `map` (row-vector OpenVDB
/// convention) within `band` world units of its surface: a level set in
/// world units on an arbitrary affine lattice.
openvdb::FloatGrid::Ptr sample_affine(const pqdc::ScalarField& f, const Mat4d& map, double band) {
    auto xf = openvdb::math::Transform::createLinearTransform(map);
    auto grid = openvdb::FloatGrid::create(float(band));
    grid->setTransform(xf);
    grid->setGridClass(openvdb::GRID_LEVEL_SET);
    grid->setName("affine");
    openvdb::BBoxd world = f.bounds();
    world.expand(band);
    const openvdb::BBoxd index = xf->worldToIndex(world);
    const openvdb::Coord lo = openvdb::Coord::floor(index.min()) - openvdb::Coord(1),
                         hi = openvdb::Coord::ceil(index.max()) + openvdb::Coord(1);
    auto acc = grid->getAccessor();
    for (int i = lo.x(); i <= hi.x(); ++i)
        for (int j = lo.y(); j <= hi.y(); ++j)
            for (int k = lo.z(); k <= hi.z(); ++k) {
                const openvdb::Coord c(i, j, k);
                const double v = f.value(xf->indexToWorld(c));
                if (std::abs(v) < band) acc.setValue(c, float(v));
            }
    openvdb::tools::signedFloodFill(grid->tree());
    return grid;
}

Mat4d scale_map(const Vec3d& s) {
    Mat4d m = Mat4d::identity();
    m.preScale(s);
    return m;
}

/// Anisotropic scale, then shear, rotation, mirror and translation.
Mat4d general_map() {
    Mat4d m = Mat4d::identity();
    m.preScale(Vec3d(0.5, 1.0, 2.0) * 0.4);
    Mat4d shear = Mat4d::identity();
    shear(1, 0) = 0.3;  // row-vector maps: world x gains 0.3 * index y
    shear(2, 1) = -0.2;
    m = shear * m;
    Mat4d rot = Mat4d::identity();
    rot.setToRotation(Vec3d(1, 2, 3).unit(), 0.7);
    m = m * rot;
    m.postScale(Vec3d(1, -1, 1));  // mirror
    m.setTranslation(Vec3d(0.3, -0.2, 0.1));
    return m;
}

double largest_voxel_edge(const Mat4d& m) {
    const openvdb::Mat3d a = m.getMat3();
    return std::max({a.row(0).length(), a.row(1).length(), a.row(2).length()});
}

double smallest_voxel_edge(const Mat4d& m) {
    const openvdb::Mat3d a = m.getMat3();
    return std::min({a.row(0).length(), a.row(1).length(), a.row(2).length()});
}

}  // namespace

TEST_CASE("check_transform takes every non-singular affine map and refuses frustums", "[affine][transform]") {
    using pqdc::detail::check_transform;
    CHECK(!check_transform(*openvdb::math::Transform::createLinearTransform(scale_map(Vec3d(0.5, 1, 2))), "g").mirrored);
    CHECK(check_transform(*openvdb::math::Transform::createLinearTransform(general_map()), "g").mirrored);
    const auto frustum =
        openvdb::math::Transform::createFrustumTransform(openvdb::BBoxd(Vec3d(-10.0), Vec3d(10.0)), 0.5, 2.0, 1.0);
    try {
        check_transform(*frustum, "camera");
        FAIL("frustum accepted");
    } catch (const pqdc::input_error& e) {
        const std::string m = e.what();
        CHECK(m.find("grid 'camera'") != std::string::npos);
        CHECK(m.find("not affine") != std::string::npos);
        CHECK(m.find("resampleToMatch") != std::string::npos);
    }
}

TEST_CASE("a sphere on 0.5 x 1 x 2 voxels matches the analytic sphere in world space", "[affine]") {
    pqdc::SphereParams p;
    p.center = Vec3d(0.3, -0.7, 1.1);
    p.radius = 6.0;
    const auto field = pqdc::make_sphere(p);
    const Mat4d map = scale_map(Vec3d(0.5, 1.0, 2.0));
    const auto grid = sample_affine(*field, map, 3 * largest_voxel_edge(map));
    const double volume = 4.0 / 3.0 * M_PI * std::pow(p.radius, 3);
    pqdc::AdaptiveOptions ao;
    ao.max_error_voxels = 0.05;
    for (bool adaptive : {false, true}) {
        INFO((adaptive ? "adaptive" : "uniform"));
        pqdc::Mesh m = adaptive ? pqdc::extract_adaptive(*grid, ao) : pqdc::extract(*grid, pqdc::ExtractOptions{});
        require_watertight(m, "anisotropic sphere");
        double worst = 0;
        for (const Vec3d& v : m.points) worst = std::max(worst, std::abs((v - p.center).length() - p.radius));
        INFO("worst vertex distance " << worst << " world units (voxel edges 0.5, 1, 2)");
        CHECK(worst < (adaptive ? 0.05 : 0.02));
        CHECK(pqdc_test::signed_volume(m) == Approx(volume).epsilon(adaptive ? 0.02 : 0.01));
        // Vertex normals are covectors: against the analytic normal.
        pqdc::compute_vertex_normals(m, *grid);
        double worst_angle = 0;
        for (std::size_t i = 0; i < m.points.size(); ++i) {
            const Vec3d exact = (m.points[i] - p.center).unit();
            worst_angle = std::max(worst_angle, std::acos(std::min(1.0, m.normals[i].dot(exact))) * 180 / M_PI);
        }
        INFO("worst normal " << worst_angle << " degrees");
        CHECK(worst_angle < 3.0);
    }
}

TEST_CASE("a box on a sheared, rotated, mirrored, anisotropic lattice keeps its corners", "[affine]") {
    pqdc::BoxParams p;
    p.half_extents = Vec3d(2.4, 1.9, 1.5);
    const auto field = pqdc::make_rotated_box(p);
    const Mat4d map = general_map();
    const double h = smallest_voxel_edge(map);
    const auto grid = sample_affine(*field, map, 3 * largest_voxel_edge(map));
    pqdc::ExtractOptions o;
    o.sigma_n = 0.01;
    o.normals = pqdc::GridNormals::sharp;
    pqdc::AdaptiveOptions ao;
    ao.base = o;
    const double volume = 8 * p.half_extents.x() * p.half_extents.y() * p.half_extents.z();
    for (bool adaptive : {false, true}) {
        INFO((adaptive ? "adaptive" : "uniform"));
        const pqdc::Mesh m = adaptive ? pqdc::extract_adaptive(*grid, ao) : pqdc::extract(*grid, o);
        require_watertight(m, "sheared box");
        CHECK(pqdc_test::signed_volume(m) == Approx(volume).epsilon(0.01));
        double worst = 0;
        for (const Vec3d& c : pqdc_test::box_corners(p)) {
            double best = std::numeric_limits<double>::max();
            for (const Vec3d& v : m.points) best = std::min(best, (v - c).length());
            worst = std::max(worst, best);
        }
        INFO("worst corner " << worst / h << " of the shortest voxel edge " << h);
        CHECK(worst < 0.1 * h);
    }
}
