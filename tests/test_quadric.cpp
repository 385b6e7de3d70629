// Tests for include/pqdc/quadric.hpp (and the vec3.hpp helpers it uses).
//
// The probabilistic quadrics are checked against their definition rather than
// against re-typed formulas: the closed forms must equal the expectation of the
// classical quadric over Gaussian inputs, estimated by Monte Carlo with a
// tolerance derived from the sample's own standard error. Each such test also
// shows that the tolerance is tight enough to reject the closed form with one
// of its higher-order terms removed, so a dropped or mistyped term fails.
//
// All randomness is seeded (std::mt19937_64) and normals come from a local
// Box-Muller transform, because std::normal_distribution's output differs
// between standard libraries.
#include "pqdc/quadric.hpp"

#include <catch2/catch.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

namespace {

using pqdc::quadric;
using pqdc::sym3;
using pqdc::vec3;
using vd = vec3<double>;
using vf = vec3<float>;
using sd = sym3<double>;
using qd = quadric<double>;
using qf = quadric<float>;
using ld = long double;

constexpr double kPi = 3.14159265358979323846;

// ------------------------------------------------------------------ random

class rng {
public:
    explicit rng(std::uint64_t seed) : engine_(seed) {}

    double uniform() { return double(engine_() >> 11) * 0x1.0p-53; }  // [0, 1)
    double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
    double log_uniform(double lo, double hi) {
        return std::exp(uniform(std::log(lo), std::log(hi)));
    }
    int integer(int lo, int hi) { return lo + int(engine_() % std::uint64_t(hi - lo + 1)); }

    double normal() {
        if (has_spare_) {
            has_spare_ = false;
            return spare_;
        }
        const double u1 = 1.0 - uniform();  // (0, 1]: log stays finite
        const double u2 = uniform();
        const double r = std::sqrt(-2.0 * std::log(u1));
        spare_ = r * std::sin(2.0 * kPi * u2);
        has_spare_ = true;
        return r * std::cos(2.0 * kPi * u2);
    }
    vd normal3() {
        const double x = normal(), y = normal(), z = normal();
        return {x, y, z};
    }
    vd uniform3(double lo, double hi) {
        const double x = uniform(lo, hi), y = uniform(lo, hi), z = uniform(lo, hi);
        return {x, y, z};
    }
    vd unit3() {
        for (;;) {
            const vd v = normal3();
            const double l = pqdc::length(v);
            if (l > 1e-3) return v / l;
        }
    }

private:
    std::mt19937_64 engine_;
    double spare_ = 0;
    bool has_spare_ = false;
};

/// A Gaussian N(mean, L L^T) that can be sampled as mean + L z.
struct gaussian3 {
    vd mean;
    double L[3][3] = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}};  // lower triangular

    sd covariance() const {
        auto s = [&](int i, int j) { return L[i][0] * L[j][0] + L[i][1] * L[j][1] + L[i][2] * L[j][2]; };
        return {s(0, 0), s(0, 1), s(0, 2), s(1, 1), s(1, 2), s(2, 2)};
    }
    vd sample(rng& g) const {
        const vd z = g.normal3();
        return mean + vd{L[0][0] * z.x, L[1][0] * z.x + L[1][1] * z.y,
                         L[2][0] * z.x + L[2][1] * z.y + L[2][2] * z.z};
    }
};

gaussian3 isotropic(const vd& mean, double sigma) {
    gaussian3 d;
    d.mean = mean;
    d.L[0][0] = d.L[1][1] = d.L[2][2] = sigma;
    return d;
}

/// Anisotropic, correlated, positive definite: eigenvalues of L L^T spread over
/// roughly (0.05 .. 2) scale^2.
gaussian3 anisotropic(rng& g, const vd& mean, double scale) {
    gaussian3 d;
    d.mean = mean;
    for (int i = 0; i < 3; ++i) {
        d.L[i][i] = scale * g.uniform(0.3, 1.0);
        for (int j = 0; j < i; ++j) d.L[i][j] = scale * g.uniform(-0.6, 0.6);
    }
    return d;
}

sd random_spd(rng& g, double scale) { return anisotropic(g, {0, 0, 0}, scale).covariance(); }

sd random_symmetric(rng& g, double scale) {
    return {scale * g.uniform(-1, 1), scale * g.uniform(-1, 1), scale * g.uniform(-1, 1),
            scale * g.uniform(-1, 1), scale * g.uniform(-1, 1), scale * g.uniform(-1, 1)};
}

// ------------------------------------------------------------ small helpers

double max_abs(const sd& m) {
    return std::max({std::fabs(m.a00), std::fabs(m.a01), std::fabs(m.a02), std::fabs(m.a11),
                     std::fabs(m.a12), std::fabs(m.a22)});
}
double max_abs_diff(const sd& a, const sd& b) { return max_abs(a - b); }

/// Rows of the full 3x3 matrix [a]x.
void cross_matrix(const vd& a, double m[3][3]) {
    const double r[3][3] = {{0, -a.z, a.y}, {a.z, 0, -a.x}, {-a.y, a.x, 0}};
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) m[i][j] = r[i][j];
}

void full(const sd& s, double m[3][3]) {
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) m[i][j] = s(i, j);
}

void multiply(const double a[3][3], const double b[3][3], double out[3][3]) {
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) out[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
}

struct spectrum {
    double min, max;  // smallest and largest eigenvalue (signed)
    double condition() const { return std::fabs(max) / std::fabs(min); }
};
spectrum eigen_range(const sd& m) {
    const pqdc::sym3_eigen e = pqdc::eigen_decompose(m);
    return {std::min({e.values[0], e.values[1], e.values[2]}),
            std::max({e.values[0], e.values[1], e.values[2]})};
}

/// A x = b in long double by Gaussian elimination with partial pivoting: the
/// reference the fast solvers are compared against. nullopt if singular.
template <class T>
std::optional<vec3<ld>> reference_solve(const quadric<T>& q) {
    ld m[3][4];
    const sym3<T>& A = q.A;
    const vec3<T>& b = q.b;
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) m[i][j] = ld(A(i, j));
        m[i][3] = ld(b[std::size_t(i)]);
    }
    for (int col = 0; col < 3; ++col) {
        int pivot = col;
        for (int r = col + 1; r < 3; ++r)
            if (std::fabs(m[r][col]) > std::fabs(m[pivot][col])) pivot = r;
        if (m[pivot][col] == 0) return std::nullopt;
        for (int j = 0; j < 4; ++j) std::swap(m[col][j], m[pivot][j]);
        for (int r = col + 1; r < 3; ++r) {
            const ld f = m[r][col] / m[col][col];
            for (int j = col; j < 4; ++j) m[r][j] -= f * m[col][j];
        }
    }
    vec3<ld> x;
    for (int i = 2; i >= 0; --i) {
        ld s = m[i][3];
        for (int j = i + 1; j < 3; ++j) s -= m[i][j] * x[std::size_t(j)];
        x[std::size_t(i)] = s / m[i][i];
    }
    return x;
}

vd to_double(const vec3<ld>& v) { return vd(v); }

// ----------------------------------------------------- Monte-Carlo statistics

constexpr int kEntries = 10;
using entry_array = std::array<double, kEntries>;
const char* const kEntryNames[kEntries] = {"A00", "A01", "A02", "A11", "A12",
                                           "A22", "b.x", "b.y", "b.z", "c"};

