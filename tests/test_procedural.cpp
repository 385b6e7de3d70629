// Tests for include/pqdc/procedural.hpp: field values and analytic gradients,
// Lipschitz and bounds guarantees, determinism, parameter validation, and the
// sampler's promise that every lattice cell with a sign change has all eight
// corners active.

#include "random.hpp"

#include "pqdc/exceptions.hpp"
#include "pqdc/procedural.hpp"

#include <catch2/catch.hpp>
#include <openvdb/openvdb.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <vector>

namespace {

using openvdb::Vec3d;

struct NamedField {
    std::string name;
    std::shared_ptr<pqdc::ScalarField> field;
};

/// The fields under test: defaults plus variants that stress one ingredient
/// (single rough octave, strong noise, a cut sphere overlapping the center,
/// an off-center box rotated about a skew axis).
std::vector<NamedField> fields_under_test()
{
    std::vector<NamedField> out;
    out.push_back({"sphere", pqdc::make_procedural("sphere")});
    out.push_back({"box", pqdc::make_procedural("box")});
    out.push_back({"figure3", pqdc::make_procedural("figure3")});

    pqdc::SphereParams sp;
    sp.center = Vec3d(0.3, -1.2, 2.5);
    sp.radius = 0.37;
    out.push_back({"sphere off-center", pqdc::make_sphere(sp)});

    pqdc::BoxParams bp;
    bp.center = Vec3d(-0.4, 0.9, 0.2);
    bp.half_extents = Vec3d(0.2, 0.8, 0.05);
    bp.axis = Vec3d(-0.3, 0.1, 0.7);
    bp.angle_degrees = 137.0;
    out.push_back({"box thin skew", pqdc::make_rotated_box(bp)});

    pqdc::Figure3Params one;
    one.octaves = 1;
    one.noise_amplitude = 0.3;
    one.noise_frequency = 2.5;
    one.cut_radius = 0.0;
    one.seed = 7;
    out.push_back({"figure3 one octave, no cut", pqdc::make_figure3(one)});

    pqdc::Figure3Params rough;
    rough.octaves = 6;
    rough.lacunarity = 2.3;
    rough.gain = 0.6;
    rough.noise_amplitude = 0.15;
    rough.cut_center = Vec3d(0.1, 0.0, 0.2);
    rough.cut_radius = 0.5;
    rough.seed = 123456789u;
    out.push_back({"figure3 rough, deep cut", pqdc::make_figure3(rough)});
    return out;
}

openvdb::BBoxd expanded(const openvdb::BBoxd& b, double fraction)
{
    const Vec3d pad = (b.max() - b.min()) * fraction;
    return openvdb::BBoxd(b.min() - pad, b.max() + pad);
}

}  // namespace

TEST_CASE("procedural: analytic gradient matches central differences", "[procedural]")
{
    pqdc_test::Random rng(20240601);
    for (const NamedField& nf : fields_under_test()) {
        INFO(nf.name);
        const pqdc::ScalarField& f = *nf.field;
        const openvdb::BBoxd box = expanded(f.bounds(), 0.2);
        const double eps = 1e-6 * (box.max() - box.min()).length();
        int checked = 0;
        for (int i = 0; i < 3000; ++i) {
            const Vec3d p = rng.in_box(box);
            Vec3d fd;
            for (int a = 0; a < 3; ++a) {
                Vec3d e(0.0);
                e[a] = eps;
                fd[a] = (f.value(p + e) - f.value(p - e)) / (2.0 * eps);
            }
            const Vec3d g = f.gradient(p);
            INFO("p = " << p << " analytic " << g << " finite difference " << fd);
            // Kinks (box edges/medial surfaces, the figure3 crease) are
            // measure-zero; a random point within eps of one is a 1e-5 event
            // per point, so every point is checked.
            REQUIRE((g - fd).length() <= 1e-5 * f.lipschitz_bound());
            ++checked;
        }
        CHECK(checked == 3000);
    }
}

