// Procedural signed fields with analytic gradients: sphere, rotated box and
// the paper's Figure 3 field (sampling.cpp lays them onto a lattice).

#include "pqdc/procedural.hpp"

#include "procedural/simplex_noise.hpp"
#include "procedural/validation.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

namespace pqdc {
namespace {

using namespace procedural_detail;

// ------------------------------------------------------------ fields

class Sphere final : public ScalarField {
public:
    explicit Sphere(const SphereParams& p) : p_(p) {}
    double value(const Vec3d& x) const override { return (x - p_.center).length() - p_.radius; }
    Vec3d gradient(const Vec3d& x) const override
    {
        const Vec3d r = x - p_.center;
        const double len = r.length();
        return len > 0.0 ? r / len : Vec3d(0.0);
    }
    double lipschitz_bound() const override { return 1.0; }
    openvdb::BBoxd bounds() const override
    {
        return openvdb::BBoxd(p_.center - Vec3d(p_.radius), p_.center + Vec3d(p_.radius));
    }

private:
    SphereParams p_;
};

/// Rotation matrix for `angle_radians` about the unit vector `axis`
/// (Rodrigues), mapping box-local to world directions.
openvdb::Mat3d rotation_about(const Vec3d& axis, double angle_radians)
{
    const double c = std::cos(angle_radians), s = std::sin(angle_radians), C = 1.0 - c;
    const double x = axis[0], y = axis[1], z = axis[2];
    return openvdb::Mat3d(c + x * x * C, x * y * C - z * s, x * z * C + y * s,   //
                          y * x * C + z * s, c + y * y * C, y * z * C - x * s,   //
                          z * x * C - y * s, z * y * C + x * s, c + z * z * C);
}

class RotatedBox final : public ScalarField {
public:
    explicit RotatedBox(const BoxParams& p)
        : p_(p), rotation_(rotation_about(p.axis.unitSafe(), p.angle_degrees * (M_PI / 180.0)))
    {
    }

    double value(const Vec3d& x) const override
    {
        const Vec3d q = to_local(x);
        const Vec3d d(std::fabs(q[0]) - p_.half_extents[0], std::fabs(q[1]) - p_.half_extents[1],
                      std::fabs(q[2]) - p_.half_extents[2]);
        const Vec3d outside(std::max(d[0], 0.0), std::max(d[1], 0.0), std::max(d[2], 0.0));
        return outside.length() + std::min(std::max(d[0], std::max(d[1], d[2])), 0.0);
    }

    Vec3d gradient(const Vec3d& x) const override
    {
        const Vec3d q = to_local(x);
        const Vec3d d(std::fabs(q[0]) - p_.half_extents[0], std::fabs(q[1]) - p_.half_extents[1],
                      std::fabs(q[2]) - p_.half_extents[2]);
        Vec3d local(0.0);
        if (d[0] > 0.0 || d[1] > 0.0 || d[2] > 0.0) {
            // Outside: direction from the nearest box point, per octant.
            for (int a = 0; a < 3; ++a) local[a] = d[a] > 0.0 ? std::copysign(d[a], q[a]) : 0.0;
            local /= local.length();  // not Vec3::normalize(): it skips lengths below 1e-7
        } else {
            // Inside: the nearest face's normal (the first one on ties).
            int a = 0;
            if (d[1] > d[a]) a = 1;
            if (d[2] > d[a]) a = 2;
            local[a] = std::copysign(1.0, q[a]);
        }
        return rotation_ * local;
    }

    double lipschitz_bound() const override { return 1.0; }

    openvdb::BBoxd bounds() const override
    {
        Vec3d e;
        for (int i = 0; i < 3; ++i) {
            e[i] = std::fabs(rotation_(i, 0)) * p_.half_extents[0] +
                   std::fabs(rotation_(i, 1)) * p_.half_extents[1] +
                   std::fabs(rotation_(i, 2)) * p_.half_extents[2];
        }
        return openvdb::BBoxd(p_.center - e, p_.center + e);
    }

private:
    // R is orthonormal, so R^T maps world offsets into the box frame.
    Vec3d to_local(const Vec3d& x) const { return rotation_.transpose() * (x - p_.center); }

