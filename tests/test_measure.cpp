#include "random.hpp"
#include "test_meshes.hpp"
#include "pqdc/measure.hpp"

#include "pqdc/exceptions.hpp"

#include <catch2/catch.hpp>

#include <openvdb/tools/LevelSetSphere.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <utility>
#include <vector>

namespace {

using openvdb::Vec3d;
using pqdc_test::uv_sphere;

// Test fields with known answers, independent of the library's procedural
// fields so these tests only exercise the measures.
class PlaneField : public pqdc::ScalarField {  // f = z
public:
    double value(const Vec3d& p) const override { return p[2]; }
    Vec3d gradient(const Vec3d&) const override { return Vec3d(0, 0, 1); }
    double lipschitz_bound() const override { return 1; }
    openvdb::BBoxd bounds() const override { return openvdb::BBoxd(Vec3d(-1, -1, -1e-3), Vec3d(1, 1, 1e-3)); }
};

class SphereSdf : public pqdc::ScalarField {  // |p - c| - r, exact distance
public:
    SphereSdf(Vec3d c, double r) : c_(c), r_(r) {}
    double value(const Vec3d& p) const override { return (p - c_).length() - r_; }
    Vec3d gradient(const Vec3d& p) const override {
        const Vec3d d = p - c_;
        const double l = d.length();
        return l > 0 ? d / l : Vec3d(0.0);
    }
    double lipschitz_bound() const override { return 1; }
    openvdb::BBoxd bounds() const override { return openvdb::BBoxd(c_ - Vec3d(r_), c_ + Vec3d(r_)); }

private:
    Vec3d c_;
    double r_;
};

class QuadraticSphere : public pqdc::ScalarField {  // |p|^2 - r^2: same surface, not a distance
public:
    explicit QuadraticSphere(double r) : r_(r) {}
    double value(const Vec3d& p) const override { return p.lengthSqr() - r_ * r_; }
    Vec3d gradient(const Vec3d& p) const override { return 2.0 * p; }
    double lipschitz_bound() const override { return 4 * r_; }
    openvdb::BBoxd bounds() const override { return openvdb::BBoxd(Vec3d(-r_), Vec3d(r_)); }

private:
    double r_;
};

// (|p| - 1)^3: the unit sphere, with a gradient that vanishes on it. Newton
// converges only linearly there and |f| / |grad f| is a third of the true
// distance. Lipschitz bound valid for |p| < 2.5.
class CubedSphere : public pqdc::ScalarField {
public:
    double value(const Vec3d& p) const override { return std::pow(p.length() - 1.0, 3); }
    Vec3d gradient(const Vec3d& p) const override {
        const double r = p.length();
        return r > 0 ? p * (3.0 * (r - 1.0) * (r - 1.0) / r) : Vec3d(0.0);
    }
    double lipschitz_bound() const override { return 3.0 * 1.5 * 1.5; }
    openvdb::BBoxd bounds() const override { return openvdb::BBoxd(Vec3d(-1.0), Vec3d(1.0)); }
};

class AxisBoxSdf : public pqdc::ScalarField {  // exact SDF of [-h, h]
public:
    explicit AxisBoxSdf(Vec3d h) : h_(h) {}
    double value(const Vec3d& p) const override {
        Vec3d q;
        for (int k = 0; k < 3; ++k) q[k] = std::abs(p[k]) - h_[k];
        const Vec3d qp(std::max(q[0], 0.0), std::max(q[1], 0.0), std::max(q[2], 0.0));
        return qp.length() + std::min(std::max(q[0], std::max(q[1], q[2])), 0.0);
    }
    Vec3d gradient(const Vec3d& p) const override {
        const double e = 1e-7;
        Vec3d g;
        for (int k = 0; k < 3; ++k) {
            Vec3d a = p, b = p;
            a[k] += e;
            b[k] -= e;
            g[k] = (value(a) - value(b)) / (2 * e);
        }
        return g;
    }
    double lipschitz_bound() const override { return 1; }
    openvdb::BBoxd bounds() const override { return openvdb::BBoxd(-h_, h_); }

private:
    Vec3d h_;
};

// Axis-aligned cube [-1,1]^3 as 6 outward counter-clockwise quads.
pqdc::Mesh cube() {
    pqdc::Mesh m;
    for (int i = 0; i < 8; ++i) m.points.emplace_back(i & 1 ? 1 : -1, i & 2 ? 1 : -1, i & 4 ? 1 : -1);
    m.quads = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
    return m;
}

pqdc::Mesh tetrahedron() {
    pqdc::Mesh m;
    m.points = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    m.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
    return m;
}

}  // namespace

TEST_CASE("topology of closed, oriented meshes", "[measure]") {
    for (const pqdc::Mesh& m : {cube(), tetrahedron(), uv_sphere(Vec3d(0.0), 1.0, 8, 12)}) {
        const pqdc::TopologyReport r = pqdc::measure_topology(m);
        CHECK(r.closed());
        CHECK(r.edge_manifold());
        CHECK(r.vertex_manifold());
        CHECK(r.consistently_oriented());
        CHECK(r.degenerate_face_count == 0);
        CHECK(r.connected_component_count == 1);
        CHECK(r.euler_characteristic == 2);
        CHECK(r.unreferenced_vertex_count == 0);
    }
    const pqdc::TopologyReport c = pqdc::measure_topology(cube());
    CHECK(c.edge_count == 12);
    CHECK(c.quad_count == 6);
    CHECK(c.vertex_count == 8);
}