TEST_CASE("procedural: Lipschitz bound holds on random point pairs", "[procedural]")
{
    pqdc_test::Random rng(77);
    for (const NamedField& nf : fields_under_test()) {
        INFO(nf.name);
        const pqdc::ScalarField& f = *nf.field;
        const double L = f.lipschitz_bound();
        const openvdb::BBoxd box = expanded(f.bounds(), 0.1);
        const double diag = (box.max() - box.min()).length();
        double worst_ratio = 0.0;
        // Pair distances from 1e-7 to 1 of the diagonal: short pairs catch
        // value jumps (a kernel too wide for the simplex would jump at the
        // simplex faces), long pairs the global behaviour.
        for (int i = 0; i < 40000; ++i) {
            const Vec3d a = rng.in_box(box);
            Vec3d dir = rng.in_box(openvdb::BBoxd(Vec3d(-1.0), Vec3d(1.0)));
            if (dir.length() < 1e-3) continue;  // direction only; resampled by the next iteration
            dir.normalize();
            const double dist = diag * std::pow(10.0, -7.0 + 7.0 * static_cast<double>(i % 1000) / 999.0);
            const Vec3d b = a + dir * dist;
            const double ratio = std::fabs(f.value(a) - f.value(b)) / (b - a).length();
            worst_ratio = std::max(worst_ratio, ratio);
        }
        INFO("worst |f(a)-f(b)|/|a-b| = " << worst_ratio << ", bound " << L);
        CHECK(worst_ratio <= L * (1.0 + 1e-9));
    }
}

TEST_CASE("procedural: gradient magnitude never exceeds the Lipschitz bound, which is near tight", "[procedural]")
{
    // For a piecewise C1 field the best Lipschitz constant is sup |grad f|.
    // With one octave, frequency 1 and amplitude 1 around a sphere centered
    // at the origin, grad f - p/|p| is the noise gradient and lipschitz_bound()
    // - 1 the certified noise gradient bound. Sampling finds ~0.85 of it, so
    // a looser bound (e.g. the naive sum over four kernels, 3.4x) fails here.
    pqdc::Figure3Params p;
    p.octaves = 1;
    p.noise_amplitude = 1.0;
    p.noise_frequency = 1.0;
    p.radius = 40.0;
    p.cut_radius = 0.0;
    for (std::uint32_t seed : {1u, 2u, 3u}) {
        p.seed = seed;
        INFO("seed " << seed);
        const auto f = pqdc::make_figure3(p);
        const double noise_bound = f->lipschitz_bound() - 1.0;
        pqdc_test::Random rng(seed);
        const openvdb::BBoxd box(Vec3d(-30.0), Vec3d(30.0));
        double max_slope = 0.0, max_noise_slope = 0.0;
        for (int i = 0; i < 400000; ++i) {
            const Vec3d x = rng.in_box(box);
            const Vec3d g = f->gradient(x);
            max_slope = std::max(max_slope, g.length());
            max_noise_slope = std::max(max_noise_slope, (g - x.unitSafe()).length());
        }
        INFO("max |grad f| = " << max_slope << ", max |grad noise| = " << max_noise_slope << ", noise bound "
                               << noise_bound);
        CHECK(max_slope <= f->lipschitz_bound());
        CHECK(max_noise_slope <= noise_bound);
        CHECK(max_noise_slope >= noise_bound / 1.3);
    }
}

namespace {

/// Proves sup_{x in box} F(x) <= target by branch and bound, given that F is
/// Lipschitz with constant lipschitz: a cube is done once F(center) plus
/// lipschitz times its half-diagonal is at most target. Returns false if
/// that needs cubes smaller than min_half (the claim is then in doubt).
template <typename Function>
bool certify_sup(const Function& F, double lipschitz, const openvdb::BBoxd& box, double target, double min_half,
                 double* largest_seen)
{
    struct Cube {
        Vec3d center;
        double half;
    };
    std::vector<Cube> stack;
    const double start_half = 0.05;
    for (double x = box.min()[0] + start_half; x - start_half < box.max()[0]; x += 2 * start_half)
        for (double y = box.min()[1] + start_half; y - start_half < box.max()[1]; y += 2 * start_half)
            for (double z = box.min()[2] + start_half; z - start_half < box.max()[2]; z += 2 * start_half)
                stack.push_back({Vec3d(x, y, z), start_half});
    *largest_seen = 0.0;
    while (!stack.empty()) {
        const Cube c = stack.back();
        stack.pop_back();
        const double f = F(c.center);
        *largest_seen = std::max(*largest_seen, f);
        if (f + lipschitz * std::sqrt(3.0) * c.half <= target) continue;
        if (c.half < min_half) return false;
        const double q = 0.5 * c.half;
        for (int k = 0; k < 8; ++k) {
            stack.push_back({c.center + Vec3d((k & 1) ? q : -q, (k & 2) ? q : -q, (k & 4) ? q : -q), q});
        }
    }
    return true;
}

}  // namespace