entry_array entries(const qd& q) {
    return {q.A.a00, q.A.a01, q.A.a02, q.A.a11, q.A.a12, q.A.a22, q.b.x, q.b.y, q.b.z, q.c};
}

/// Sample mean and standard error of the ten quadric entries. Samples are
/// accumulated as deviations from a fixed center (the closed form under test)
/// so that sums of squares do not cancel.
class entry_statistics {
public:
    explicit entry_statistics(const qd& center) : center_(entries(center)) {}

    void add(const qd& sample) {
        const entry_array e = entries(sample);
        for (int i = 0; i < kEntries; ++i) {
            const double d = e[std::size_t(i)] - center_[std::size_t(i)];
            sum_[std::size_t(i)] += d;
            sum_sq_[std::size_t(i)] += d * d;
        }
        ++n_;
    }
    double mean(int i) const { return center_[std::size_t(i)] + sum_[std::size_t(i)] / double(n_); }
    double standard_error(int i) const {
        const double n = double(n_);
        const double m = sum_[std::size_t(i)] / n;
        const double variance = (sum_sq_[std::size_t(i)] / n - m * m) * n / (n - 1);
        return std::sqrt(std::max(variance, 0.0) / n);
    }

    /// The sample mean of N iid draws has standard error SE = sd / sqrt(N);
    /// with N in the hundreds of thousands the mean is normal to excellent
    /// approximation (CLT), so |mean - E| > 5 SE has probability ~6e-7 per
    /// entry. The rounding allowance covers entries whose true variance is 0.
    static constexpr double kZ = 5.0;
    bool accepts(int i, double expected) const {
        const double allowance = 1e-12 * (1.0 + std::fabs(expected));
        return std::fabs(mean(i) - expected) <= kZ * standard_error(i) + allowance;
    }
    int rejected_count(const qd& candidate) const {
        const entry_array e = entries(candidate);
        int count = 0;
        for (int i = 0; i < kEntries; ++i) count += accepts(i, e[std::size_t(i)]) ? 0 : 1;
        return count;
    }
    std::string report(const qd& candidate) const {
        const entry_array e = entries(candidate);
        std::ostringstream s;
        s.precision(6);
        for (int i = 0; i < kEntries; ++i)
            s << kEntryNames[i] << ": mean " << mean(i) << " closed form " << e[std::size_t(i)]
              << " SE " << standard_error(i) << " z "
              << (mean(i) - e[std::size_t(i)]) / standard_error(i) << "\n";
        return s.str();
    }

private:
    entry_array center_;
    entry_array sum_{}, sum_sq_{};
    long n_ = 0;
};

void check_closed_form(const entry_statistics& stats, const qd& closed) {
    const entry_array e = entries(closed);
    INFO(stats.report(closed));
    for (int i = 0; i < kEntries; ++i) {
        INFO("entry " << kEntryNames[i]);
        CHECK(stats.accepts(i, e[std::size_t(i)]));
    }
}

// Sample counts: enough that every higher-order term below is many standard
// errors large; small enough for ~0.1 s per case in Release.
constexpr int kPlaneSamples = 1 << 18;
constexpr int kTriangleSamples = 1 << 18;

// ---------------------------------------------------------- plane configs

struct plane_sample {
    vd point, normal;
};

/// Hermite-like data of one dual-contouring cell: points on 1..3 planes
/// through a feature point inside the unit cell. layout: 1 = flat, 2 = edge,
/// 3 = corner, 0 = every sample with its own random normal.
std::vector<plane_sample> random_cell_planes(rng& g, int layout, int count) {
    const vd feature = g.uniform3(0.1, 0.9);
    std::vector<vd> normals;
    for (int i = 0; i < std::max(layout, 1); ++i) normals.push_back(g.unit3());
    std::vector<plane_sample> out;
    for (int i = 0; i < count; ++i) {
        const vd n = layout == 0 ? g.unit3() : normals[std::size_t(i % layout)];
        const vd u = g.uniform3(-0.5, 0.5);
        out.push_back({feature + (u - n * pqdc::dot(u, n)), n});
    }
    return out;
}

}  // namespace

// =====================================================================
// vec3.hpp helpers
// =====================================================================

TEST_CASE("sym3 helpers match explicit 3x3 matrix products", "[quadric][vec3]") {
    rng g(11);
    for (int trial = 0; trial < 100; ++trial) {
        const sd s = random_symmetric(g, 2.0), t = random_symmetric(g, 3.0);
        const vd a = g.normal3(), v = g.normal3();
        double ax[3][3], sm[3][3], tmp[3][3], prod[3][3], axt[3][3];
        cross_matrix(a, ax);
        full(s, sm);
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) axt[i][j] = ax[j][i];
        multiply(ax, sm, tmp);
        multiply(tmp, axt, prod);
        const sd sandwich = pqdc::cross_sandwich(a, s);
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) CHECK(sandwich(i, j) == Approx(prod[i][j]).margin(1e-12));

        double tm[3][3], st[3][3];
        full(t, tm);
        multiply(sm, tm, st);
        CHECK(pqdc::trace_of_product(s, t) == Approx(st[0][0] + st[1][1] + st[2][2]).margin(1e-12));

        const vd sv = s * v;
        for (int i = 0; i < 3; ++i)
            CHECK(sv[std::size_t(i)] ==
                  Approx(sm[i][0] * v.x + sm[i][1] * v.y + sm[i][2] * v.z).margin(1e-12));
        CHECK(s.determinant() ==
              Approx(sm[0][0] * (sm[1][1] * sm[2][2] - sm[1][2] * sm[2][1]) -
                     sm[0][1] * (sm[1][0] * sm[2][2] - sm[1][2] * sm[2][0]) +
                     sm[0][2] * (sm[1][0] * sm[2][1] - sm[1][1] * sm[2][0]))
                  .margin(1e-12));
        CHECK(pqdc::cross(a, v).x == Approx(ax[0][1] * v.y + ax[0][2] * v.z).margin(1e-12));
    }
}

// =====================================================================
// cross-interference matrix (eq. 12, Appendix A)
// =====================================================================

TEST_CASE("cross_interference is symmetric in its arguments", "[quadric][ci]") {
    rng g(21);
    for (int trial = 0; trial < 200; ++trial) {
        const sd a = random_symmetric(g, 1.5), b = random_symmetric(g, 0.7);
        CHECK(max_abs_diff(pqdc::cross_interference(a, b), pqdc::cross_interference(b, a)) <=
              1e-14 * (1 + max_abs(pqdc::cross_interference(a, b))));
    }
}

TEST_CASE("cross_interference of isotropic covariances is 2 sigma^4 I (eq. 13)", "[quadric][ci]") {
    for (double s : {0.01, 0.3, 1.0, 7.5}) {
        const double v = s * s;
        const sd ci = pqdc::cross_interference(sd::identity(v), sd::identity(v));
        CHECK(max_abs_diff(ci, sd::identity(2 * v * v)) <= 1e-15 * v * v);
    }
    // Different isotropic variances: Ci[a I, b I] = 2 a b I.
    const sd ci = pqdc::cross_interference(sd::identity(0.5), sd::identity(3.0));
    CHECK(max_abs_diff(ci, sd::identity(3.0)) <= 1e-15);
}