TEST_CASE("topology detects flips, holes, bowties and non-manifold edges", "[measure]") {
    SECTION("one flipped face") {
        pqdc::Mesh m = tetrahedron();
        std::swap(m.triangles[3][0], m.triangles[3][1]);
        const auto r = pqdc::measure_topology(m);
        CHECK_FALSE(r.consistently_oriented());
        CHECK(r.inconsistent_edge_count == 3);
        CHECK(r.closed());
        CHECK(r.edge_manifold());
    }
    SECTION("one face removed") {
        pqdc::Mesh m = tetrahedron();
        m.triangles.pop_back();
        const auto r = pqdc::measure_topology(m);
        CHECK_FALSE(r.closed());
        CHECK(r.boundary_edge_count == 3);
        CHECK(r.consistently_oriented());
        CHECK(r.vertex_manifold());  // a disk: the boundary vertices are open fans
        CHECK(r.euler_characteristic == 1);
    }
    SECTION("bowtie vertex") {
        pqdc::Mesh m;
        m.points = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {-1, 0, 0}, {-1, -1, 0}};
        m.triangles = {{0, 1, 2}, {0, 3, 4}};
        const auto r = pqdc::measure_topology(m);
        CHECK_FALSE(r.vertex_manifold());
        CHECK(r.non_manifold_vertex_count == 1);
        CHECK(r.edge_manifold());
        CHECK(r.connected_component_count == 1);
    }
    SECTION("two cubes touching at a vertex (closed but not vertex-manifold)") {
        pqdc::Mesh m = cube();
        const pqdc::Mesh other = cube();
        // Second cube shifted so its corner 0 coincides with the first's corner 7.
        std::vector<unsigned> remap(8);
        for (unsigned i = 0; i < 8; ++i) {
            if (i == 0) {
                remap[i] = 7;
            } else {
                remap[i] = unsigned(m.points.size());
                m.points.push_back(other.points[i] + Vec3d(2, 2, 2));
            }
        }
        for (const auto& q : other.quads) m.quads.emplace_back(remap[q[0]], remap[q[1]], remap[q[2]], remap[q[3]]);
        const auto r = pqdc::measure_topology(m);
        CHECK(r.closed());
        CHECK(r.edge_manifold());
        CHECK(r.non_manifold_vertex_count == 1);
        CHECK(r.connected_component_count == 1);
    }
    SECTION("three faces on one edge") {
        pqdc::Mesh m;
        m.points = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}};
        m.triangles = {{0, 1, 2}, {1, 0, 3}, {0, 1, 4}};
        const auto r = pqdc::measure_topology(m);
        CHECK_FALSE(r.edge_manifold());
        CHECK(r.non_manifold_edge_count == 1);
        CHECK(r.boundary_edge_count == 6);
    }
    SECTION("degenerate faces, non-finite points, components, unreferenced vertices") {
        pqdc::Mesh m = tetrahedron();
        const unsigned base = unsigned(m.points.size());
        for (const Vec3d& p : tetrahedron().points) m.points.push_back(p + Vec3d(5, 0, 0));
        for (const auto& t : tetrahedron().triangles) m.triangles.emplace_back(t[0] + base, t[1] + base, t[2] + base);
        m.points.emplace_back(0, 0, std::nan(""));     // unreferenced, non-finite
        m.points.emplace_back(2, 0, 0);                // collinear with points 0 and 1
        m.triangles.emplace_back(0, 1, 9);             // zero area
        m.triangles.emplace_back(2, 2, 3);             // repeated index
        const auto r = pqdc::measure_topology(m);
        CHECK(r.degenerate_face_count == 2);
        CHECK(r.non_finite_point_count == 1);
        CHECK(r.unreferenced_vertex_count == 1);
        CHECK(r.connected_component_count == 2);
    }
    SECTION("index out of range") {
        pqdc::Mesh m = tetrahedron();
        m.triangles.emplace_back(0, 1, 4);
        CHECK_THROWS_AS(pqdc::measure_topology(m), pqdc::input_error);
        CHECK_THROWS_AS(pqdc::measure_triangle_quality(m), pqdc::input_error);
    }
}

TEST_CASE("triangle quality: min angles", "[measure]") {
    pqdc::Mesh m;
    const double h = std::sqrt(3.0) / 2;
    m.points = {{0, 0, 0}, {1, 0, 0}, {0.5, h, 0}};
    m.triangles = {{0, 1, 2}};
    auto q = pqdc::measure_triangle_quality(m);
    CHECK(q.triangle_count == 1);
    CHECK(q.min_angle_mean_degrees == Approx(60).epsilon(1e-12));
    CHECK(q.min_angle_p05_degrees == Approx(60).epsilon(1e-12));
    CHECK(q.fraction_below_10_degrees == 0);

    // A unit square quad splits into two right isosceles triangles.
    pqdc::Mesh sq;
    sq.points = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
    sq.quads = {{0, 1, 2, 3}};
    q = pqdc::measure_triangle_quality(sq);
    CHECK(q.triangle_count == 2);
    CHECK(q.min_angle_mean_degrees == Approx(45).epsilon(1e-12));

    // 19 equilateral triangles and one with a 5-degree corner.
    pqdc::Mesh mix = m;
    for (int i = 1; i < 19; ++i) mix.triangles.emplace_back(0, 1, 2);
    const double t = 5.0 * 3.14159265358979323846 / 180.0;
    mix.points.emplace_back(std::cos(t), std::sin(t), 0);  // angle at 0 between (1,0,0) and this = 5 degrees
    mix.triangles.emplace_back(0, 1, 3);
    q = pqdc::measure_triangle_quality(mix);
    CHECK(q.triangle_count == 20);
    CHECK(q.min_angle_min_degrees == Approx(5).epsilon(1e-9));
    CHECK(q.min_angle_p05_degrees == Approx(5).epsilon(1e-9));  // rank ceil(0.05 * 20) = 1
    CHECK(q.fraction_below_10_degrees == Approx(0.05));
    CHECK(q.min_angle_mean_degrees == Approx((19 * 60 + 5) / 20.0).epsilon(1e-9));

    // A triangle with a zero-length side has quality 0.
    pqdc::Mesh degenerate;
    degenerate.points = {{0, 0, 0}, {0, 0, 0}, {1, 0, 0}};
    degenerate.triangles = {{0, 1, 2}};
    CHECK(pqdc::measure_triangle_quality(degenerate).min_angle_min_degrees == 0);
    CHECK(pqdc::measure_triangle_quality(pqdc::Mesh{}).triangle_count == 0);
}