TEST_CASE("procedural: certificate for the simplex noise kernel bounds", "[procedural]")
{
    // src/procedural/procedural.cpp bounds |noise| and |grad noise| by sums over the
    // four corners of the simplex holding x of
    //   value:    t^4 |d|                      t = 0.5 - |d|^2, d = x - corner
    //   gradient: phi(s) = max(t^4, |t^3 (t - 8 s)|),  s = |d|^2
    // and claims sup sum <= 0.00984 (value) and <= 0.0746 (gradient); the
    // noise scale and the Lipschitz bound are built on these two numbers.
    // Prove both over one simplex (all others are congruent to it).
    const double r2 = 0.5, g3 = 1.0 / 6.0;
    std::array<Vec3d, 4> corners = {Vec3d(0, 0, 0), Vec3d(1, 0, 0), Vec3d(1, 1, 0), Vec3d(1, 1, 1)};
    openvdb::BBoxd box;
    for (Vec3d& v : corners) {
        v -= Vec3d((v[0] + v[1] + v[2]) * g3);  // unskew
        box.expand(v);
    }
    auto phi = [&](double s) {
        const double t = std::max(r2 - s, 0.0);
        return std::max(t * t * t * t, std::fabs(t * t * t * (t - 8.0 * s)));
    };
    auto value_term = [&](double s) {
        const double t = std::max(r2 - s, 0.0);
        return t * t * t * t * std::sqrt(s);
    };
    // Lipschitz constants of one term as a function of x: |d/dx f(|d|^2)| =
    // 2 sqrt(s) |f'(s)|. For the value term it is r2^4 (at d = 0); for phi
    // it is found by a dense scan of the smooth pieces (max ~0.2429).
    double phi_slope = 0.0;
    for (int i = 1; i < 200000; ++i) {
        const double s = r2 * i / 200000.0, ds = 1e-9;
        phi_slope = std::max(phi_slope, 2.0 * std::sqrt(s) * std::fabs(phi(s + ds) - phi(s - ds)) / (2.0 * ds));
    }
    REQUIRE(phi_slope < 0.245);
    const double phi_lipschitz = 4.0 * 0.25;       // four corners, rounded up
    const double value_lipschitz = 4.0 * r2 * r2 * r2 * r2;

    auto phi_sum = [&](const Vec3d& x) {
        double sum = 0.0;
        for (const Vec3d& v : corners) sum += phi((x - v).lengthSqr());
        return sum;
    };
    auto value_sum = [&](const Vec3d& x) {
        double sum = 0.0;
        for (const Vec3d& v : corners) sum += value_term((x - v).lengthSqr());
        return sum;
    };
    double seen = 0.0;
    CHECK(certify_sup(phi_sum, phi_lipschitz, box, 0.0746, 1e-4, &seen));
    CHECK(seen > 0.072);  // the bound is within 3% of the true supremum
    CHECK(certify_sup(value_sum, value_lipschitz, box, 0.00984, 1e-4, &seen));
    CHECK(seen > 0.0092);

    // Only the four corners matter: every other lattice vertex is at squared
    // distance >= r2 from every point of the simplex (the kernel's support).
    std::vector<Vec3d> others;
    for (int i = -2; i <= 3; ++i)
        for (int j = -2; j <= 3; ++j)
            for (int k = -2; k <= 3; ++k) {
                const Vec3d v = Vec3d(i, j, k) - Vec3d((i + j + k) * g3);
                bool corner = false;
                for (const Vec3d& c : corners) corner = corner || (v - c).lengthSqr() < 1e-12;
                if (!corner) others.push_back(v);
            }
    pqdc_test::Random rng(11);
    double nearest = 1e9;
    for (int n = 0; n < 20000; ++n) {
        // Uniform barycentric weights (sorted uniforms), faces included.
        double u[3];
        for (double& x : u) x = rng.unit();
        std::sort(u, u + 3);
        const double w[4] = {u[0], u[1] - u[0], u[2] - u[1], 1.0 - u[2]};
        Vec3d x(0.0);
        for (int c = 0; c < 4; ++c) x += corners[c] * w[c];
        for (const Vec3d& v : others) nearest = std::min(nearest, (x - v).lengthSqr());
    }
    CHECK(nearest >= r2 - 1e-12);
    CHECK(nearest < r2 + 0.01);  // and the support is not smaller than it could be
}