TEST_CASE("cross_interference satisfies Lemma A.5: Tr[A [x]x B [x]x^T] = x^T Ci[A,B] x",
          "[quadric][ci]") {
    rng g(22);
    for (int trial = 0; trial < 500; ++trial) {
        const bool spd = trial % 2 == 0;  // the identity is polynomial: holds for any symmetric A, B
        const sd a = spd ? random_spd(g, g.log_uniform(0.1, 3)) : random_symmetric(g, 2.0);
        const sd b = spd ? random_spd(g, g.log_uniform(0.1, 3)) : random_symmetric(g, 2.0);
        const vd x = g.normal3() * g.log_uniform(0.1, 10);
        const double lhs = pqdc::trace_of_product(a, pqdc::cross_sandwich(x, b));
        const double rhs = pqdc::dot(x, pqdc::cross_interference(a, b) * x);
        const double scale = max_abs(a) * max_abs(b) * pqdc::dot(x, x);
        INFO("trial " << trial);
        CHECK(std::fabs(lhs - rhs) <= 1e-13 * scale);
    }
}

TEST_CASE("cross_interference of SPD matrices is SPD (Theorem A.13)", "[quadric][ci]") {
    rng g(23);
    for (int trial = 0; trial < 500; ++trial) {
        const sd a = random_spd(g, g.log_uniform(0.1, 3)), b = random_spd(g, g.log_uniform(0.1, 3));
        CHECK(eigen_range(pqdc::cross_interference(a, b)).min > 0);
    }
}

// =====================================================================
// classical quadrics: values
// =====================================================================

TEST_CASE("classical plane, triangle and point quadrics evaluate to their squared distances",
          "[quadric]") {
    rng g(31);
    for (int trial = 0; trial < 200; ++trial) {
        const vd q = g.uniform3(-2, 2), n = g.normal3(), x = g.uniform3(-3, 3);
        const double d = pqdc::dot(x - q, n);
        CHECK(qd::plane(q, n)(x) == Approx(d * d).margin(1e-12));
        CHECK(qd::point(q)(x) == Approx(pqdc::length_sqr(x - q)).margin(1e-12));

        const vd p0 = g.uniform3(-2, 2), p1 = g.uniform3(-2, 2), p2 = g.uniform3(-2, 2);
        const vd normal = pqdc::cross(p1 - p0, p2 - p0);  // |normal| = 2 area
        const double twice_area_dist = pqdc::dot(x - p0, normal);
        CHECK(qd::triangle(p0, p1, p2)(x) ==
              Approx(twice_area_dist * twice_area_dist).margin(1e-10));
        // The triangle quadric is the plane quadric of its area-weighted normal.
        const qd t = qd::triangle(p0, p1, p2), pl = qd::plane(p0, normal);
        CHECK(max_abs_diff(t.A, pl.A) <= 1e-12 * (1 + max_abs(t.A)));
        CHECK(pqdc::length(t.b - pl.b) <= 1e-12 * (1 + pqdc::length(t.b)));
        CHECK(t.c == Approx(pl.c).margin(1e-10));
    }
}

TEST_CASE("quadric_terms::a_b gives the same A and b with c = 0", "[quadric]") {
    rng g(32);
    for (int trial = 0; trial < 50; ++trial) {
        const vd p = g.uniform3(-2, 2), q = g.uniform3(-2, 2), r = g.uniform3(-2, 2), n = g.normal3();
        const sd s1 = random_spd(g, 0.3), s2 = random_spd(g, 0.3), s3 = random_spd(g, 0.3);
        constexpr auto ab = pqdc::quadric_terms::a_b;
        const std::pair<qd, qd> pairs[] = {
            {qd::plane(q, n), qd::plane<ab>(q, n)},
            {qd::probabilistic_plane(q, n, 0.2, 0.3), qd::probabilistic_plane<ab>(q, n, 0.2, 0.3)},
            {qd::probabilistic_plane(q, n, s1, s2), qd::probabilistic_plane<ab>(q, n, s1, s2)},
            {qd::triangle(p, q, r), qd::triangle<ab>(p, q, r)},
            {qd::probabilistic_triangle(p, q, r, 0.3), qd::probabilistic_triangle<ab>(p, q, r, 0.3)},
            {qd::probabilistic_triangle(p, q, r, s1, s2, s3),
             qd::probabilistic_triangle<ab>(p, q, r, s1, s2, s3)},
        };
        for (const auto& [full_q, ab_q] : pairs) {
            CHECK(max_abs_diff(full_q.A, ab_q.A) == 0);
            CHECK(full_q.b == ab_q.b);
            CHECK(ab_q.c == 0);
        }
    }
}

// =====================================================================
// probabilistic quadrics == expected classical quadric (Monte Carlo)
// =====================================================================

TEST_CASE("probabilistic plane quadric (isotropic) is the expected plane quadric",
          "[quadric][monte-carlo]") {
    rng g(101);
    const vd q{0.3, -0.7, 0.5}, n{0.48, 0.64, -0.6};
    const double sigma_q = 0.4, sigma_n = 0.5, vq = sigma_q * sigma_q, vn = sigma_n * sigma_n;
    const gaussian3 dq = isotropic(q, sigma_q), dn = isotropic(n, sigma_n);
    const qd closed = qd::probabilistic_plane(q, n, sigma_q, sigma_n);
    entry_statistics stats(closed);
    for (int i = 0; i < kPlaneSamples; ++i) stats.add(qd::plane(dq.sample(g), dn.sample(g)));
    check_closed_form(stats, closed);

    // The tolerance is tight enough to see each noise term.
    qd without_sigma_n = closed;  // Sigma_n in A and b
    without_sigma_n.A -= sd::identity(vn);
    without_sigma_n.b -= q * vn;
    CHECK(stats.rejected_count(without_sigma_n) >= 3);
    qd without_trace = closed;  // Tr[Sigma_n Sigma_q] in c
    without_trace.c -= 3 * vn * vq;
    CHECK(stats.rejected_count(without_trace) == 1);
    qd without_sigma_q = closed;  // n^T Sigma_q n in c
    without_sigma_q.c -= vq * pqdc::dot(n, n);
    CHECK(stats.rejected_count(without_sigma_q) == 1);

    // The general overload with Sigma = sigma^2 I agrees to rounding.
    const qd general = qd::probabilistic_plane(q, n, sd::identity(vq), sd::identity(vn));
    CHECK(max_abs_diff(general.A, closed.A) <= 1e-15);
    CHECK(pqdc::length(general.b - closed.b) <= 1e-15);
    CHECK(general.c == Approx(closed.c).epsilon(1e-14));
}

TEST_CASE("probabilistic plane quadric (general covariances) is the expected plane quadric",
          "[quadric][monte-carlo]") {
    rng g(102);
    const vd q{-0.4, 0.9, 0.2}, n{0.2, -0.9, 0.35};
    const gaussian3 dq = anisotropic(g, q, 0.6), dn = anisotropic(g, n, 0.6);
    const sd Sq = dq.covariance(), Sn = dn.covariance();
    const qd closed = qd::probabilistic_plane(q, n, Sq, Sn);
    entry_statistics stats(closed);
    for (int i = 0; i < kPlaneSamples; ++i) stats.add(qd::plane(dq.sample(g), dn.sample(g)));
    check_closed_form(stats, closed);

    qd without_sigma_n = closed;
    without_sigma_n.A -= Sn;
    without_sigma_n.b -= Sn * q;
    CHECK(stats.rejected_count(without_sigma_n) >= 3);
    qd without_trace = closed;
    without_trace.c -= pqdc::trace_of_product(Sn, Sq);
    CHECK(stats.rejected_count(without_trace) == 1);
    // Swapping the roles of the two covariances must be visible too.
    const qd swapped = qd::probabilistic_plane(q, n, Sn, Sq);
    CHECK(stats.rejected_count(swapped) >= 3);
}