TEST_CASE("distance to a procedural field", "[measure]") {
    const Vec3d c(0.3, -0.2, 0.1);
    const pqdc::Mesh m = uv_sphere(c, 1.1, 16, 24);
    SECTION("signed distance field: exact") {
        const auto d = pqdc::measure_distance(m, SphereSdf(c, 1.0));
        CHECK(d.sample_count == m.points.size());
        CHECK(d.mean == Approx(0.1).margin(1e-12));
        CHECK(d.max == Approx(0.1).margin(1e-12));
        CHECK(d.rms == Approx(0.1).margin(1e-12));
        CHECK(d.mean_signed == Approx(0.1).margin(1e-12));
        CHECK(d.unreliable_count == 0);
        const auto inside = pqdc::measure_distance(uv_sphere(c, 0.95, 8, 8), SphereSdf(c, 1.0));
        CHECK(inside.mean_signed == Approx(-0.05).margin(1e-12));
    }
    SECTION("non-distance field: Newton projection recovers the true distance") {
        // |p|^2 - 1 at |p| = 1.1 gives a first-order estimate 0.21 / 2.2 = 0.0955,
        // the true distance is 0.1.
        const auto d = pqdc::measure_distance(uv_sphere(Vec3d(0.0), 1.1, 10, 10), QuadraticSphere(1.0));
        CHECK(d.mean == Approx(0.1).margin(1e-9));
        CHECK(d.max == Approx(0.1).margin(1e-9));
        CHECK(d.unreliable_count == 0);
        pqdc::FieldDistanceOptions one_step;
        one_step.newton_steps = 1;
        const auto rough = pqdc::measure_distance(uv_sphere(Vec3d(0.0), 1.1, 10, 10), QuadraticSphere(1.0), one_step);
        CHECK(rough.unreliable_count > 0);
    }
    SECTION("a gradient vanishing at the surface: the fallback finds the true distance") {
        for (double r : {1.3, 0.8}) {
            const auto d = pqdc::measure_distance(uv_sphere(Vec3d(0.0), r, 6, 8), CubedSphere());
            INFO("radius " << r);
            CHECK(d.unreliable_count == d.sample_count);  // Newton does not converge in 8 steps
            CHECK(d.mean == Approx(std::abs(r - 1.0)).epsilon(1e-6));
            CHECK(d.max == Approx(std::abs(r - 1.0)).epsilon(1e-6));
        }
    }
    SECTION("invalid options") {
        pqdc::FieldDistanceOptions bad;
        bad.newton_steps = 0;
        CHECK_THROWS_AS(pqdc::measure_distance(m, SphereSdf(c, 1.0), bad), pqdc::option_error);
        bad = {};
        bad.tolerance = -1;
        CHECK_THROWS_AS(pqdc::measure_distance(m, SphereSdf(c, 1.0), bad), pqdc::option_error);
    }
}

TEST_CASE("distance to a level-set grid", "[measure]") {
    const float voxel = 0.05f;
    auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(1.0f, openvdb::Vec3f(0.f), voxel, 3.0f);
    const auto near = pqdc::measure_distance(uv_sphere(Vec3d(0.0), 1.04, 12, 16), *grid);
    CHECK(near.mean == Approx(0.04).margin(0.003));  // trilinear interpolation error ~ h^2 / R
    CHECK(near.max == Approx(0.04).margin(0.005));
    CHECK(near.mean_signed > 0);
    CHECK(near.unreliable_count == 0);
    const auto far = pqdc::measure_distance(uv_sphere(Vec3d(0.0), 1.5, 6, 6), *grid);
    CHECK(far.unreliable_count == far.sample_count);
    grid->setGridClass(openvdb::GRID_FOG_VOLUME);
    CHECK_THROWS_AS(pqdc::measure_distance(uv_sphere(Vec3d(0.0), 1.0, 4, 4), *grid), pqdc::input_error);
}

TEST_CASE("normal deviation", "[measure]") {
    SECTION("a triangle tilted 30 degrees from the plane z = 0") {
        const double t = 30.0 * 3.14159265358979323846 / 180.0;
        pqdc::Mesh m;
        m.points = {{0, 0, 0}, {1, 0, 0}, {0, std::cos(t), std::sin(t)}};
        m.triangles = {{0, 1, 2}};
        for (auto s : {pqdc::NormalSampling::per_face, pqdc::NormalSampling::per_vertex}) {
            const auto d = pqdc::measure_normal_deviation(m, PlaneField(), s);
            CHECK(d.mean_degrees == Approx(30).epsilon(1e-9));
            CHECK(d.max_degrees == Approx(30).epsilon(1e-9));
        }
    }
    SECTION("cube against its box SDF: exact on faces, flipped faces read 180") {
        pqdc::Mesh m = cube();
        auto d = pqdc::measure_normal_deviation(m, AxisBoxSdf(Vec3d(1, 1, 1)), pqdc::NormalSampling::per_face);
        CHECK(d.sample_count == 6);
        CHECK(d.max_degrees == Approx(0).margin(1e-4));
        std::swap(m.quads[0][1], m.quads[0][3]);
        d = pqdc::measure_normal_deviation(m, AxisBoxSdf(Vec3d(1, 1, 1)), pqdc::NormalSampling::per_face);
        CHECK(d.max_degrees == Approx(180).margin(1e-4));
        CHECK(d.mean_degrees == Approx(30).margin(1e-4));
    }
    SECTION("a finer sphere has smaller normal error") {
        const SphereSdf field(Vec3d(0.0), 1.0);
        const auto coarse = pqdc::measure_normal_deviation(uv_sphere(Vec3d(0.0), 1.0, 8, 12), field);
        const auto fine = pqdc::measure_normal_deviation(uv_sphere(Vec3d(0.0), 1.0, 32, 48), field);
        const auto coarse_v = pqdc::measure_normal_deviation(uv_sphere(Vec3d(0.0), 1.0, 8, 12), field,
                                                             pqdc::NormalSampling::per_vertex);
        const auto fine_v = pqdc::measure_normal_deviation(uv_sphere(Vec3d(0.0), 1.0, 32, 48), field,
                                                           pqdc::NormalSampling::per_vertex);
        CHECK(fine.mean_degrees < coarse.mean_degrees);
        CHECK(fine.max_degrees < 10);
        CHECK(fine_v.mean_degrees < coarse_v.mean_degrees);
        CHECK(fine_v.max_degrees < 10);
        CHECK(fine_v.sample_count == uv_sphere(Vec3d(0.0), 1.0, 32, 48).points.size());
    }
    SECTION("zero-area faces are skipped") {
        pqdc::Mesh m;
        m.points = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}};
        m.triangles = {{0, 1, 2}};
        const auto d = pqdc::measure_normal_deviation(m, PlaneField());
        CHECK(d.sample_count == 0);
        CHECK(d.skipped_count == 1);
    }
}