    BoxParams p_;
    openvdb::Mat3d rotation_;
};

class Figure3 final : public ScalarField {
public:
    explicit Figure3(const Figure3Params& p) : p_(p)
    {
        SplitMix64 rng(0x5EED0F160003ull ^ (static_cast<std::uint64_t>(p.seed) << 17) ^ p.seed);
        noise_.reserve(static_cast<std::size_t>(p.octaves));
        double weight = 1.0, scale = 1.0;
        for (int o = 0; o < p.octaves; ++o) {
            Octave oct;
            oct.noise = std::make_unique<SimplexNoise>(rng);
            // A seeded shift per octave so that octaves do not share lattice
            // vertices (where simplex noise vanishes) at the origin.
            oct.offset = Vec3d(rng.unit(), rng.unit(), rng.unit()) * 64.0;
            oct.scale = scale;
            oct.weight = weight;
            noise_.push_back(std::move(oct));
            weight_sum_ += weight;
            gradient_weight_sum_ += weight * scale;
            weight *= p.gain;
            scale *= p.lacunarity;
        }
        has_cut_ = p.cut_radius > 0.0;
        noise_reach_ = p.noise_amplitude * kNoiseValueBound * weight_sum_;
    }

    double value(const Vec3d& x) const override
    {
        const double radial = (x - p_.center).length() - p_.radius;
        if (!has_cut_) return radial + p_.noise_amplitude * fbm(x, nullptr);
        const double cut = p_.cut_radius - (x - p_.cut_center).length();
        // Where the cut exceeds every possible g, f is the cut: skip the
        // noise (same result, and most of the cut's surface is like that).
        if (cut > radial + noise_reach_) return cut;
        return std::max(radial + p_.noise_amplitude * fbm(x, nullptr), cut);
    }

    Vec3d gradient(const Vec3d& x) const override
    {
        const Vec3d r = x - p_.center;
        const double rl = r.length();
        const Vec3d rc = x - p_.cut_center;
        const double rcl = rc.length();
        const Vec3d cut_gradient = rcl > 0.0 ? -rc / rcl : Vec3d(0.0);
        if (has_cut_ && p_.cut_radius - rcl > rl - p_.radius + noise_reach_) return cut_gradient;
        Vec3d noise_gradient;
        const double g = rl - p_.radius + p_.noise_amplitude * fbm(x, &noise_gradient);
        if (has_cut_ && p_.cut_radius - rcl > g) return cut_gradient;
        const Vec3d radial = rl > 0.0 ? r / rl : Vec3d(0.0);
        return radial + noise_gradient * (p_.noise_amplitude * p_.noise_frequency);
    }

    double lipschitz_bound() const override
    {
        // max(g, cut) is Lipschitz with the larger of the two constants (1 for the cut).
        return 1.0 + p_.noise_amplitude * p_.noise_frequency * kNoiseGradientBound * gradient_weight_sum_;
    }

    openvdb::BBoxd bounds() const override
    {
        // f = 0 needs g <= 0, i.e. |x - c| <= radius - amplitude * fbm.
        const double reach = p_.radius + noise_reach_;
        return openvdb::BBoxd(p_.center - Vec3d(reach), p_.center + Vec3d(reach));
    }

private:
    struct Octave {
        std::unique_ptr<SimplexNoise> noise;
        Vec3d offset;
        double scale = 1.0;
        double weight = 1.0;
    };

    /// sum_o gain^o * simplex_o(lacunarity^o * frequency * x + offset_o);
    /// `gradient` receives d/d(frequency * x).
    double fbm(const Vec3d& x, Vec3d* gradient) const
    {
        const Vec3d base = x * p_.noise_frequency;
        double sum = 0.0;
        Vec3d grad(0.0), octave_gradient;
        for (const Octave& o : noise_) {
            sum += o.weight * o.noise->evaluate(base * o.scale + o.offset, gradient ? &octave_gradient : nullptr);
            if (gradient) grad += octave_gradient * (o.weight * o.scale);
        }
        if (gradient) *gradient = grad;
        return sum;
    }