TEST_CASE("probabilistic triangle quadric (isotropic) is the expected triangle quadric",
          "[quadric][monte-carlo]") {
    rng g(103);
    const vd p{0.2, 0.1, 0.4}, q{1.3, 0.2, -0.1}, r{0.5, 1.1, 0.3};
    const double sigma = 0.5, v = sigma * sigma;
    const gaussian3 dp = isotropic(p, sigma), dq = isotropic(q, sigma), dr = isotropic(r, sigma);
    const qd closed = qd::probabilistic_triangle(p, q, r, sigma);
    entry_statistics stats(closed);
    for (int i = 0; i < kTriangleSamples; ++i)
        stats.add(qd::triangle(dp.sample(g), dq.sample(g), dr.sample(g)));
    check_closed_form(stats, closed);

    // O(Sigma^2) terms: Ci = 2 sigma^4 I, three times in A.
    qd without_ci = closed;
    without_ci.A -= sd::identity(6 * v * v);
    CHECK(stats.rejected_count(without_ci) >= 3);
    qd without_ci_b = closed;
    without_ci_b.b -= (p + q + r) * (2 * v * v);
    CHECK(stats.rejected_count(without_ci_b) >= 1);
    // O(Sigma^3) term of c: Tr[Sigma_r Ci[Sigma_p, Sigma_q]] = 6 sigma^6.
    qd without_cubic = closed;
    without_cubic.c -= 6 * v * v * v;
    CHECK(stats.rejected_count(without_cubic) == 1);

    const qd general = qd::probabilistic_triangle(p, q, r, sd::identity(v), sd::identity(v), sd::identity(v));
    CHECK(max_abs_diff(general.A, closed.A) <= 1e-14 * max_abs(closed.A));
    CHECK(pqdc::length(general.b - closed.b) <= 1e-14 * pqdc::length(closed.b));
    CHECK(general.c == Approx(closed.c).epsilon(1e-14));
}

TEST_CASE("probabilistic triangle quadric (general covariances) is the expected triangle quadric",
          "[quadric][monte-carlo]") {
    rng g(104);
    const vd p{-0.3, 0.2, 0.5}, q{0.9, -0.1, 0.1}, r{0.1, 1.2, -0.4};
    const gaussian3 dp = anisotropic(g, p, 0.7), dq = anisotropic(g, q, 0.5), dr = anisotropic(g, r, 0.6);
    const sd Sp = dp.covariance(), Sq = dq.covariance(), Sr = dr.covariance();
    const qd closed = qd::probabilistic_triangle(p, q, r, Sp, Sq, Sr);
    entry_statistics stats(closed);
    for (int i = 0; i < kTriangleSamples; ++i)
        stats.add(qd::triangle(dp.sample(g), dq.sample(g), dr.sample(g)));
    check_closed_form(stats, closed);

    const sd ci_pq = pqdc::cross_interference(Sp, Sq), ci_qr = pqdc::cross_interference(Sq, Sr),
             ci_rp = pqdc::cross_interference(Sr, Sp);
    qd without_ci = closed;
    without_ci.A -= ci_pq + ci_qr + ci_rp;
    CHECK(stats.rejected_count(without_ci) >= 3);
    qd without_ci_b = closed;
    without_ci_b.b -= ci_pq * r + ci_qr * p + ci_rp * q;
    CHECK(stats.rejected_count(without_ci_b) >= 1);
    qd without_cubic = closed;
    without_cubic.c -= pqdc::trace_of_product(Sr, ci_pq);
    CHECK(stats.rejected_count(without_cubic) == 1);
    // Each covariance must pair with its own opposite edge: permuting them is visible.
    const qd permuted = qd::probabilistic_triangle(p, q, r, Sq, Sr, Sp);
    CHECK(stats.rejected_count(permuted) >= 3);
}

// =====================================================================
// positive definiteness and the closed-form solve
// =====================================================================

namespace {

template <class T>
quadric<T> probabilistic_cell_quadric(rng& g, const std::vector<plane_sample>& planes, double sigma_n,
                                      bool general) {
    quadric<T> sum;
    for (const plane_sample& s : planes) {
        const vec3<T> pt(s.point), n(s.normal);
        if (general)
            sum += quadric<T>::probabilistic_plane(pt, n, sym3<T>(random_spd(g, 0.1)),
                                                   sym3<T>(random_spd(g, sigma_n)));
        else
            sum += quadric<T>::probabilistic_plane(pt, n, T(0.05), T(sigma_n));
    }
    return sum;
}

/// Triangles of size ~1: generic, slivers, exactly collinear, coincident, fans.
template <class T>
quadric<T> random_triangle_quadric(rng& g, int layout, double sigma, bool general) {
    auto one = [&](const vd& p, const vd& q, const vd& r) {
        const vec3<T> a(p), b(q), c(r);
        if (general)
            return quadric<T>::probabilistic_triangle(a, b, c, sym3<T>(random_spd(g, sigma)),
                                                      sym3<T>(random_spd(g, sigma)),
                                                      sym3<T>(random_spd(g, sigma)));
        return quadric<T>::probabilistic_triangle(a, b, c, T(sigma));
    };
    const vd p = g.uniform3(-1, 1), q = g.uniform3(-1, 1);
    switch (layout) {
        case 0: return one(p, q, g.uniform3(-1, 1));
        case 1: return one(p, q, p + (q - p) * 0.4 + g.normal3() * 1e-4);  // sliver
        case 2: return one(p, q, p + (q - p) * 0.5);                        // collinear
        case 3: return one(p, p, p);                                        // a point
        default: {
            quadric<T> fan;  // a coplanar fan: the sum has a rank-1 classical part
            const vd n = g.unit3();
            vd prev = q - n * pqdc::dot(q - p, n);
            for (int i = 0; i < 5; ++i) {
                const vd u = g.uniform3(-1, 1);
                const vd next = p + (u - n * pqdc::dot(u, n));
                fan += one(p, prev, next);
                prev = next;
            }
            return fan;
        }
    }
}

/// Checks that A is positive definite and that minimizer_positive_definite,
/// when it answers, is as accurate as its contract says: the adjugate solve
/// loses ~cond(A) eps from rounding b and, from the cancellation in det,
/// eps trace^3 / det relative (which the det > 64 eps trace^3 guard caps).
/// Returns whether it answered.
template <class T>
bool check_positive_definite_solve(const quadric<T>& q, const std::string& what) {
    INFO(what);
    const spectrum s = eigen_range(sd(q.A));
    INFO("eigenvalues [" << s.min << ", " << s.max << "], condition " << s.condition());
    REQUIRE(s.min > 0);
    const std::optional<vec3<T>> x = pqdc::minimizer_positive_definite(q);
    if (!x) return false;
    const std::optional<vec3<ld>> ref = reference_solve(q);
    REQUIRE(ref.has_value());
    const vd exact = to_double(*ref);
    const double err = pqdc::distance(vd(*x), exact);
    const double tr = double(q.A.trace());
    const double det_cancellation = tr * tr * tr / sd(q.A).determinant();
    const double unit = double(std::numeric_limits<T>::epsilon()) * std::max(1.0, pqdc::length(exact)) *
                        (s.condition() + det_cancellation);
    INFO("x error " << err << " error unit " << unit);
    CHECK(err <= unit);  // measured: err / unit <= 0.09 over all cases below
    return true;
}

}  // namespace