TEST_CASE("procedural: the surface lies inside bounds()", "[procedural]")
{
    // f > 0 everywhere outside bounds(): sample a shell of boxes around it.
    // Strong noise (the bound relies on the certified |noise| <= 1).
    pqdc::Figure3Params loud;
    loud.noise_amplitude = 0.5;
    loud.octaves = 2;
    loud.cut_radius = 0.0;
    auto fields = fields_under_test();
    fields.push_back({"figure3 loud", pqdc::make_figure3(loud)});
    pqdc_test::Random rng(5);
    for (const NamedField& nf : fields) {
        INFO(nf.name);
        const pqdc::ScalarField& f = *nf.field;
        const openvdb::BBoxd b = f.bounds();
        const openvdb::BBoxd outer = expanded(b, 0.5);
        int outside = 0;
        for (int i = 0; i < 20000; ++i) {
            const Vec3d p = rng.in_box(outer);
            if (b.isInside(p)) continue;
            ++outside;
            INFO("p = " << p);
            REQUIRE(f.value(p) > 0.0);
        }
        CHECK(outside > 10000);
    }
}

TEST_CASE("procedural: sphere is an exact signed distance", "[procedural]")
{
    pqdc::SphereParams p;
    p.center = Vec3d(1.0, -2.0, 0.5);
    p.radius = 0.75;
    const auto f = pqdc::make_sphere(p);
    CHECK(f->value(p.center) == Approx(-0.75));
    CHECK(f->value(p.center + Vec3d(0.75, 0.0, 0.0)) == Approx(0.0).margin(1e-15));
    CHECK(f->value(p.center + Vec3d(0.0, -2.0, 0.0)) == Approx(1.25));
    CHECK(f->gradient(p.center + Vec3d(0.0, 0.0, -3.0)).eq(Vec3d(0.0, 0.0, -1.0)));
    CHECK(f->lipschitz_bound() == 1.0);
    CHECK(f->bounds().min().eq(p.center - Vec3d(0.75)));
    CHECK(f->bounds().max().eq(p.center + Vec3d(0.75)));
}