TEST_CASE("measures do not depend on the thread count", "[measure]") {
    pqdc_test::Random rng(42);
    pqdc_test::Normal jitter{0.0, 0.01};
    pqdc::Mesh m = uv_sphere(Vec3d(0.0), 1.0, 60, 90);
    for (Vec3d& p : m.points)
        for (int k = 0; k < 3; ++k) p[k] += jitter(rng);
    const SphereSdf field(Vec3d(0.0), 1.0);
    auto run = [&](int threads) {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
        return pqdc::to_json(pqdc::measure_topology(m)) + pqdc::to_json(pqdc::measure_triangle_quality(m)) +
               pqdc::to_json(pqdc::measure_distance(m, field)) +
               pqdc::to_json(pqdc::measure_normal_deviation(m, field, pqdc::NormalSampling::per_vertex)) +
               pqdc::to_json(pqdc::measure_normal_deviation(m, field, pqdc::NormalSampling::per_face));
    };
    CHECK(run(1) == run(2));
}

TEST_CASE("to_json writes compact objects", "[measure]") {
    const std::string t = pqdc::to_json(pqdc::measure_topology(cube()));
    CHECK(t.front() == '{');
    CHECK(t.back() == '}');
    CHECK_THAT(t, Catch::Contains("\"closed\":true") && Catch::Contains("\"edge_count\":12") &&
                      Catch::Contains("\"euler_characteristic\":2"));
    pqdc::DistanceStats d;
    d.mean = 0.1;
    d.max = std::numeric_limits<double>::infinity();
    const std::string j = pqdc::to_json(d);
    CHECK_THAT(j, Catch::Contains("\"mean\":0.1,") && Catch::Contains("\"max\":null"));
}

TEST_CASE("measures without samples are null, and skipped points are counted", "[measure]") {
    // A point at 1e300 is finite, but its distance to the sphere is not
    // (1e300 squared): it is left out and counted, never a 0 that reads as a fit.
    pqdc::Mesh far;
    far.points = {{1e300, 0, 0}, {1e300, 1, 0}, {1e300, 0, 1}};
    far.triangles = {{0, 1, 2}};
    const pqdc::DistanceStats d = pqdc::measure_distance(far, SphereSdf(Vec3d(0.0), 1.0));
    CHECK(d.sample_count == 0);
    CHECK(d.skipped_count == 3);
    CHECK(std::isnan(d.mean));
    CHECK(std::isnan(d.rms));
    CHECK(std::isnan(d.max));
    CHECK(std::isnan(d.mean_signed));
    CHECK_THAT(pqdc::to_json(d), Catch::Contains("\"mean\":null,\"rms\":null,\"max\":null,\"mean_signed\":null") &&
                                     Catch::Contains("\"skipped_count\":3"));
    const pqdc::DistanceStats to_mesh = pqdc::measure_distance(far, cube());
    CHECK(to_mesh.sample_count + to_mesh.skipped_count == 3);

    const pqdc::NormalDeviation n = pqdc::measure_normal_deviation(pqdc::Mesh{}, PlaneField());
    CHECK(n.sample_count == 0);
    CHECK(std::isnan(n.mean_degrees));
    CHECK_THAT(pqdc::to_json(n), Catch::Contains("\"max_degrees\":null"));
    const pqdc::TriangleQuality q = pqdc::measure_triangle_quality(pqdc::Mesh{});
    CHECK(std::isnan(q.min_angle_p05_degrees));
    CHECK(std::isnan(q.fraction_below_10_degrees));
    CHECK_THAT(pqdc::to_json(q), Catch::Contains("\"min_angle_min_degrees\":null"));

    // Samples that are there are summarized as before.
    pqdc::Mesh near = far;
    near.points[0] = {2, 0, 0};
    const pqdc::DistanceStats one = pqdc::measure_distance(near, SphereSdf(Vec3d(0.0), 1.0));
    CHECK(one.sample_count == 1);
    CHECK(one.skipped_count == 2);
    CHECK(one.mean == Approx(1.0));
}

// ---------------------------------------------------------------- distance to a mesh

