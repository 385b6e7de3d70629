// The tests' one source of random numbers: seeded, and the same sequence
// with every standard library (std::*_distribution are not specified
// bit-for-bit, so they are not used).
#pragma once

#include <openvdb/openvdb.h>

#include <cmath>
#include <cstdint>
#include <random>

namespace pqdc_test {

class Random {
public:
    explicit Random(std::uint64_t seed) : engine_(seed) {}

    std::uint64_t bits() { return engine_(); }
    /// Uniform in [0, 1), 53 random bits.
    double unit() { return double(engine_() >> 11) * 0x1.0p-53; }
    /// Uniform in [lo, hi).
    double uniform(double lo, double hi) { return lo + (hi - lo) * unit(); }
    /// Uniform integer in [lo, hi].
    int integer(int lo, int hi) { return lo + int(engine_() % std::uint64_t(hi - lo + 1)); }
    /// Standard normal (Box-Muller).
    double normal() {
        const double u = 1.0 - unit(), v = unit();
        return std::sqrt(-2.0 * std::log(u)) * std::cos(2.0 * M_PI * v);
    }
    /// Uniform in the box.
    openvdb::Vec3d in_box(const openvdb::BBoxd& box) {
        openvdb::Vec3d p;
        for (int a = 0; a < 3; ++a) p[a] = box.min()[a] + unit() * (box.max()[a] - box.min()[a]);
        return p;
    }

private:
    std::mt19937_64 engine_;
};

/// Distributions in the call style of <random>: dist(rng).
struct UniformReal {
    double lo = 0, hi = 1;
    double operator()(Random& r) const { return r.uniform(lo, hi); }
};
struct UniformInt {
    int lo = 0, hi = 1;
    int operator()(Random& r) const { return r.integer(lo, hi); }
};
struct Normal {
    double mean = 0, sd = 1;
    double operator()(Random& r) const { return mean + sd * r.normal(); }
};

}  // namespace pqdc_test