    Figure3Params p_;
    std::vector<Octave> noise_;
    double weight_sum_ = 0.0;           // sum_o gain^o
    double gradient_weight_sum_ = 0.0;  // sum_o (gain * lacunarity)^o
    double noise_reach_ = 0.0;          // >= |amplitude * fbm| everywhere
    bool has_cut_ = false;
};

}  // namespace

// ------------------------------------------------------------ factories

std::unique_ptr<ScalarField> make_sphere(const SphereParams& p)
{
    require(finite(p.center), "sphere", "center", "finite", format_vec(p.center));
    require(std::isfinite(p.radius) && p.radius > 0.0, "sphere", "radius", "finite and > 0 (world units)",
            format_number(p.radius));
    return std::make_unique<Sphere>(p);
}

std::unique_ptr<ScalarField> make_rotated_box(const BoxParams& p)
{
    require(finite(p.center), "box", "center", "finite", format_vec(p.center));
    require(finite(p.half_extents) && p.half_extents[0] > 0.0 && p.half_extents[1] > 0.0 &&
                p.half_extents[2] > 0.0,
            "box", "half_extents", "finite and > 0 in each component (world units)", format_vec(p.half_extents));
    require(finite(p.axis) && p.axis.length() > 0.0 && std::isfinite(p.axis.length()), "box", "axis",
            "a finite non-zero vector", format_vec(p.axis));
    require(std::isfinite(p.angle_degrees), "box", "angle_degrees", "finite", format_number(p.angle_degrees));
    return std::make_unique<RotatedBox>(p);
}

std::unique_ptr<ScalarField> make_figure3(const Figure3Params& p)
{
    require(finite(p.center), "figure3", "center", "finite", format_vec(p.center));
    require(std::isfinite(p.radius) && p.radius > 0.0, "figure3", "radius", "finite and > 0 (world units)",
            format_number(p.radius));
    require(finite(p.cut_center), "figure3", "cut_center", "finite", format_vec(p.cut_center));
    require(std::isfinite(p.cut_radius) && p.cut_radius >= 0.0, "figure3", "cut_radius",
            "finite and >= 0 (world units; 0 = no cut)", format_number(p.cut_radius));
    require(std::isfinite(p.noise_amplitude) && p.noise_amplitude >= 0.0, "figure3", "noise_amplitude",
            "finite and >= 0 (world units)", format_number(p.noise_amplitude));
    require(std::isfinite(p.noise_frequency) && p.noise_frequency > 0.0, "figure3", "noise_frequency",
            "finite and > 0 (cycles per world unit)", format_number(p.noise_frequency));
    require(p.octaves >= 1 && p.octaves <= 16, "figure3", "octaves", "in [1, 16]", std::to_string(p.octaves));
    require(std::isfinite(p.lacunarity) && p.lacunarity > 1.0, "figure3", "lacunarity", "finite and > 1",
            format_number(p.lacunarity));
    require(std::isfinite(p.gain) && p.gain > 0.0 && p.gain < 1.0, "figure3", "gain", "in (0, 1)",
            format_number(p.gain));
    auto field = std::make_unique<Figure3>(p);
    require(std::isfinite(field->lipschitz_bound()), "figure3", "noise_frequency * lacunarity^(octaves-1)",
            "small enough for a finite Lipschitz bound", format_number(field->lipschitz_bound()));
    return field;
}

std::vector<std::string> procedural_names() { return {"sphere", "box", "figure3"}; }

std::unique_ptr<ScalarField> make_procedural(const std::string& name)
{
    if (name == "sphere") return make_sphere(SphereParams{});
    if (name == "box") return make_rotated_box(BoxParams{});
    if (name == "figure3") return make_figure3(Figure3Params{});
    std::string list;
    for (const std::string& n : procedural_names()) list += (list.empty() ? "" : ", ") + n;
    throw option_error("unknown procedural field '" + name + "'; valid names: " + list);
}

}  // namespace pqdc