namespace {

using Soup = std::vector<std::array<Vec3d, 3>>;

/// Closest point by a different route than the library's Voronoi-region
/// walk: project onto the plane, keep the foot if it is inside all three
/// sides, else the nearest point of the three sides. A normal that is only
/// rounding noise (sine of the corner angle below 1e-12) has no plane.
double brute_triangle_distance(const Vec3d& p, const std::array<Vec3d, 3>& t) {
    const Vec3d& a = t[0];
    const Vec3d& b = t[1];
    const Vec3d& c = t[2];
    const Vec3d n = (b - a).cross(c - a);
    const double n2 = n.lengthSqr();
    if (n2 > 1e-24 * (b - a).lengthSqr() * (c - a).lengthSqr()) {
        const Vec3d q = p - n * (n.dot(p - a) / n2);
        if ((b - a).cross(q - a).dot(n) >= 0 && (c - b).cross(q - b).dot(n) >= 0 && (a - c).cross(q - c).dot(n) >= 0)
            return (p - q).length();
    }
    auto segment = [&](const Vec3d& u, const Vec3d& v) {
        const Vec3d uv = v - u;
        const double l2 = uv.lengthSqr();
        const double s = l2 > 0 ? std::clamp(uv.dot(p - u) / l2, 0.0, 1.0) : 0.0;
        return (p - (u + uv * s)).length();
    };
    return std::min({segment(a, b), segment(b, c), segment(c, a)});
}

double brute_distance(const Vec3d& p, const Soup& soup) {
    double best = std::numeric_limits<double>::infinity();
    for (const auto& t : soup) best = std::min(best, brute_triangle_distance(p, t));
    return best;
}

pqdc::Mesh mesh_of(const Soup& soup) {
    pqdc::Mesh m;
    for (const auto& t : soup) {
        const unsigned base = unsigned(m.points.size());
        m.points.insert(m.points.end(), t.begin(), t.end());
        m.triangles.emplace_back(base, base + 1, base + 2);
    }
    return m;
}

/// Triangles of every size in [0, 1]^3, some overlapping, plus exactly
/// degenerate ones (a repeated corner, three collinear corners).
Soup random_soup(pqdc_test::Random& rng, int count) {
    pqdc_test::UniformReal unit{0.0, 1.0}, offset{-1.0, 1.0};
    Soup soup;
    for (int i = 0; i < count; ++i) {
        const Vec3d center(unit(rng), unit(rng), unit(rng));
        const double size = std::pow(10.0, -2.5 + 2.5 * unit(rng));  // 0.003 .. 1
        std::array<Vec3d, 3> t;
        for (auto& v : t) v = center + Vec3d(offset(rng), offset(rng), offset(rng)) * size;
        soup.push_back(t);
    }
    soup.push_back({Vec3d(0.5, 0.5, 0.5), Vec3d(0.5, 0.5, 0.5), Vec3d(0.75, 0.25, 0.5)});
    soup.push_back({Vec3d(0.25, 0.5, 0.125), Vec3d(0.5, 1.0, 0.875), Vec3d(0.375, 0.75, 0.5)});  // collinear
    // Collinear up to rounding: a tiny, unreliable cross product.
    const Vec3d a(0.1, 0.7, 0.3), d(0.3, -0.2, 0.45);
    soup.push_back({a, a + d * 0.3, a + d * 0.8});
    soup.push_back({a + d * 0.9, a, a + d * 0.1});
    return soup;
}

/// Query points: a box around the soup, points on its triangles, and points
/// 1e2 to 1e6 away in every direction.
std::vector<Vec3d> random_queries(pqdc_test::Random& rng, const Soup& soup, int count) {
    pqdc_test::UniformReal around{-0.5, 1.5}, unit{0.0, 1.0};
    pqdc_test::Normal gauss;
    std::vector<Vec3d> points;
    for (int i = 0; i < count; ++i) points.emplace_back(around(rng), around(rng), around(rng));
    for (int i = 0; i < count / 4; ++i) {
        const auto& t = soup[std::size_t(rng.bits() % soup.size())];
        double u = unit(rng), v = unit(rng);
        if (u + v > 1) u = 1 - u, v = 1 - v;
        points.push_back(t[0] + (t[1] - t[0]) * u + (t[2] - t[0]) * v);
    }
    for (int i = 0; i < count / 4; ++i) {
        const Vec3d dir = Vec3d(gauss(rng), gauss(rng), gauss(rng)).unitSafe();
        points.push_back(Vec3d(0.5) + dir * std::pow(10.0, 2.0 + 4.0 * unit(rng)));
    }
    return points;
}

/// Generalized winding number of a closed triangle mesh around p (1 inside
/// a counter-clockwise outward mesh, 0 outside): solid angles, Van Oosterom
/// and Strackee.
double winding_number(const pqdc::Mesh& m, const Vec3d& p) {
    double sum = 0;
    auto add = [&](unsigned i, unsigned j, unsigned k) {
        const Vec3d a = m.points[i] - p, b = m.points[j] - p, c = m.points[k] - p;
        const double la = a.length(), lb = b.length(), lc = c.length();
        sum += 2 * std::atan2(a.dot(b.cross(c)), la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb);
    };
    for (const auto& t : m.triangles) add(t[0], t[1], t[2]);
    for (const auto& q : m.quads) {
        add(q[0], q[1], q[2]);
        add(q[0], q[2], q[3]);
    }
    return sum / (4 * 3.14159265358979323846);
}

/// Distance from p to a triangle in long double (64-bit mantissa): the
/// nearest point of the sides, or the foot on the plane when it is inside.
/// Accurate to about 1e-19 of the triangle's size for slivers down to a
/// thinness of about 1e-9, where double precision formulas fail first.
double long_double_triangle_distance(const Vec3d& pd, const std::array<Vec3d, 3>& t) {
    using L = long double;
    struct V {
        L x, y, z;
        V operator-(const V& o) const { return {x - o.x, y - o.y, z - o.z}; }
        V operator+(const V& o) const { return {x + o.x, y + o.y, z + o.z}; }
        V operator*(L s) const { return {x * s, y * s, z * s}; }
        L dot(const V& o) const { return x * o.x + y * o.y + z * o.z; }
        V cross(const V& o) const { return {y * o.z - z * o.y, z * o.x - x * o.z, x * o.y - y * o.x}; }
    };
    auto v = [](const Vec3d& d) { return V{d[0], d[1], d[2]}; };
    const V p = v(pd), a = v(t[0]), b = v(t[1]), c = v(t[2]);
    L best2 = std::numeric_limits<L>::infinity();
    V nearest{};
    for (const auto& [u, w] : {std::pair{a, b}, std::pair{b, c}, std::pair{c, a}}) {
        const V uw = w - u;
        const L l2 = uw.dot(uw);
        const L s = l2 > 0 ? std::clamp(uw.dot(p - u) / l2, L(0), L(1)) : L(0);
        const V q = u + uw * s;
        if ((p - q).dot(p - q) < best2) best2 = (p - q).dot(p - q), nearest = q;
    }
    const V n = (b - a).cross(c - a);
    if (n.dot(n) > 0 && n.dot((b - p).cross(c - p)) > 0 && n.dot((c - p).cross(a - p)) > 0 &&
        n.dot((a - p).cross(b - p)) > 0) {
        const L h = n.dot(p - nearest) / std::sqrt(n.dot(n));
        best2 = std::min(best2, h * h);
    }
    return double(std::sqrt(best2));
}

/// A closed star-shaped mesh: the uv sphere with every point moved along its
/// ray from the center by up to +-30%, so it has concave and convex parts but
/// no self-intersections.
pqdc::Mesh bumpy_sphere(pqdc_test::Random& rng, int rings, int segments) {
    pqdc_test::UniformReal scale{0.7, 1.3};
    pqdc::Mesh m = uv_sphere(Vec3d(0.0), 1.0, rings, segments);
    for (Vec3d& p : m.points) p *= scale(rng);
    return m;
}

}  // namespace