TEMPLATE_TEST_CASE("probabilistic plane quadrics are positive definite and solvable with A^-1 b",
                   "[quadric][positive-definite]", float, double) {
    rng g(201);
    constexpr bool is_float = std::is_same<TestType, float>::value;
    // The documented acceptance limit of minimizer_positive_definite for unit
    // normals and isotropic noise (attained on flat regions).
    const double sigma_accepted = is_float ? 0.06 : 4e-4;
    const double sigma_min = is_float ? 0.01 : 1e-4;
    int rejected = 0;
    for (int trial = 0; trial < 2000; ++trial) {
        const int layout = trial % 4;
        const int count = g.integer(std::max(layout, 1), 12);
        const std::vector<plane_sample> planes = random_cell_planes(g, layout, count);
        const double sigma_n = g.log_uniform(sigma_min, 10.0);
        const bool general = trial % 3 == 0;
        const quadric<TestType> q = probabilistic_cell_quadric<TestType>(g, planes, sigma_n, general);
        const std::string what = "trial " + std::to_string(trial) + " layout " + std::to_string(layout) +
                                 " planes " + std::to_string(count) + " sigma_n " + std::to_string(sigma_n) +
                                 (general ? " general" : " isotropic");
        const bool solved = check_positive_definite_solve(q, what);
        rejected += solved ? 0 : 1;
        if (!general && sigma_n >= sigma_accepted) {
            INFO(what);
            CHECK(solved);
        }
    }
    CHECK(rejected < 300);  // ~100 of 2000 are below the limit
}

TEMPLATE_TEST_CASE("probabilistic triangle quadrics are positive definite and solvable with A^-1 b",
                   "[quadric][positive-definite]", float, double) {
    rng g(202);
    constexpr bool is_float = std::is_same<TestType, float>::value;
    // For triangles of size ~1 (measured: all isotropic sigma >= 0.06 float,
    // >= 4e-4 double pass; the limit scales with the triangle's size).
    const double sigma_accepted = is_float ? 0.15 : 1.5e-3;
    const double sigma_min = is_float ? 0.01 : 1e-4;
    int rejected = 0;
    for (int trial = 0; trial < 2000; ++trial) {
        const int layout = trial % 5;
        const double sigma = g.log_uniform(sigma_min, 1.0);
        const bool general = trial % 3 == 0;
        const quadric<TestType> q = random_triangle_quadric<TestType>(g, layout, sigma, general);
        const std::string what = "trial " + std::to_string(trial) + " layout " + std::to_string(layout) +
                                 " sigma " + std::to_string(sigma) + (general ? " general" : " isotropic");
        const bool solved = check_positive_definite_solve(q, what);
        rejected += solved ? 0 : 1;
        if (!general && sigma >= sigma_accepted) {
            INFO(what);
            CHECK(solved);
        }
    }
    CHECK(rejected < 400);
}

TEST_CASE("minimizer_positive_definite refuses singular, indefinite and non-finite input",
          "[quadric][positive-definite]") {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const double inf = std::numeric_limits<double>::infinity();
    rng g(203);
    const vd n1 = g.unit3(), n2 = g.unit3(), n3 = g.unit3(), o = g.uniform3(0, 1);

    CHECK_FALSE(pqdc::minimizer_positive_definite(qd{}).has_value());
    CHECK_FALSE(pqdc::minimizer_positive_definite(qd::plane(o, n1)).has_value());
    CHECK_FALSE(pqdc::minimizer_positive_definite(qd::plane(o, n1) + qd::plane(o, n2)).has_value());
    CHECK_FALSE(pqdc::minimizer_positive_definite(qd::plane(o, n1) * 5.0 + qd::plane(o, n1) * 2.0 +
                                                  qd::plane(o + n2, n1))
                    .has_value());
    CHECK_FALSE(pqdc::minimizer_positive_definite(qf::plane(vf(o), vf(n1)) + qf::plane(vf(o), vf(n2)))
                    .has_value());
    // Three planes are fine.
    CHECK(pqdc::minimizer_positive_definite(qd::plane(o, n1) + qd::plane(o, n2) + qd::plane(o, n3))
              .has_value());

    // Indefinite with positive trace and determinant: a saddle, not a minimum.
    qd saddle;
    saddle.A = {-1, 0, 0, -1, 0, 3};
    saddle.b = {1, 1, 1};
    CHECK_FALSE(pqdc::minimizer_positive_definite(saddle).has_value());
    qd rotated_saddle;  // the same in a rotated frame
    {
        const vd u = pqdc::cross(n1, n2) / pqdc::length(pqdc::cross(n1, n2));
        const vd w = pqdc::cross(u, n1);
        rotated_saddle.A = sd::outer(n1) * -1.0 + sd::outer(u) * -2.0 + sd::outer(w) * 4.0;
        rotated_saddle.b = {0.5, -1, 2};
    }
    CHECK_FALSE(pqdc::minimizer_positive_definite(rotated_saddle).has_value());
    qd negative;
    negative.A = sd::identity(-1.0);
    CHECK_FALSE(pqdc::minimizer_positive_definite(negative).has_value());

    // Non-finite input never produces a non-finite answer.
    const qd good = qd::probabilistic_plane(o, n1, 0.0, 0.1);
    REQUIRE(pqdc::minimizer_positive_definite(good).has_value());
    for (double bad : {nan, inf, -inf}) {
        for (int entry = 0; entry < 9; ++entry) {
            qd q = good;
            double* slots[9] = {&q.A.a00, &q.A.a01, &q.A.a02, &q.A.a11, &q.A.a12,
                                &q.A.a22, &q.b.x,   &q.b.y,   &q.b.z};
            *slots[entry] = bad;
            INFO("entry " << entry << " = " << bad);
            const std::optional<vd> x = pqdc::minimizer_positive_definite(q);
            if (x) CHECK(pqdc::is_finite(*x));
            CHECK_FALSE(x.has_value());
        }
    }
    // Garbage in float: whatever comes out is finite.
    for (int trial = 0; trial < 2000; ++trial) {
        qf q;
        const double scale = g.log_uniform(1e-30, 1e30);
        q.A = sym3<float>(random_symmetric(g, scale));
        q.b = vf(g.normal3() * g.log_uniform(1e-30, 1e30));
        const std::optional<vf> x = pqdc::minimizer_positive_definite(q);
        if (x) CHECK(pqdc::is_finite(*x));
    }
}

// =====================================================================
// limits in sigma_n
// =====================================================================

TEST_CASE("sigma -> 0 gives the classical quadric", "[quadric][limits]") {
    rng g(301);
    for (int trial = 0; trial < 50; ++trial) {
        const vd q = g.uniform3(-2, 2), n = g.normal3(), p = g.uniform3(-2, 2), r = g.uniform3(-2, 2);
        const qd plane = qd::plane(q, n);
        const qd iso = qd::probabilistic_plane(q, n, 0.0, 0.0);
        CHECK(max_abs_diff(iso.A, plane.A) == 0);
        CHECK(iso.b == plane.b);
        CHECK(iso.c == plane.c);
        const qd gen = qd::probabilistic_plane(q, n, sd::zero(), sd::zero());
        CHECK(max_abs_diff(gen.A, plane.A) == 0);
        CHECK(pqdc::length(gen.b - plane.b) <= 1e-14 * (1 + pqdc::length(plane.b)));
        CHECK(gen.c == Approx(plane.c).margin(1e-13));

        const qd tri = qd::triangle(p, q, r);
        const qd tiso = qd::probabilistic_triangle(p, q, r, 0.0);
        const qd tgen = qd::probabilistic_triangle(p, q, r, sd::zero(), sd::zero(), sd::zero());
        for (const qd& t : {tiso, tgen}) {
            CHECK(max_abs_diff(t.A, tri.A) <= 1e-14 * max_abs(tri.A));
            CHECK(pqdc::length(t.b - tri.b) <= 1e-14 * (1 + pqdc::length(tri.b)));
            CHECK(t.c == Approx(tri.c).margin(1e-12));
        }
    }
}

