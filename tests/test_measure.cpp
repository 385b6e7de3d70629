#include "pqdc/measure.hpp"

#include "pqdc/exceptions.hpp"

#include <catch2/catch.hpp>

#include <openvdb/tools/LevelSetSphere.h>
#include <tbb/global_control.h>

#include <cmath>
#include <cstring>
#include <random>

namespace {

using openvdb::Vec3d;

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

// Latitude-longitude sphere: triangle fans at the poles, quads between,
// outward counter-clockwise.
pqdc::Mesh uv_sphere(Vec3d center, double radius, int rings, int segments) {
    pqdc::Mesh m;
    const double pi = 3.14159265358979323846;
    m.points.push_back(center + Vec3d(0, 0, radius));
    for (int i = 1; i < rings; ++i) {
        const double t = pi * i / rings;
        for (int j = 0; j < segments; ++j) {
            const double f = 2 * pi * j / segments;
            m.points.push_back(center + radius * Vec3d(std::sin(t) * std::cos(f), std::sin(t) * std::sin(f), std::cos(t)));
        }
    }
    m.points.push_back(center + Vec3d(0, 0, -radius));
    const unsigned south = unsigned(m.points.size() - 1);
    auto at = [&](int i, int j) { return unsigned(1 + (i - 1) * segments + (j % segments)); };
    for (int j = 0; j < segments; ++j) {
        m.triangles.emplace_back(0, at(1, j), at(1, j + 1));
        m.triangles.emplace_back(at(rings - 1, j), south, at(rings - 1, j + 1));
        for (int i = 1; i + 1 < rings; ++i) m.quads.emplace_back(at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
    }
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
    std::mt19937 rng(42);
    std::normal_distribution<double> jitter(0.0, 0.01);
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