TEST_CASE("distance to a mesh equals brute force over all triangles, near and far", "[measure][mesh_distance]") {
    for (const std::uint32_t seed : {1u, 2u, 3u}) {
        pqdc_test::Random rng(seed);
        const Soup soup = random_soup(rng, 300);
        const pqdc::Mesh reference = mesh_of(soup);
        const std::vector<Vec3d> points = random_queries(rng, soup, 2000);
        const pqdc::MeshDistance distance(reference);
        pqdc::MeshDistanceOptions one, many;
        one.leaf_triangles = 1;
        many.leaf_triangles = 64;
        const pqdc::MeshDistance distance_one(reference, one), distance_many(reference, many);
        // The tree search must return the smallest of the per-triangle
        // distances exactly: compare with one single-triangle MeshDistance
        // per triangle.
        std::vector<pqdc::MeshDistance> singles;
        for (const auto& t : soup) singles.emplace_back(mesh_of({t}));
        double worst = 0;
        for (const Vec3d& p : points) {
            const double d = distance(p);
            const double expected = brute_distance(p, soup);
            worst = std::max(worst, std::abs(d - expected) / std::max(expected, 1.0));
            double smallest = std::numeric_limits<double>::infinity();
            for (const auto& s : singles) smallest = std::min(smallest, s(p));
            INFO("seed " << seed << " point " << p << " distance " << d << " brute force " << expected);
            REQUIRE(d == smallest);
            REQUIRE(distance_one(p) == d);
            REQUIRE(distance_many(p) == d);
            REQUIRE(std::abs(distance.signed_distance(p)) == d);
        }
        INFO("seed " << seed << ": worst relative difference from brute force " << worst);
        CHECK(worst <= 1e-12);
    }
}

TEST_CASE("distance to slivers stays at rounding level at any thinness", "[measure][mesh_distance]") {
    // Caps (third corner between the others) and needles (beyond them) of
    // size about 1, their third corner 10^-k off the line of the other two,
    // rotated so every corner takes every role; query points along the
    // sliver at distances from 1e-12 to 100.
    pqdc_test::Random rng(13);
    pqdc_test::UniformReal u{-1.0, 1.0}, unit{0.0, 1.0};
    for (int k = 0; k <= 17; ++k) {
        double worst = 0;
        for (int trial = 0; trial < 60; ++trial) {
            const Vec3d a(u(rng), u(rng), u(rng)), b = a + Vec3d(u(rng), u(rng), u(rng));
            const Vec3d across = (b - a).cross(Vec3d(u(rng), u(rng), u(rng))).unitSafe();
            const double along = trial % 2 ? unit(rng) : 1.0 + unit(rng);
            std::array<Vec3d, 3> t{a, b, a + (b - a) * along + across * std::pow(10.0, -k)};
            std::rotate(t.begin(), t.begin() + trial % 3, t.end());
            const pqdc::MeshDistance distance(mesh_of({t}));
            for (int i = 0; i < 100; ++i) {
                const Vec3d p = a + (b - a) * (1.5 * unit(rng) - 0.25) +
                                Vec3d(u(rng), u(rng), u(rng)) * std::pow(10.0, 2.0 - 14.0 * unit(rng));
                const double expected = long_double_triangle_distance(p, t);
                worst = std::max(worst, std::abs(distance(p) - expected) / std::max(expected, 1.0));
            }
        }
        INFO("thinness 1e-" << k << ": worst difference " << worst << " of max(distance, size)");
        CHECK(worst <= 1e-13);
    }
}

TEST_CASE("a quad reference measures as its two triangles 0-1-2 and 0-2-3", "[measure][mesh_distance]") {
    pqdc_test::Random rng(7);
    pqdc_test::UniformReal unit{0.0, 1.0}, jitter{-0.2, 0.2};
    pqdc::Mesh quads, triangles;
    for (int i = 0; i < 50; ++i) {  // non-planar quads
        const Vec3d o(unit(rng), unit(rng), unit(rng));
        const unsigned base = unsigned(quads.points.size());
        for (const Vec3d& c : {Vec3d(0, 0, 0), Vec3d(0.2, 0, 0), Vec3d(0.2, 0.2, 0), Vec3d(0, 0.2, 0)})
            quads.points.push_back(o + c + Vec3d(0, 0, jitter(rng)));
        quads.quads.emplace_back(base, base + 1, base + 2, base + 3);
        triangles.triangles.emplace_back(base, base + 1, base + 2);
        triangles.triangles.emplace_back(base, base + 2, base + 3);
    }
    triangles.points = quads.points;
    const pqdc::MeshDistance to_quads(quads), to_triangles(triangles);
    pqdc_test::UniformReal around{-0.5, 1.5};
    pqdc::Mesh probe;
    for (int i = 0; i < 2000; ++i) {
        const Vec3d p(around(rng), around(rng), around(rng));
        probe.points.push_back(p);
        INFO("point " << p);
        REQUIRE(to_quads(p) == to_triangles(p));
        REQUIRE(to_quads.signed_distance(p) == to_triangles.signed_distance(p));
    }
    CHECK(pqdc::to_json(pqdc::measure_distance(probe, quads)) ==
          pqdc::to_json(pqdc::measure_distance(probe, triangles)));
}