TEST_CASE("small sigma_n: the minimizer converges to the classical one as O(sigma_n^2)",
          "[quadric][limits]") {
    rng g(302);
    for (int layout = 1; layout <= 3; ++layout) {
        for (int trial = 0; trial < 20; ++trial) {
            const std::vector<plane_sample> planes = random_cell_planes(g, layout, 9);
            qd classical;
            pqdc::mass_point<double> mass;
            for (const plane_sample& s : planes) {
                classical += qd::plane(s.point, s.normal);
                mass.add(s.point);
            }
            // Rank-deficient classical sums have a family of minimizers; the
            // probabilistic limit picks the one nearest the mass point (the
            // Tikhonov reading of eqs. 6-7), which is what the pseudo-inverse
            // returns for reference = mass point.
            const vd limit = pqdc::minimizer_pseudo_inverse(classical, *mass.point(), 1e-9).point;
            auto error = [&](double sigma_n) {
                qd sum;
                for (const plane_sample& s : planes) sum += qd::probabilistic_plane(s.point, s.normal, 0.0, sigma_n);
                return pqdc::distance(*pqdc::minimizer_positive_definite(sum), limit);
            };
            INFO("layout " << layout << " trial " << trial);
            if (layout == 1) {
                // Parallel planes through one plane: the minimizer is the mass
                // point (already on the plane) for every sigma_n.
                for (double sigma_n : {1.0, 0.1, 0.01}) {
                    INFO("sigma_n " << sigma_n);
                    CHECK(error(sigma_n) <= 1e-8);
                }
                continue;
            }
            // The O(sigma_n^2) coefficient grows with the classical sum's
            // conditioning on its range (random corners can be nearly flat).
            const pqdc::sym3_eigen e = pqdc::eigen_decompose(classical.A);
            const double lmax = std::max({e.values[0], e.values[1], e.values[2]});
            double lmin = lmax;
            for (double l : e.values)
                if (l > 1e-9 * lmax) lmin = std::min(lmin, l);
            // Asymptotic regime: N sigma_n^2 well below lmin; not so small that
            // the (cond ~ 1 / sigma_n^2) solve is dominated by rounding.
            const double sigma1 = std::min(1e-2, 0.1 * std::sqrt(lmin / classical.A.trace()));
            const double e1 = error(sigma1), e2 = error(sigma1 / 10);
            INFO("sigma_n " << sigma1 << " errors " << e1 << " " << e2 << ", range condition " << lmax / lmin);
            CHECK(e1 <= 10 * (lmax / lmin) * sigma1 * sigma1);
            CHECK(e1 / e2 == Approx(100).epsilon(0.05));  // quadratic in sigma_n
        }
    }
}

TEST_CASE("large sigma_n: the minimizer tends to the mass point of the plane points",
          "[quadric][limits]") {
    rng g(303);
    for (int layout = 0; layout <= 3; ++layout) {
        for (int trial = 0; trial < 20; ++trial) {
            const std::vector<plane_sample> planes = random_cell_planes(g, layout, g.integer(3, 12));
            pqdc::mass_point<double> mass;
            for (const plane_sample& s : planes) mass.add(s.point);
            const vd centroid = *mass.point();
            auto error = [&](double sigma_n) {
                qd sum;
                for (const plane_sample& s : planes) sum += qd::probabilistic_plane(s.point, s.normal, 0.0, sigma_n);
                return pqdc::distance(*pqdc::minimizer_positive_definite(sum), centroid);
            };
            const double e1 = error(1e2), e2 = error(1e3);
            INFO("layout " << layout << " trial " << trial << " errors " << e1 << " " << e2);
            CHECK(e1 <= 1e-4);
            CHECK(e2 <= 1e-6);
            if (e1 > 1e-12) CHECK(e1 / e2 == Approx(100).epsilon(0.05));  // O(1/sigma_n^2)
        }
    }
}

TEST_CASE("mass_point averages with weights and merges", "[quadric]") {
    pqdc::mass_point<double> a, b;
    CHECK_FALSE(a.point().has_value());
    a.add({1, 2, 3});
    a.add({3, 2, 1}, 3.0);
    b.add({0, 0, 4});
    const vd m = *(a + b).point();
    CHECK(m.x == Approx((1 + 9 + 0) / 5.0));
    CHECK(m.y == Approx((2 + 6 + 0) / 5.0));
    CHECK(m.z == Approx((3 + 3 + 4) / 5.0));
    a += b;
    CHECK(*a.point() == m);
}

// =====================================================================
// relative_to: moving the origin
// =====================================================================

namespace {

template <class T>
quadric<T> random_world_quadric(rng& g, const vd& near) {
    quadric<T> q;
    for (int i = 0; i < 8; ++i)
        q += quadric<T>::probabilistic_plane(vec3<T>(near + g.uniform3(0, 1)), vec3<T>(g.unit3()), T(0.05),
                                             T(0.2));
    q += quadric<T>::probabilistic_triangle(vec3<T>(near + g.uniform3(0, 1)), vec3<T>(near + g.uniform3(0, 1)),
                                            vec3<T>(near + g.uniform3(0, 1)), T(0.1));
    return q;
}

}  // namespace

TEMPLATE_TEST_CASE("relative_to re-origins the value and the minimizer", "[quadric][relative_to]", float,
                   double) {
    using T = TestType;
    const double eps = double(std::numeric_limits<T>::epsilon());
    rng g(401);
    for (int trial = 0; trial < 200; ++trial) {
        const vd near = g.uniform3(-50, 50);
        const quadric<T> q = random_world_quadric<T>(g, near);
        const vec3<T> origin(near + g.uniform3(-2, 2));
        const quadric<T> r = q.relative_to(origin);
        // Reference: the same quadric evaluated in long double.
        const quadric<ld> ql = static_cast<quadric<ld>>(q);
        for (int k = 0; k < 10; ++k) {
            const vd y = g.uniform3(-2, 2);
            const vec3<ld> x = vec3<ld>(origin) + vec3<ld>(y);
            const ld expected = ql(x);
            // Rounding scale of the relative quadric's own terms.
            const double scale = max_abs(sd(r.A)) * pqdc::dot(y, y) + 2 * pqdc::length(vd(r.b)) * pqdc::length(y) +
                                 std::fabs(double(r.c));
            INFO("trial " << trial << " value " << double(r(vec3<T>(y))) << " expected " << double(expected));
            CHECK(std::fabs(double(r(vec3<T>(y))) - double(expected)) <= 64 * eps * scale + 1e-300);
        }
        CHECK(max_abs_diff(sd(r.A), sd(q.A)) == 0);
        const std::optional<vec3<T>> xq = pqdc::minimizer_positive_definite(q);
        const std::optional<vec3<T>> xr = pqdc::minimizer_positive_definite(r);
        REQUIRE(xq.has_value());
        REQUIRE(xr.has_value());
        const double cond = eigen_range(sd(q.A)).condition();
        // x_r = x_q - origin up to the solve's rounding at world scale.
        CHECK(pqdc::distance(vd(*xr), vd(*xq) - vd(origin)) <= 16 * cond * eps * (1 + pqdc::length(vd(*xq))));

        const quadric<T> back = r.relative_to(-origin);
        CHECK(pqdc::length(vd(back.b - q.b)) <= 64 * eps * (1 + pqdc::length(vd(q.b))));
        const quadric<T> same = q.relative_to(vec3<T>(0, 0, 0));
        CHECK(same.b == q.b);
        CHECK(same.c == q.c);
    }
}