TEST_CASE("procedural: rotated box is an exact signed distance with the right corners", "[procedural]")
{
    pqdc::BoxParams p;
    p.center = Vec3d(0.2, -0.1, 0.4);
    p.half_extents = Vec3d(0.6, 0.45, 0.35);
    p.axis = Vec3d(1.0, 2.0, 3.0);
    p.angle_degrees = 30.0;
    const auto f = pqdc::make_rotated_box(p);

    // Independent rotation: Rodrigues' formula applied to vectors.
    const Vec3d k = p.axis.unitSafe();
    const double th = p.angle_degrees * M_PI / 180.0;
    auto rotate = [&](const Vec3d& v) {
        return v * std::cos(th) + k.cross(v) * std::sin(th) + k * (k.dot(v) * (1.0 - std::cos(th)));
    };
    const Vec3d& h = p.half_extents;

    Vec3d lo(1e9), hi(-1e9);
    for (int c = 0; c < 8; ++c) {
        const Vec3d local((c & 1) ? h[0] : -h[0], (c & 2) ? h[1] : -h[1], (c & 4) ? h[2] : -h[2]);
        const Vec3d corner = p.center + rotate(local);
        INFO("corner " << c << " at " << corner);
        CHECK(f->value(corner) == Approx(0.0).margin(1e-12));
        // Along the corner's diagonal the distance is the Euclidean one.
        const Vec3d out = p.center + rotate(local * 1.5);
        CHECK(f->value(out) == Approx((local * 0.5).length()).epsilon(1e-12));
        // Outside the corner region the gradient points away from the corner.
        CHECK((f->gradient(out) - rotate(local).unitSafe()).length() < 1e-12);
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::min(lo[a], corner[a]);
            hi[a] = std::max(hi[a], corner[a]);
        }
    }
    // bounds() is exactly the axis-aligned box of the corners.
    CHECK((f->bounds().min() - lo).length() < 1e-12);
    CHECK((f->bounds().max() - hi).length() < 1e-12);

    // Inside: distance to the nearest face, negative; gradient its normal.
    CHECK(f->value(p.center) == Approx(-0.35));
    CHECK((f->gradient(p.center + rotate(Vec3d(0.0, 0.0, 0.1))) - rotate(Vec3d(0.0, 0.0, 1.0))).length() < 1e-12);
    const Vec3d face_point = p.center + rotate(Vec3d(0.1, -0.45 + 0.05, 0.2));
    CHECK(f->value(face_point) == Approx(-0.05).epsilon(1e-9));
    CHECK((f->gradient(face_point) - rotate(Vec3d(0.0, -1.0, 0.0))).length() < 1e-12);
    // Just outside the surface (1e-9 away, below Vec3::normalize's 1e-7
    // cut-off) the gradient is still a unit vector, at faces and at edges.
    for (const Vec3d& local : {Vec3d(0.6 + 1e-9, 0.1, 0.0), Vec3d(0.6 + 1e-9, 0.45 + 1e-9, 0.0),
                               Vec3d(-0.2, -0.45 - 1e-10, 0.35 + 1e-9)}) {
        INFO("local point " << local);
        CHECK(f->gradient(p.center + rotate(local)).length() == Approx(1.0).epsilon(1e-12));
    }
    // Outside a face: plain distance to the face plane.
    CHECK(f->value(p.center + rotate(Vec3d(0.9, 0.1, -0.2))) == Approx(0.3).epsilon(1e-12));
    CHECK(f->lipschitz_bound() == 1.0);
}

TEST_CASE("procedural: rotating a box by 90 degrees about z swaps its x and y extents", "[procedural]")
{
    pqdc::BoxParams rotated;
    rotated.half_extents = Vec3d(0.6, 0.2, 0.3);
    rotated.axis = Vec3d(0.0, 0.0, 2.0);
    rotated.angle_degrees = 90.0;
    pqdc::BoxParams plain;
    plain.half_extents = Vec3d(0.2, 0.6, 0.3);
    plain.angle_degrees = 0.0;
    const auto a = pqdc::make_rotated_box(rotated);
    const auto b = pqdc::make_rotated_box(plain);
    pqdc_test::Random rng(9);
    for (int i = 0; i < 1000; ++i) {
        const Vec3d p = rng.in_box(openvdb::BBoxd(Vec3d(-1.0), Vec3d(1.0)));
        REQUIRE(a->value(p) == Approx(b->value(p)).margin(1e-12));
    }
}

TEST_CASE("procedural: noise is deterministic per seed and differs across seeds", "[procedural]")
{
    pqdc::Figure3Params p;
    p.seed = 42;
    const auto a = pqdc::make_figure3(p);
    const auto b = pqdc::make_figure3(p);
    p.seed = 43;
    const auto c = pqdc::make_figure3(p);
    pqdc_test::Random rng(3);
    int differ = 0;
    const int n = 2000;
    for (int i = 0; i < n; ++i) {
        const Vec3d x = rng.in_box(a->bounds());
        REQUIRE(a->value(x) == b->value(x));
        REQUIRE(a->gradient(x).eq(b->gradient(x), 0.0));
        if (a->value(x) != c->value(x)) ++differ;
    }
    // Points inside the cut sphere are the same for any seed.
    CHECK(differ > n / 2);
}

TEST_CASE("procedural: names and the factory", "[procedural]")
{
    const std::vector<std::string> names = pqdc::procedural_names();
    REQUIRE(names == std::vector<std::string>{"sphere", "box", "figure3"});
    for (const std::string& name : names) {
        const auto f = pqdc::make_procedural(name);
        REQUIRE(f);
        CHECK(f->lipschitz_bound() >= 1.0);
    }
    try {
        pqdc::make_procedural("torus");
        FAIL("no exception");
    } catch (const pqdc::option_error& e) {
        const std::string what = e.what();
        CHECK(what.find("torus") != std::string::npos);
        for (const std::string& name : names) CHECK(what.find(name) != std::string::npos);
    }
}