TEST_CASE("signed distance to a mesh: the cube's is the box SDF", "[measure][mesh_distance]") {
    const AxisBoxSdf box(Vec3d(1, 1, 1));
    pqdc::Mesh flipped = cube();
    for (auto& q : flipped.quads) std::swap(q[1], q[3]);
    const pqdc::MeshDistance to_cube(cube()), to_flipped(flipped);
    pqdc_test::Random rng(11);
    pqdc_test::UniformReal around{-3.0, 3.0}, near{-1.1, 1.1};
    std::vector<Vec3d> points;
    for (int i = 0; i < 3000; ++i) points.emplace_back(around(rng), around(rng), around(rng));
    // Close to the corners and edges, where a face normal alone gets the sign wrong.
    for (int i = 0; i < 3000; ++i) {
        Vec3d p(near(rng), near(rng), near(rng));
        p[i % 3] = p[i % 3] < 0 ? -1.0 - 0.05 * (p[i % 3] + 1.1) : 1.0 + 0.05 * (1.1 - p[i % 3]);
        points.push_back(p);
    }
    for (const Vec3d& p : points) {
        INFO("point " << p);
        REQUIRE(to_cube.signed_distance(p) == Approx(box.value(p)).margin(1e-12));
        REQUIRE(to_flipped.signed_distance(p) == -to_cube.signed_distance(p));
        REQUIRE(to_cube(p) == std::abs(to_cube.signed_distance(p)));
    }
}

TEST_CASE("signed distance to a mesh: negative exactly inside a closed bumpy mesh", "[measure][mesh_distance]") {
    for (const std::uint32_t seed : {5u, 6u}) {
        pqdc_test::Random rng(seed);
        const pqdc::Mesh m = bumpy_sphere(rng, 12, 16);
        const pqdc::TopologyReport topo = pqdc::measure_topology(m);
        REQUIRE((topo.closed() && topo.edge_manifold() && topo.consistently_oriented()));
        const pqdc::MeshDistance distance(m);
        pqdc_test::UniformReal around{-1.5, 1.5}, offset{-0.03, 0.03};
        std::vector<Vec3d> points;
        for (int i = 0; i < 3000; ++i) points.emplace_back(around(rng), around(rng), around(rng));
        // Near the vertices, where the nearest feature is often a vertex or
        // an edge and the fans' uneven angles (split quads) matter.
        for (int i = 0; i < 20000; ++i)
            points.push_back(m.points[rng.bits() % m.points.size()] + Vec3d(offset(rng), offset(rng), offset(rng)));
        int inside = 0, checked = 0;
        for (const Vec3d& p : points) {
            const double d = distance.signed_distance(p);
            if (std::abs(d) < 1e-9) continue;
            const double w = winding_number(m, p);
            INFO("seed " << seed << " point " << p << " signed distance " << d << " winding number " << w);
            REQUIRE((d < 0) == (w > 0.5));
            inside += d < 0;
            ++checked;
        }
        CHECK(inside > 3000);  // both sides were exercised
        CHECK(checked - inside > 3000);
    }
}

TEST_CASE("distance stats against a mesh", "[measure][mesh_distance]") {
    SECTION("a mesh against itself is at distance zero") {
        pqdc_test::Random rng(3);
        for (const pqdc::Mesh& m :
             {cube(), tetrahedron(), uv_sphere(Vec3d(0.0), 1.0, 12, 16), bumpy_sphere(rng, 20, 30)}) {
            const pqdc::DistanceStats d = pqdc::measure_distance(m, m);
            CHECK(d.sample_count == m.points.size());
            CHECK(d.max == 0);
            CHECK(d.mean_signed == 0);
            CHECK(d.unreliable_count == 0);
        }
    }
    SECTION("cube corners outside and a cube inside: known distances and signs") {
        pqdc::Mesh outer = cube(), inner = cube();
        for (Vec3d& p : outer.points) p *= 1.5;  // corners (1.5, 1.5, 1.5): sqrt(3) / 2 from the corner
        for (Vec3d& p : inner.points) p *= 0.5;  // 0.5 from three faces
        const auto o = pqdc::measure_distance(outer, cube());
        CHECK(o.sample_count == 8);
        CHECK(o.mean == Approx(std::sqrt(3.0) / 2).epsilon(1e-14));
        CHECK(o.max == Approx(std::sqrt(3.0) / 2).epsilon(1e-14));
        CHECK(o.mean_signed == Approx(std::sqrt(3.0) / 2).epsilon(1e-14));
        const auto i = pqdc::measure_distance(inner, cube());
        CHECK(i.mean == Approx(0.5).epsilon(1e-14));
        CHECK(i.rms == Approx(0.5).epsilon(1e-14));
        CHECK(i.mean_signed == Approx(-0.5).epsilon(1e-14));
        CHECK(i.unreliable_count == 0);
    }
    SECTION("non-finite vertices are skipped, as by the other overloads") {
        pqdc::Mesh m = cube();
        m.points.emplace_back(std::nan(""), 0, 0);
        m.points.emplace_back(0, std::numeric_limits<double>::infinity(), 0);
        const auto d = pqdc::measure_distance(m, cube());
        CHECK(d.sample_count == 8);
        CHECK(d.max == 0);
        const pqdc::MeshDistance distance(cube());
        CHECK(std::isnan(distance(m.points[8])));
        CHECK(std::isnan(distance.signed_distance(m.points[9])));
        CHECK(pqdc::measure_distance(pqdc::Mesh{}, cube()).sample_count == 0);
    }
}