TEST_CASE("float quadrics far from the origin need cell-local coordinates", "[quadric][relative_to]") {
    // A dual-contouring cell [O, O + 1]^3 far from the world origin with a
    // sharp corner inside. Inputs are exactly representable in float at world
    // scale (multiples of 1/64 near 1e5), so every error below comes from
    // accumulating the quadric, not from rounding the inputs.
    const vd O{1e5, 1e5, 1e5};
    const double sigma_n = 0.1;
    rng g(402);
    for (int layout = 1; layout <= 3; ++layout) {
        const vd normals[3] = {vd(vf(g.unit3())), vd(vf(g.unit3())), vd(vf(g.unit3()))};
        const vd corner{23 / 64.0, 39 / 64.0, 19 / 64.0};
        std::vector<plane_sample> samples;  // local coordinates
        for (int i = 0; i < 12; ++i) {
            const vd n = normals[i % layout];
            const vd u = g.uniform3(-0.3, 0.3);
            vd pt = corner + (u - n * pqdc::dot(u, n));
            pt = {std::round(pt.x * 64) / 64, std::round(pt.y * 64) / 64, std::round(pt.z * 64) / 64};
            samples.push_back({pt, n});
        }
        qd local_d, world_d;
        qf local_f, world_f;
        for (const plane_sample& s : samples) {
            local_d += qd::probabilistic_plane(s.point, s.normal, 0.0, sigma_n);
            world_d += qd::probabilistic_plane(O + s.point, s.normal, 0.0, sigma_n);
            REQUIRE(vd(vf(O + s.point)) == O + s.point);  // exact in float
            local_f += qf::probabilistic_plane(vf(s.point), vf(s.normal), 0.f, float(sigma_n));
            world_f += qf::probabilistic_plane(vf(O + s.point), vf(s.normal), 0.f, float(sigma_n));
        }
        const vd truth = *pqdc::minimizer_positive_definite(local_d);

        const double local_error = pqdc::distance(vd(*pqdc::minimizer_positive_definite(local_f)), truth);
        const double world_double_error =
            pqdc::distance(*pqdc::minimizer_positive_definite(world_d) - O, truth);
        const std::optional<vf> world_solve = pqdc::minimizer_positive_definite(world_f);
        REQUIRE(world_solve.has_value());
        const double world_error = pqdc::distance(vd(*world_solve) - O, truth);
        // Moving the world quadric to the cell afterwards cannot restore the lost bits.
        const std::optional<vf> moved_solve = pqdc::minimizer_positive_definite(world_f.relative_to(vf(O)));
        REQUIRE(moved_solve.has_value());
        const double moved_error = pqdc::distance(vd(*moved_solve), truth);

        INFO("layout " << layout << ": float local " << local_error << ", double world " << world_double_error
                       << ", float world " << world_error << ", float world moved to cell " << moved_error);
        // Measured (GCC 12, x86-64): local 2e-5 / 1e-6 / 4e-8 for flat / edge /
        // corner; world 4 / 0.17 / 0.02; moved to the cell 1 / 0.13 / 0.02.
        CHECK(local_error < 1e-4);
        CHECK(world_double_error < 1e-6);
        CHECK(world_error > 5e-3);
        CHECK(moved_error > 5e-3);
    }
}

// =====================================================================
// pseudo-inverse (classical quadrics)
// =====================================================================

namespace {

/// The unit vector at `angle` from unit n, in the plane of n and `towards`.
vd rotate_away(const vd& n, const vd& towards, double angle) {
    vd t = towards - n * pqdc::dot(towards, n);
    if (pqdc::length(t) < 1e-3) t = pqdc::cross(n, std::fabs(n.x) < 0.9 ? vd{1, 0, 0} : vd{0, 1, 0});
    t = t / pqdc::length(t);
    return n * std::cos(angle) + t * std::sin(angle);
}

vd project_onto_plane(const vd& x, const vd& q, const vd& n) {
    return x - n * (pqdc::dot(x - q, n) / pqdc::dot(n, n));
}
vd project_onto_line(const vd& x, const vd& on_line, const vd& dir) {
    return on_line + dir * (pqdc::dot(x - on_line, dir) / pqdc::dot(dir, dir));
}

}  // namespace

TEST_CASE("minimizer_pseudo_inverse: planar, edge and corner configurations", "[quadric][pseudo-inverse]") {
    rng g(501);
    for (int trial = 0; trial < 200; ++trial) {
        const vd f = g.uniform3(0, 1), ref = g.uniform3(-1, 2);
        const vd n1 = g.unit3(), n3 = g.unit3();
        const vd t1 = pqdc::cross(n1, g.unit3());
        // n2 at 60..120 degrees from n1: a feature edge (with the default
        // cutoff 0.1, dihedral deviations below ~35 degrees count as flat).
        const vd n2 = rotate_away(n1, g.unit3(), g.uniform(kPi / 3, 2 * kPi / 3));
        const vd t2 = pqdc::cross(n1, n2);
        INFO("trial " << trial);

        // Rank 1: coplanar samples; the answer is the reference projected onto the plane.
        const qd flat = qd::plane(f, n1) + qd::plane(f + t1 * 0.3, n1 * 2.0) + qd::plane(f - t1, n1 * 0.5);
        const auto r1 = pqdc::minimizer_pseudo_inverse(flat, ref);
        CHECK(r1.rank == 1);
        CHECK(pqdc::distance(r1.point, project_onto_plane(ref, f, n1)) <= 1e-12);

        // Rank 2: two planes through a line; the reference projected onto the line.
        const qd edge = qd::plane(f, n1) + qd::plane(f + t2 * 0.7, n2) + qd::plane(f - t2 * 0.2, n1);
        const auto r2 = pqdc::minimizer_pseudo_inverse(edge, ref);
        CHECK(r2.rank == 2);
        CHECK(pqdc::distance(r2.point, project_onto_line(ref, f, t2)) <= 1e-11);

        // Rank 3: the intersection point, whatever the reference.
        if (std::fabs(pqdc::dot(t2, n3)) < 0.2 * pqdc::length(t2)) continue;
        const qd corner = edge + qd::plane(f, n3);
        const auto r3 = pqdc::minimizer_pseudo_inverse(corner, ref, 1e-6);
        CHECK(r3.rank == 3);
        CHECK(pqdc::distance(r3.point, f) <= 1e-10);
        const auto r3b = pqdc::minimizer_pseudo_inverse(corner, ref + g.normal3() * 10.0, 1e-6);
        CHECK(pqdc::distance(r3b.point, f) <= 1e-10);

        // Translating quadric and reference together translates the answer.
        const vd o = g.uniform3(-5, 5);
        const auto moved = pqdc::minimizer_pseudo_inverse(edge.relative_to(o), ref - o);
        CHECK(pqdc::distance(moved.point + o, r2.point) <= 1e-10);
    }
}