TEST_CASE("procedural: invalid parameters throw option_error naming the parameter", "[procedural]")
{
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const double inf = std::numeric_limits<double>::infinity();
    auto expect = [](const std::function<void()>& make, const std::string& param) {
        INFO("parameter " << param);
        try {
            make();
            FAIL("no exception for " << param);
        } catch (const pqdc::option_error& e) {
            CHECK(std::string(e.what()).find(param) != std::string::npos);
        }
    };
    auto sphere = [](std::function<void(pqdc::SphereParams&)> edit) {
        return [edit] { pqdc::SphereParams p; edit(p); pqdc::make_sphere(p); };
    };
    auto box = [](std::function<void(pqdc::BoxParams&)> edit) {
        return [edit] { pqdc::BoxParams p; edit(p); pqdc::make_rotated_box(p); };
    };
    auto fig = [](std::function<void(pqdc::Figure3Params&)> edit) {
        return [edit] { pqdc::Figure3Params p; edit(p); pqdc::make_figure3(p); };
    };
    expect(sphere([](auto& p) { p.radius = 0.0; }), "radius");
    expect(sphere([&](auto& p) { p.radius = nan; }), "radius");
    expect(sphere([&](auto& p) { p.center[1] = inf; }), "center");
    expect(box([](auto& p) { p.half_extents[2] = -0.1; }), "half_extents");
    expect(box([](auto& p) { p.axis = Vec3d(0.0); }), "axis");
    expect(box([&](auto& p) { p.angle_degrees = nan; }), "angle_degrees");
    expect(box([&](auto& p) { p.center[0] = nan; }), "center");
    expect(fig([](auto& p) { p.radius = -1.0; }), "radius");
    expect(fig([](auto& p) { p.cut_radius = -0.1; }), "cut_radius");
    expect(fig([&](auto& p) { p.cut_center[2] = inf; }), "cut_center");
    expect(fig([](auto& p) { p.noise_amplitude = -0.01; }), "noise_amplitude");
    expect(fig([](auto& p) { p.noise_frequency = 0.0; }), "noise_frequency");
    expect(fig([](auto& p) { p.octaves = 0; }), "octaves");
    expect(fig([](auto& p) { p.octaves = 17; }), "octaves");
    expect(fig([](auto& p) { p.lacunarity = 1.0; }), "lacunarity");
    expect(fig([](auto& p) { p.gain = 0.0; }), "gain");
    expect(fig([](auto& p) { p.gain = 1.0; }), "gain");

    const auto sphere_field = pqdc::make_procedural("sphere");
    pqdc::ProceduralSampling s;
    s.resolution = 3;
    expect([&] { pqdc::sample_field(*sphere_field, s); }, "resolution");
    s.resolution = 16385;
    expect([&] { pqdc::procedural_transform(*sphere_field, s); }, "resolution");
    s.resolution = 64;
    s.margin_voxels = 1.5;
    expect([&] { pqdc::procedural_index_bbox(*sphere_field, s); }, "margin_voxels");
    s.margin_voxels = nan;
    expect([&] { pqdc::sample_field(*sphere_field, s); }, "margin_voxels");
}

