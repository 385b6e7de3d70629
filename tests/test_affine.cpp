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

}  // namespace

TEST_CASE("check_transform takes every non-singular affine map and refuses frustums", "[affine][transform]") {
    using pqdc::detail::check_transform;
    CHECK(!check_transform(*openvdb::math::Transform::createLinearTransform(scale_map(Vec3d(0.5, 1, 2))), "g").mirrored);
    CHECK(check_transform(*openvdb::math::Transform::createLinearTransform(general_map()), "g").mirrored);
    // Flat voxels OpenVDB still builds (its singularity test is absolute):
    // the third axis lies within 1e-13 of the plane of the first two.
    Mat4d flat = Mat4d::identity();
    flat.setRow(0, openvdb::Vec4d(1e6, 0, 0, 0));
    flat.setRow(1, openvdb::Vec4d(0, 1e6, 0, 0));
    flat.setRow(2, openvdb::Vec4d(1e6, 1e6, 1e-7, 0));
    try {
        check_transform(*openvdb::math::Transform::createLinearTransform(flat), "flat");
        FAIL("flat voxels accepted");
    } catch (const pqdc::input_error& e) {
        CHECK(std::string(e.what()).find("singular") != std::string::npos);
    }
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
    struct Error {
        double worst = 0, mean = 0, worst_normal_degrees = 0;
    };
    auto error = [&](pqdc::Mesh m, const openvdb::FloatGrid& grid) {
        Error e;
        for (const Vec3d& v : m.points) {
            const double d = std::abs((v - p.center).length() - p.radius);
            e.worst = std::max(e.worst, d);
            e.mean += d / double(m.points.size());
        }
        // Vertex normals are covectors: against the analytic normal.
        pqdc::compute_vertex_normals(m, grid);
        for (std::size_t i = 0; i < m.points.size(); ++i) {
            const double c = m.normals[i].dot((m.points[i] - p.center).unit());
            e.worst_normal_degrees = std::max(e.worst_normal_degrees, std::acos(std::min(1.0, c)) * 180 / M_PI);
        }
        return e;
    };
    // Peers measured here: cubic lattices with the same voxel count (edge 1)
    // and with the longest edge (2).
    const auto cubic1 = sample_affine(*field, scale_map(Vec3d(1.0)), 3.0);
    const auto cubic2 = sample_affine(*field, scale_map(Vec3d(2.0)), 6.0);
    const Error e1 = error(pqdc::extract(*cubic1, pqdc::ExtractOptions{}), *cubic1);
    const Error e2 = error(pqdc::extract(*cubic2, pqdc::ExtractOptions{}), *cubic2);
    const Mat4d map = scale_map(Vec3d(0.5, 1.0, 2.0));
    const auto grid = sample_affine(*field, map, 3 * largest_voxel_edge(map));
    const double volume = 4.0 / 3.0 * M_PI * std::pow(p.radius, 3);
    pqdc::AdaptiveOptions ao;
    ao.max_error_voxels = 0.05;
    for (bool adaptive : {false, true}) {
        INFO((adaptive ? "adaptive" : "uniform"));
        const pqdc::Mesh m = adaptive ? pqdc::extract_adaptive(*grid, ao) : pqdc::extract(*grid, pqdc::ExtractOptions{});
        require_watertight(m, "anisotropic sphere");
        CHECK(pqdc_test::signed_volume(m) == Approx(volume).epsilon(adaptive ? 0.02 : 0.01));
        const Error e = error(m, *grid);
        INFO("world distance worst " << e.worst << " mean " << e.mean << ", normals " << e.worst_normal_degrees
                                     << " deg; cubic edge 1: " << e1.worst << " / " << e1.mean << ", edge 2: "
                                     << e2.worst << " / " << e2.mean);
        CHECK(e.worst < 0.6 * e2.worst);
        if (!adaptive) CHECK(e.mean < e1.mean);
        CHECK(e.worst_normal_degrees < 3.0);
    }
}

TEST_CASE("a box on a sheared, rotated, mirrored, anisotropic lattice keeps its corners", "[affine]") {
    pqdc::BoxParams p;
    p.half_extents = Vec3d(2.4, 1.9, 1.5);
    const auto field = pqdc::make_rotated_box(p);
    const Mat4d map = scale_map(Vec3d(0.5)) * general_map();  // voxel edges 0.1 .. 0.4
    const double longest = largest_voxel_edge(map);
    pqdc::ExtractOptions o;
    o.sigma_n = 0.01;
    o.normals = pqdc::GridNormals::sharp;
    pqdc::AdaptiveOptions ao;
    ao.base = o;
    auto worst_corner = [&](const pqdc::Mesh& m) {
        double worst = 0;
        for (const Vec3d& c : pqdc_test::box_corners(p)) {
            double best = std::numeric_limits<double>::max();
            for (const Vec3d& v : m.points) best = std::min(best, (v - c).length());
            worst = std::max(worst, best);
        }
        return worst;
    };
    // The peer: the same box on a cubic lattice of the longest edge.
    const auto cubic = sample_affine(*field, scale_map(Vec3d(longest)), 3 * longest);
    const double cubic_worst = worst_corner(pqdc::extract(*cubic, o));
    const auto grid = sample_affine(*field, map, 3 * longest);
    const double volume = 8 * p.half_extents.x() * p.half_extents.y() * p.half_extents.z();
    for (bool adaptive : {false, true}) {
        INFO((adaptive ? "adaptive" : "uniform"));
        const pqdc::Mesh m = adaptive ? pqdc::extract_adaptive(*grid, ao) : pqdc::extract(*grid, o);
        require_watertight(m, "sheared box");
        CHECK(pqdc_test::signed_volume(m) == Approx(volume).epsilon(0.01));
        const double worst = worst_corner(m);
        INFO("worst corner " << worst << " world units; cubic lattice of edge " << longest << ": " << cubic_worst);
        CHECK(worst < 0.4 * longest);
        CHECK(worst < 2.5 * cubic_worst);  // measured 2.0x: shear makes some index-space corners acute
    }
}