TEST_CASE("minimizer_pseudo_inverse: noisy near-degenerate configurations", "[quadric][pseudo-inverse]") {
    rng g(502);
    for (int trial = 0; trial < 200; ++trial) {
        INFO("trial " << trial);
        const vd f = g.uniform3(0, 1), n = g.unit3();
        pqdc::mass_point<double> mass;
        qd flat;
        // Almost coplanar: normals tilted by ~1e-3 rad, points off the plane by ~1e-4.
        for (int i = 0; i < 8; ++i) {
            const vd u = g.uniform3(-0.5, 0.5);
            const vd pt = f + (u - n * pqdc::dot(u, n)) + n * (1e-4 * g.normal());
            const vd ni = n + g.normal3() * 1e-3;
            flat += qd::plane(pt, ni / pqdc::length(ni));
            mass.add(pt);
        }
        const vd ref = *mass.point();
        const auto r = pqdc::minimizer_pseudo_inverse(flat, ref);
        CHECK(r.rank == 1);
        // Stays at the reference, within the noise, instead of running off
        // along the barely constrained in-plane directions.
        CHECK(pqdc::distance(r.point, project_onto_plane(ref, f, n)) <= 1e-3);
        CHECK(pqdc::distance(r.point, ref) <= 1e-3);
        // Without truncation (cutoff 0) the exact least-squares answer is the
        // reference solve, far from the samples in some trials: this is why the
        // cutoff exists (not asserted per trial).
        const auto exact = pqdc::minimizer_pseudo_inverse(flat, ref, 0.0);
        CHECK(exact.rank == 3);
        const std::optional<vec3<ld>> ls = reference_solve(flat);
        REQUIRE(ls.has_value());
        CHECK(pqdc::distance(exact.point, to_double(*ls)) <=
              1e-15 * eigen_range(flat.A).condition() * (1 + pqdc::length(to_double(*ls))));

        // A noisy edge: two normal clusters 60..120 degrees apart.
        const vd n2 = rotate_away(n, g.unit3(), g.uniform(kPi / 3, 2 * kPi / 3));
        const vd dir = pqdc::cross(n, n2);
        qd edge;
        for (int i = 0; i < 10; ++i) {
            const vd ni = (i % 2 ? n : n2) + g.normal3() * 1e-3;
            const vd pt = f + dir * g.uniform(-0.5, 0.5) + ni * (1e-4 * g.normal());
            edge += qd::plane(pt, ni / pqdc::length(ni));
        }
        const vd eref = g.uniform3(0, 1);
        const auto re = pqdc::minimizer_pseudo_inverse(edge, eref);
        CHECK(re.rank == 2);
        // Normal tilts of ~1e-3 rad move the line by ~1e-3 at distance ~1.
        CHECK(pqdc::distance(re.point, project_onto_line(eref, f, dir)) <= 3e-3);
    }
}

TEST_CASE("minimizer_pseudo_inverse: reference handling and bad input", "[quadric][pseudo-inverse]") {
    const vd ref{0.25, -0.5, 0.75};
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const double inf = std::numeric_limits<double>::infinity();

    const auto zero = pqdc::minimizer_pseudo_inverse(qd{}, ref);
    CHECK(zero.rank == 0);
    CHECK(zero.point == ref);

    const qd good = qd::plane({0, 0, 0}, {0, 0, 1}) + qd::plane({0, 0, 0}, {1, 0, 0});
    for (double bad : {nan, inf, -inf}) {
        for (int entry = 0; entry < 9; ++entry) {
            qd q = good;
            double* slots[9] = {&q.A.a00, &q.A.a01, &q.A.a02, &q.A.a11, &q.A.a12,
                                &q.A.a22, &q.b.x,   &q.b.y,   &q.b.z};
            *slots[entry] = bad;
            INFO("entry " << entry << " = " << bad);
            const auto r = pqdc::minimizer_pseudo_inverse(q, ref);
            CHECK(r.rank == 0);
            CHECK(r.point == ref);
        }
    }
    // The unconstrained direction (y) keeps the reference's coordinate.
    const auto e = pqdc::minimizer_pseudo_inverse(good, ref);
    CHECK(e.rank == 2);
    CHECK(e.point.x == Approx(0).margin(1e-15));
    CHECK(e.point.y == ref.y);
    CHECK(e.point.z == Approx(0).margin(1e-15));
    // Cutoff: a weak third plane counts only when above the cutoff.
    const qd weak = good + qd::plane({0, 0.5, 0}, {0, 0.2, 0});  // eigenvalue 0.04 of 1
    CHECK(pqdc::minimizer_pseudo_inverse(weak, ref, 0.1).rank == 2);
    const auto strong = pqdc::minimizer_pseudo_inverse(weak, ref);  // default cutoff 0.01
    CHECK(strong.rank == 3);
    CHECK(strong.point.y == Approx(0.5));

    // Float quadrics work the same (computed in double internally).
    const qf gf = qf::plane({0, 0, 0}, {0, 0, 1}) + qf::plane({0, 0, 0}, {1, 0, 0});
    const auto ef = pqdc::minimizer_pseudo_inverse(gf, vf(ref));
    CHECK(ef.rank == 2);
    CHECK(ef.point.y == float(ref.y));
    CHECK(std::fabs(ef.point.x) <= 1e-7f);
}

// =====================================================================
// eigen_decompose
// =====================================================================

TEST_CASE("eigen_decompose reconstructs the matrix with orthonormal vectors", "[quadric][eigen]") {
    rng g(601);
    std::vector<sd> cases = {sd::zero(), sd::identity(), sd::identity(-3.0), sd{1, 0, 0, 2, 0, 3},
                             sd::outer({1, 2, 3}), sd{0, 1, 0, 0, 0, 0}, sd{1e-200, 0, 0, 1, 0, 1e200}};
    for (int i = 0; i < 500; ++i) cases.push_back(random_symmetric(g, g.log_uniform(1e-6, 1e6)));
    for (int i = 0; i < 200; ++i) {  // repeated eigenvalues in a random frame
        const vd a = g.unit3();
        const double l1 = g.uniform(-2, 2), l2 = i % 3 == 0 ? l1 : g.uniform(-2, 2);
        cases.push_back(sd::identity(l1) + sd::outer(a) * (l2 - l1));  // eigenvalues l1, l1, l2
    }
    for (std::size_t k = 0; k < cases.size(); ++k) {
        const sd& m = cases[k];
        const pqdc::sym3_eigen e = pqdc::eigen_decompose(m);
        sd rebuilt = sd::zero();
        for (int i = 0; i < 3; ++i) rebuilt += sd::outer(e.vectors[i]) * e.values[i];
        INFO("case " << k);
        CHECK(max_abs_diff(rebuilt, m) <= 1e-14 * max_abs(m));
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j)
                CHECK(std::fabs(pqdc::dot(e.vectors[i], e.vectors[j]) - (i == j ? 1.0 : 0.0)) <= 1e-14);
        // Eigenvalues are eigenvalues: M v = l v.
        for (int i = 0; i < 3; ++i)
            CHECK(pqdc::length(m * e.vectors[i] - e.vectors[i] * e.values[i]) <= 1e-14 * (1e-300 + max_abs(m)));
    }
}