TEST_CASE("procedural: lattice transform and index box follow bounds()", "[procedural]")
{
    pqdc::BoxParams bp;
    bp.center = Vec3d(3.0, -1.0, 7.0);
    const auto f = pqdc::make_rotated_box(bp);
    pqdc::ProceduralSampling s;
    s.resolution = 50;
    s.margin_voxels = 2.5;
    const openvdb::BBoxd b = f->bounds();
    const Vec3d extent = b.max() - b.min();
    const double longest = std::max(extent[0], std::max(extent[1], extent[2]));
    const double h = longest / 50.0;

    const auto xform = pqdc::procedural_transform(*f, s);
    REQUIRE(xform->isLinear());
    CHECK(xform->voxelSize()[0] == Approx(h));
    CHECK(xform->voxelSize()[2] == Approx(h));
    CHECK((xform->indexToWorld(Vec3d(0.0)) - (b.min() - Vec3d(2.5 * h))).length() < 1e-12);

    const openvdb::CoordBBox ib = pqdc::procedural_index_bbox(*f, s);
    CHECK(ib.min() == openvdb::Coord(0));
    for (int a = 0; a < 3; ++a) {
        // The last lattice point is the first one at least margin beyond bounds().max().
        const double last = xform->indexToWorld(ib.max().asVec3d())[a];
        CHECK(last >= b.max()[a] + 2.5 * h - 1e-9 * h);
        CHECK(last < b.max()[a] + 3.5 * h);
    }
    // The longest axis gets exactly resolution cells plus both margins.
    const int longest_axis = extent[0] >= extent[1] ? (extent[0] >= extent[2] ? 0 : 2) : (extent[1] >= extent[2] ? 1 : 2);
    CHECK(ib.max()[longest_axis] == 55);
}