TEST_CASE("distance to a mesh does not depend on the thread count", "[measure][mesh_distance]") {
    pqdc_test::Random rng(9);
    const pqdc::Mesh reference = bumpy_sphere(rng, 40, 60);
    pqdc::Mesh m = uv_sphere(Vec3d(0.05, -0.02, 0.01), 1.0, 80, 120);
    pqdc_test::Normal jitter{0.0, 0.05};
    for (Vec3d& p : m.points)
        for (int k = 0; k < 3; ++k) p[k] += jitter(rng);
    auto run = [&](int threads) {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
        return pqdc::to_json(pqdc::measure_distance(m, reference));
    };
    const std::string one = run(1);
    CHECK(one == run(4));
    CHECK(one == run(2));
    // Concurrent queries on one shared object (and on copies) match serial ones.
    const pqdc::MeshDistance distance(reference);
    const pqdc::MeshDistance copy = distance;
    std::vector<double> serial(m.points.size()), parallel(m.points.size()), copied(m.points.size());
    for (std::size_t i = 0; i < m.points.size(); ++i) serial[i] = distance.signed_distance(m.points[i]);
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 4);
    tbb::parallel_for(std::size_t(0), m.points.size(), [&](std::size_t i) {
        parallel[i] = distance.signed_distance(m.points[i]);
        copied[i] = copy.signed_distance(m.points[i]);
    });
    CHECK(parallel == serial);
    CHECK(copied == serial);
}

TEST_CASE("distance to a mesh: bad references and options", "[measure][mesh_distance]") {
    auto message = [](const pqdc::Mesh& reference, pqdc::MeshDistanceOptions options = {}) -> std::string {
        try {
            pqdc::MeshDistance d(reference, options);
        } catch (const pqdc::input_error& e) {
            return std::string("input_error: ") + e.what();
        } catch (const pqdc::option_error& e) {
            return std::string("option_error: ") + e.what();
        }
        return "no error";
    };
    pqdc::Mesh points_only = cube();
    points_only.quads.clear();
    const std::string no_faces = "input_error: reference mesh has no triangles or quads";
    CHECK_THAT(message(points_only), Catch::StartsWith(no_faces + " (8 points)"));
    CHECK_THAT(message(pqdc::Mesh{}), Catch::StartsWith(no_faces + " (0 points)"));

    pqdc::Mesh missing = tetrahedron();
    missing.triangles.emplace_back(0, 1, 7);
    CHECK(message(missing) == "input_error: reference mesh face 4 refers to vertex 7 but the mesh has only 4 points");
    pqdc::Mesh missing_quad = cube();
    missing_quad.quads[5][2] = 8;
    CHECK_THAT(message(missing_quad), Catch::Contains("reference mesh face 5 refers to vertex 8"));

    pqdc::Mesh nan_corner = tetrahedron();
    nan_corner.points[2][1] = std::nan("");
    CHECK_THAT(message(nan_corner), Catch::StartsWith("input_error: reference mesh point 2 (a corner of face 0) has "
                                                      "a NaN or infinite coordinate"));
    pqdc::Mesh unused_nan = tetrahedron();
    unused_nan.points.emplace_back(std::numeric_limits<double>::infinity(), 0, 0);  // used by no face: ignored
    CHECK(message(unused_nan) == "no error");

    pqdc::MeshDistanceOptions bad;
    bad.leaf_triangles = 0;
    CHECK(message(cube(), bad) == "option_error: MeshDistanceOptions::leaf_triangles = 0 is outside [1, 64]");
    bad.leaf_triangles = 65;
    CHECK_THAT(message(cube(), bad), Catch::StartsWith("option_error:"));
    CHECK_THROWS_AS(pqdc::measure_distance(cube(), points_only), pqdc::input_error);
    CHECK_THROWS_AS(pqdc::measure_distance(cube(), cube(), bad), pqdc::option_error);
}

TEST_CASE("normal deviation against a reference mesh", "[measure][mesh_distance]") {
    pqdc::Mesh cube;  // [-1, 1]^3, outward quads
    for (int i = 0; i < 8; ++i) cube.points.emplace_back(i & 1 ? 1 : -1, i & 2 ? 1 : -1, i & 4 ? 1 : -1);
    cube.quads = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
    const pqdc::MeshDistance reference(cube);
    CHECK(reference.nearest_face_normal(Vec3d(3, 0.2, 0.1)) == Vec3d(1, 0, 0));
    CHECK(reference.nearest_face_normal(Vec3d(0.1, 0.2, -0.9)) == Vec3d(0, 0, -1));
    CHECK(std::isnan(reference.nearest_face_normal(Vec3d(std::nan(""), 0, 0))[0]));

    // The cube turned 10 degrees about z and scaled by 1.2: its side faces'
    // normals are 10 degrees off the nearest reference face's, top and bottom 0.
    pqdc::Mesh turned = cube;
    const double a = 10.0 * M_PI / 180.0;
    for (Vec3d& p : turned.points) p = Vec3d(p[0] * std::cos(a) - p[1] * std::sin(a), p[0] * std::sin(a) + p[1] * std::cos(a), p[2]) * 1.2;
    const pqdc::NormalDeviation d = pqdc::measure_normal_deviation(turned, reference);
    CHECK(d.sample_count == 6);
    CHECK(d.skipped_count == 0);
    CHECK(d.max_degrees == Approx(10.0));
    CHECK(d.mean_degrees == Approx(40.0 / 6.0));

    // The prebuilt-tree overload gives the same numbers as the Mesh one.
    const pqdc::DistanceStats s1 = pqdc::measure_distance(turned, cube), s2 = pqdc::measure_distance(turned, reference);
    CHECK(s1.mean == s2.mean);
    CHECK(s1.mean_signed == s2.mean_signed);
    CHECK(s1.mean > 0.2);
}