namespace {

/// Checks sample_field's promises on every lattice point of the index box:
/// active voxels hold float(f), inactive values are +-background with f's
/// sign, and every cell with a sign change among its exact corner values has
/// all eight corners active. Returns the number of such cells.
std::string str(const openvdb::Coord& c)
{
    return "(" + std::to_string(c.x()) + ", " + std::to_string(c.y()) + ", " + std::to_string(c.z()) + ")";
}

std::size_t check_sampled(const pqdc::ScalarField& f, const pqdc::ProceduralSampling& s)
{
    const openvdb::FloatGrid::Ptr grid = pqdc::sample_field(f, s);
    REQUIRE(grid);
    CHECK(grid->getGridClass() == openvdb::GRID_LEVEL_SET);
    CHECK(!grid->getName().empty());
    const auto xform = pqdc::procedural_transform(f, s);
    CHECK(grid->transform() == *xform);
    const float background = grid->background();
    CHECK(background == Approx(3.0 * xform->voxelSize()[0]));

    const openvdb::CoordBBox ib = pqdc::procedural_index_bbox(f, s);
    const openvdb::Coord dim = ib.dim();
    std::vector<double> exact(static_cast<std::size_t>(dim.x()) * dim.y() * dim.z());
    auto at = [&](int i, int j, int k) -> double& {
        return exact[(static_cast<std::size_t>(i) * dim.y() + j) * dim.z() + k];
    };
    // Counted rather than asserted per point (millions of points); the first
    // offender of each kind is reported.
    std::size_t wrong_active = 0, wrong_inactive = 0, inactive_corners = 0;
    std::string first_problem;
    auto note = [&](std::size_t& counter, const std::string& what) {
        if (counter++ == 0 && first_problem.empty()) first_problem = what;
    };
    auto accessor = grid->getConstAccessor();
    for (int i = 0; i < dim.x(); ++i) {
        for (int j = 0; j < dim.y(); ++j) {
            for (int k = 0; k < dim.z(); ++k) {
                const openvdb::Coord ijk(i, j, k);
                const double v = f.value(xform->indexToWorld(ijk));
                at(i, j, k) = v;
                float stored = 0.0f;
                if (accessor.probeValue(ijk, stored)) {
                    if (stored != static_cast<float>(v)) {
                        note(wrong_active, "active " + str(ijk) + " holds " + std::to_string(stored) +
                                               ", f = " + std::to_string(v));
                    }
                } else if (std::fabs(stored) != background || (stored < 0.0f) != (v < 0.0)) {
                    note(wrong_inactive, "inactive " + str(ijk) + " holds " + std::to_string(stored) +
                                             ", f = " + std::to_string(v));
                }
            }
        }
    }
    std::size_t crossed = 0;
    for (int i = 0; i + 1 < dim.x(); ++i) {
        for (int j = 0; j + 1 < dim.y(); ++j) {
            for (int k = 0; k + 1 < dim.z(); ++k) {
                bool neg = false, pos = false;
                for (int c = 0; c < 8; ++c) {
                    const double v = at(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
                    (v < 0.0 ? neg : pos) = true;
                }
                if (!(neg && pos)) continue;
                ++crossed;
                for (int c = 0; c < 8; ++c) {
                    const openvdb::Coord corner(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
                    if (!accessor.isValueOn(corner)) {
                        note(inactive_corners, "cell " + str(openvdb::Coord(i, j, k)) +
                                                   " has a sign change but its corner " + str(corner) +
                                                   " is inactive");
                    }
                }
            }
        }
    }
    INFO(first_problem);
    CHECK(wrong_active == 0);
    CHECK(wrong_inactive == 0);
    CHECK(inactive_corners == 0);
    // The active voxels stay within the index box.
    const openvdb::CoordBBox active = grid->evalActiveVoxelBoundingBox();
    CHECK(ib.isInside(active));
    return crossed;
}

}  // namespace

TEST_CASE("procedural: every cell with a sign change has all corners active", "[procedural]")
{
    pqdc::Figure3Params rough;
    rough.octaves = 5;
    rough.noise_amplitude = 0.12;
    rough.noise_frequency = 6.0;
    rough.seed = 99;
    struct Case {
        std::string name;
        std::shared_ptr<pqdc::ScalarField> field;
        int resolution;
    };
    const std::vector<Case> cases = {
        {"sphere", pqdc::make_procedural("sphere"), 40},
        {"box", pqdc::make_procedural("box"), 37},
        {"figure3", pqdc::make_procedural("figure3"), 64},
        {"figure3 rough, coarse", pqdc::make_figure3(rough), 24},
        {"figure3 rough", pqdc::make_figure3(rough), 72},
    };
    for (const Case& c : cases) {
        INFO(c.name << " at resolution " << c.resolution);
        pqdc::ProceduralSampling s;
        s.resolution = c.resolution;
        CHECK(check_sampled(*c.field, s) > 0);
    }
}

TEST_CASE("procedural: sampling is sparse away from the surface", "[procedural]")
{
    // A block is active only if f may vanish in one of the sub-cubes of its
    // cell region [o-1, o+8]^3; for a distance field (L = 1) that puts every
    // active voxel within ~17 voxels of the surface (9*sqrt(3) across the
    // region plus the sub-cube radius). Plain per-block culling alone would
    // allow the same; what this guards is that culling happens at all.
    for (const char* name : {"sphere", "box"}) {
        INFO(name);
        const auto f = pqdc::make_procedural(name);
        pqdc::ProceduralSampling s;
        s.resolution = 160;
        const openvdb::FloatGrid::Ptr grid = pqdc::sample_field(*f, s);
        const double h = grid->voxelSize()[0];
        float worst = 0.0f;
        for (auto it = grid->tree().cbeginValueOn(); it; ++it) worst = std::max(worst, std::fabs(*it));
        CHECK(worst <= (9.0 * std::sqrt(3.0) + 1.1) * h);
        CHECK(grid->activeVoxelCount() < pqdc::procedural_index_bbox(*f, s).volume() / 4);
    }
    // Deep inside: an inactive tile at -background.
    const auto sphere = pqdc::make_procedural("sphere");
    const openvdb::FloatGrid::Ptr grid = pqdc::sample_field(*sphere, pqdc::ProceduralSampling{});
    const openvdb::Coord center = grid->transform().worldToIndexCellCentered(Vec3d(0.0));
    float v = 0.0f;
    CHECK_FALSE(grid->tree().probeValue(center, v));
    CHECK(v == -grid->background());
}

TEST_CASE("procedural: sample_field is identical for any thread count", "[procedural]")
{
    const auto f = pqdc::make_procedural("figure3");
    pqdc::ProceduralSampling s;
    s.resolution = 48;
    openvdb::FloatGrid::Ptr one, two;
    {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
        one = pqdc::sample_field(*f, s);
    }
    {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 4);
        two = pqdc::sample_field(*f, s);
    }
    REQUIRE(one->tree().leafCount() == two->tree().leafCount());
    REQUIRE(one->activeVoxelCount() == two->activeVoxelCount());
    REQUIRE(one->tree().hasSameTopology(two->tree()));
    auto b = two->getConstAccessor();
    for (auto it = one->tree().cbeginValueAll(); it; ++it) {
        openvdb::CoordBBox bbox;
        it.getBoundingBox(bbox);
        float w = 0.0f;
        REQUIRE(b.probeValue(bbox.min(), w) == it.isValueOn());
        REQUIRE(w == *it);
    }
}
