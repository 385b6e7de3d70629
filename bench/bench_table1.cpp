// Reproduces Table 1 of Trettner & Kobbelt 2020 ("Fast and Robust QEF
// Minimization using Probabilistic Quadrics"): single-thread, single-precision
// throughput of constructing classical and probabilistic plane/triangle
// quadrics and of minimizing them (A^-1 b versus SVDs).
//
// Every row streams over large arrays (4M inputs by default, so construction
// is limited by memory traffic as in the paper) generated once per run and
// shared by all rows, writes its results to an output array, and the output is
// checksummed afterwards so the work cannot be optimized away. A row's time is
// the fastest of several passes over its array, in thread CPU time.
//
// Usage: bench_table1 [--quick] [--csv]
//   --quick  small arrays and one pass per row (smoke test, numbers meaningless)
//   --csv    print only CSV: a header, then "row",ops_per_second per row
#include "pqdc/quadric.hpp"

#include <Eigen/Dense>
#include <Eigen/SVD>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <fstream>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#ifndef PQDC_BENCH_FLAGS  // set by bench/CMakeLists.txt
#define PQDC_BENCH_FLAGS "unknown"
#endif
#ifndef PQDC_BENCH_BUILD_TYPE
#define PQDC_BENCH_BUILD_TYPE "unknown"
#endif

namespace {

using pqdc::quadric_terms;
using vf = pqdc::vec3<float>;
using sf = pqdc::sym3<float>;
using qf = pqdc::quadric<float>;
constexpr auto ab = quadric_terms::a_b;
constexpr auto abc = quadric_terms::a_b_c;

// ------------------------------------------------------------------ inputs

/// splitmix64: fast, seeded, identical on every platform.
struct random_bits {
    std::uint64_t state;
    std::uint64_t next() {
        std::uint64_t z = (state += 0x9E3779B97F4A7C15ull);
        z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
        z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
        return z ^ (z >> 31);
    }
    float uniform(float lo, float hi) { return lo + (hi - lo) * float(next() >> 40) * 0x1.0p-24f; }
    vf uniform3(float lo, float hi) {
        const float x = uniform(lo, hi), y = uniform(lo, hi), z = uniform(lo, hi);
        return {x, y, z};
    }
    vf unit3() {
        for (;;) {
            const vf v = uniform3(-1, 1);
            const float l2 = pqdc::dot(v, v);
            if (l2 > 0.01f && l2 <= 1.f) return v / std::sqrt(l2);
        }
    }
    /// L L^T with random lower-triangular L: anisotropic, correlated, SPD.
    sf covariance(float scale) {
        const float l00 = scale * uniform(0.3f, 1), l11 = scale * uniform(0.3f, 1), l22 = scale * uniform(0.3f, 1);
        const float l10 = scale * uniform(-0.5f, 0.5f), l20 = scale * uniform(-0.5f, 0.5f),
                    l21 = scale * uniform(-0.5f, 0.5f);
        return {l00 * l00,       l00 * l10, l00 * l20, l10 * l10 + l11 * l11, l10 * l20 + l11 * l21,
                l20 * l20 + l21 * l21 + l22 * l22};
    }
};

/// Inputs for all rows, in cell-local coordinates (a unit cell), as a
/// dual-contouring or decimation pass would produce them.
struct inputs {
    // construction: plane i = (p0[i], normal[i]); triangle i = (p0, p1, p2)[i]
    std::vector<vf> p0, p1, p2, normal;
    std::vector<float> sigma;     // isotropic standard deviation per input
    std::vector<sf> s0, s1, s2;   // general covariances per input (plane: s0 = Sigma_q, s1 = Sigma_n)
    // minimization: per-cell sums of probabilistic plane quadrics (sigma_n = 0.1)
    std::vector<qf> cells;
};

inputs make_inputs(std::size_t n_construct, std::size_t n_cells) {
    random_bits g{42};
    inputs in;
    in.p0.resize(n_construct);
    in.p1.resize(n_construct);
    in.p2.resize(n_construct);
    in.normal.resize(n_construct);
    in.sigma.resize(n_construct);
    in.s0.resize(n_construct);
    in.s1.resize(n_construct);
    in.s2.resize(n_construct);
    for (std::size_t i = 0; i < n_construct; ++i) {
        const vf p = g.uniform3(0, 1);
        in.p0[i] = p;
        in.p1[i] = p + g.uniform3(-0.3f, 0.3f);
        in.p2[i] = p + g.uniform3(-0.3f, 0.3f);
        in.normal[i] = g.unit3();
        in.sigma[i] = g.uniform(0.01f, 0.1f);
        in.s0[i] = g.covariance(0.05f);
        in.s1[i] = g.covariance(0.05f);
        in.s2[i] = g.covariance(0.05f);
    }
    in.cells.resize(n_cells);
    for (std::size_t i = 0; i < n_cells; ++i) {
        // 3..6 Hermite samples on one to three planes through a feature point.
        const vf feature = g.uniform3(0.2f, 0.8f);
        const int planes = 1 + int(g.next() % 3), samples = 3 + int(g.next() % 4);
        const vf n[3] = {g.unit3(), g.unit3(), g.unit3()};
        qf sum;
        for (int k = 0; k < samples; ++k) {
            const vf nk = n[k % planes];
            const vf u = g.uniform3(-0.4f, 0.4f);
            sum += qf::probabilistic_plane<ab>(feature + (u - nk * pqdc::dot(u, nk)), nk, 0.f, 0.1f);
        }
        in.cells[i] = sum;
    }
    return in;
}

// ------------------------------------------------------------ solvers

vf solve_jacobi_svd(const qf& q) {
    Eigen::Matrix3f A;
    A << q.A.a00, q.A.a01, q.A.a02, q.A.a01, q.A.a11, q.A.a12, q.A.a02, q.A.a12, q.A.a22;
    const Eigen::Vector3f b(q.b.x, q.b.y, q.b.z);
    const Eigen::JacobiSVD<Eigen::Matrix3f> svd(A, Eigen::ComputeFullU | Eigen::ComputeFullV);
    const Eigen::Vector3f x = svd.solve(b);
    return {x.x(), x.y(), x.z()};
}

vf solve_bdc_svd(const qf& q) {
    Eigen::Matrix3f A;
    A << q.A.a00, q.A.a01, q.A.a02, q.A.a01, q.A.a11, q.A.a12, q.A.a02, q.A.a12, q.A.a22;
    const Eigen::Vector3f b(q.b.x, q.b.y, q.b.z);
    const Eigen::BDCSVD<Eigen::Matrix3f> svd(A, Eigen::ComputeFullU | Eigen::ComputeFullV);
    const Eigen::Vector3f x = svd.solve(b);
    return {x.x(), x.y(), x.z()};
}

/// Not in the paper: LDL^T solve of the same SPD systems, measured as a
/// candidate replacement for the adjugate inverse (error ~cond eps instead of
/// up to cond^2 eps on flat cells; see tests/test_quadric.cpp).
std::optional<vf> solve_ldlt(const qf& q) {
    const sf& a = q.A;
    const float d0 = a.a00;
    if (!(d0 > 0)) return std::nullopt;
    const float l10 = a.a01 / d0, l20 = a.a02 / d0;
    const float d1 = a.a11 - l10 * a.a01;
    if (!(d1 > 0)) return std::nullopt;
    const float l21 = (a.a12 - l10 * a.a02) / d1;
    const float d2 = a.a22 - l20 * a.a02 - l21 * l21 * d1;
    if (!(d2 > 0)) return std::nullopt;
    const float y1 = q.b.y - l10 * q.b.x, y2 = q.b.z - l20 * q.b.x - l21 * y1;
    const float x2 = y2 / d2, x1 = y1 / d1 - l21 * x2, x0 = q.b.x / d0 - l10 * x1 - l20 * x2;
    return vf{x0, x1, x2};
}

// ------------------------------------------------------------ measuring

double wall_seconds() {
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

/// CPU time of this thread: unlike wall time it does not count the time the
/// thread waits for a core, so rows stay comparable on a shared, loaded
/// machine (on an idle one the two agree). Shared caches and memory
/// bandwidth are still contended.
double thread_cpu_seconds() {
    timespec t{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
    return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
}

double total_wall = 0, total_cpu = 0;  // over all timed passes: load indicator

struct row_result {
    std::string name;
    double ops_per_second;
    double bytes_per_op;  // streamed: inputs read + outputs written
    double paper_ops_per_second;  // 0: not in the paper
    double checksum;
};

struct run_config {
    double min_seconds_per_row;
    int min_passes;
};

/// Runs `pass` (one sweep over n items) until min_seconds (CPU) and
/// min_passes are reached; returns the fastest pass in ops per CPU second.
double measure(std::size_t n, const run_config& cfg, const std::function<void()>& pass) {
    double best = std::numeric_limits<double>::infinity(), total = 0;
    for (int passes = 0; passes < cfg.min_passes || total < cfg.min_seconds_per_row; ++passes) {
        const double w0 = wall_seconds(), t0 = thread_cpu_seconds();
        pass();
        const double t = thread_cpu_seconds() - t0;
        total_wall += wall_seconds() - w0;
        total_cpu += t;
        best = std::min(best, t);
        total += t;
    }
    return double(n) / best;
}

double checksum(const std::vector<qf>& out, std::size_t n) {
    double s = 0;
    for (std::size_t i = 0; i < n; ++i) {
        const qf& q = out[i];
        s += double(q.A.a00) + q.A.a01 + q.A.a02 + q.A.a11 + q.A.a12 + q.A.a22 + q.b.x + q.b.y + q.b.z + q.c;
    }
    return s;
}

double checksum(const std::vector<vf>& out, std::size_t n) {
    double s = 0;
    for (std::size_t i = 0; i < n; ++i) s += double(out[i].x) + out[i].y + out[i].z;
    return s;
}

// The construction loops are templates on the factory so that each row is
// its own inlined, separately optimized loop.
template <class F>
__attribute__((noinline)) void construct_all(std::vector<qf>& out, std::size_t n, F&& make) {
    qf* o = out.data();
    for (std::size_t i = 0; i < n; ++i) o[i] = make(i);
}

template <class F>
__attribute__((noinline)) void solve_all(std::vector<vf>& out, const std::vector<qf>& cells, std::size_t n,
                                         F&& solve) {
    vf* o = out.data();
    const qf* c = cells.data();
    for (std::size_t i = 0; i < n; ++i) o[i] = solve(c[i]);
}

std::string cpu_model() {
    std::ifstream f("/proc/cpuinfo");
    std::string line;
    while (std::getline(f, line))
        if (line.rfind("model name", 0) == 0) {
            const std::size_t colon = line.find(':');
            return colon == std::string::npos ? line : line.substr(colon + 2);
        }
    return "unknown CPU";
}

/// The paper's Table 1 figures the summary line compares against (ops/s).
constexpr double kPaperInverse = 261e6, kPaperJacobi = 4.445e6;

void usage(std::FILE* to) {
    std::fprintf(to,
                 "usage: bench_table1 [--quick] [--csv]\n"
                 "  Reproduces Table 1 of Trettner & Kobbelt 2020 on one thread in single precision.\n"
                 "  --quick  small arrays, one pass per row (smoke test; numbers are not meaningful)\n"
                 "  --csv    print only CSV: header row,ops_per_second, then one quoted row name and\n"
                 "           its ops/s per line\n");
}

/// The construction rows: every quadric kind of the paper's Table 1 built
/// from the same inputs into `out`.
void construction_rows(const inputs& in, std::size_t n, const run_config& cfg, std::vector<qf>& out,
                       std::vector<row_result>& rows) {
    const vf* p0 = in.p0.data();
    const vf* p1 = in.p1.data();
    const vf* p2 = in.p2.data();
    const vf* nn = in.normal.data();
    const float* sg = in.sigma.data();
    const sf* s0 = in.s0.data();
    const sf* s1 = in.s1.data();
    const sf* s2 = in.s2.data();

    constexpr double kQ = sizeof(qf), kV = sizeof(vf), kS = sizeof(sf), kF = sizeof(float);
    auto construct_row = [&](const char* name, double paper, double bytes_in, auto make) {
        const double ops = measure(n, cfg, [&] { construct_all(out, n, make); });
        rows.push_back({name, ops, bytes_in + kQ, paper, checksum(out, n)});
    };

    construct_row("plane classical (A,b)", 399e6, 2 * kV, [=](std::size_t i) { return qf::plane<ab>(p0[i], nn[i]); });
    construct_row("plane classical (A,b,c)", 368e6, 2 * kV,
                  [=](std::size_t i) { return qf::plane<abc>(p0[i], nn[i]); });
    construct_row("plane probabilistic (A,b)", 273e6, 2 * kV + kS,  // Sigma_q only enters c
                  [=](std::size_t i) { return qf::probabilistic_plane<ab>(p0[i], nn[i], s0[i], s1[i]); });
    construct_row("plane probabilistic (A,b,c)", 137e6, 2 * kV + 2 * kS,
                  [=](std::size_t i) { return qf::probabilistic_plane<abc>(p0[i], nn[i], s0[i], s1[i]); });
    construct_row("plane probabilistic (A,b, isotropic)", 399e6, 2 * kV + kF,
                  [=](std::size_t i) { return qf::probabilistic_plane<ab>(p0[i], nn[i], sg[i], sg[i]); });
    construct_row("plane probabilistic (A,b,c, isotropic)", 310e6, 2 * kV + kF,
                  [=](std::size_t i) { return qf::probabilistic_plane<abc>(p0[i], nn[i], sg[i], sg[i]); });
    construct_row("triangle classical (A,b)", 236e6, 3 * kV,
                  [=](std::size_t i) { return qf::triangle<ab>(p0[i], p1[i], p2[i]); });
    construct_row("triangle classical (A,b,c)", 221e6, 3 * kV,
                  [=](std::size_t i) { return qf::triangle<abc>(p0[i], p1[i], p2[i]); });
    construct_row("triangle probabilistic (A,b)", 22e6, 3 * kV + 3 * kS, [=](std::size_t i) {
        return qf::probabilistic_triangle<ab>(p0[i], p1[i], p2[i], s0[i], s1[i], s2[i]);
    });
    construct_row("triangle probabilistic (A,b,c)", 18.7e6, 3 * kV + 3 * kS, [=](std::size_t i) {
        return qf::probabilistic_triangle<abc>(p0[i], p1[i], p2[i], s0[i], s1[i], s2[i]);
    });
    construct_row("triangle probabilistic (A,b, isotropic)", 55.4e6, 3 * kV + kF,
                  [=](std::size_t i) { return qf::probabilistic_triangle<ab>(p0[i], p1[i], p2[i], sg[i]); });
    construct_row("triangle probabilistic (A,b,c, isotropic)", 49.5e6, 3 * kV + kF,
                  [=](std::size_t i) { return qf::probabilistic_triangle<abc>(p0[i], p1[i], p2[i], sg[i]); });
}

/// What the minimizer rows found besides their speed.
struct SolveFacts {
    std::size_t rejected_inverse = 0, rejected_ldlt = 0;  ///< cells each solver refused
    double max_diff_jacobi = 0;                           ///< |x(A^-1 b) - x(JacobiSVD)| over the SVD cells
};

/// The minimizer rows, all on the same per-cell probabilistic quadric sums
/// (the SVD and pseudo-inverse rows on the first n_svd cells).
SolveFacts solve_rows(const inputs& in, std::size_t n, std::size_t n_svd, const run_config& cfg,
                      std::vector<vf>& out, std::vector<row_result>& rows) {
    constexpr double kQ = sizeof(qf), kV = sizeof(vf);
    const vf center{0.5f, 0.5f, 0.5f};
    SolveFacts facts;
    for (const qf& c : in.cells) {
        facts.rejected_inverse += pqdc::minimizer_positive_definite(c) ? 0 : 1;
        facts.rejected_ldlt += solve_ldlt(c) ? 0 : 1;
    }
    auto solve_row = [&](const char* name, double paper, std::size_t count, auto solve) {
        const double ops = measure(count, cfg, [&] { solve_all(out, in.cells, count, solve); });
        rows.push_back({name, ops, kQ + kV, paper, checksum(out, count)});
    };
    solve_row("solve A^-1 b", kPaperInverse, n, [=](const qf& q) {
        const std::optional<vf> x = pqdc::minimizer_positive_definite(q);
        return x ? *x : center;
    });
    const std::vector<vf> x_inverse(out.begin(), out.begin() + std::ptrdiff_t(n_svd));
    solve_row("Eigen::JacobiSVD", kPaperJacobi, n_svd, [](const qf& q) { return solve_jacobi_svd(q); });
    for (std::size_t i = 0; i < n_svd; ++i)
        facts.max_diff_jacobi = std::max(facts.max_diff_jacobi, double(pqdc::distance(out[i], x_inverse[i])));
    solve_row("Eigen::BDCSVD", 3.07e6, n_svd, [](const qf& q) { return solve_bdc_svd(q); });
    solve_row("pqdc pseudo-inverse", 0, n_svd,
              [=](const qf& q) { return pqdc::minimizer_pseudo_inverse(q, center).point; });
    solve_row("LDL^T solve (not in paper)", 0, n, [=](const qf& q) {
        const std::optional<vf> x = solve_ldlt(q);
        return x ? *x : center;
    });
    return facts;
}

double ops_of(const std::vector<row_result>& rows, const char* name) {
    for (const row_result& r : rows)
        if (r.name == name) return r.ops_per_second;
    return 0;
}

void print_table(const std::vector<row_result>& rows, const SolveFacts& facts, std::size_t n, std::size_t n_svd,
                 bool quick) {
    const double inverse = ops_of(rows, "solve A^-1 b");
    std::printf("pqdc Table 1 benchmark: 1 thread, float; %s\n", cpu_model().c_str());
    std::printf("compiler: GCC %s, flags: %s, build type %s%s\n", __VERSION__, PQDC_BENCH_FLAGS, PQDC_BENCH_BUILD_TYPE,
                quick ? "  [--quick: numbers not meaningful]" : "");
    std::printf("construction: %zu inputs per row; minimization: %zu cells (SVD and pseudo-inverse rows: first %zu)\n\n",
                n, n, n_svd);
    std::printf("%-42s %12s %8s %9s %7s  %12s %9s\n", "row", "ops/s", "ns/op", "vs A^-1b", "GB/s", "paper ops/s",
                "paper vs");
    for (const row_result& r : rows) {
        std::printf("%-42s %12.4g %8.2f %9.3f %7.2f  ", r.name.c_str(), r.ops_per_second, 1e9 / r.ops_per_second,
                    r.ops_per_second / inverse, r.ops_per_second * r.bytes_per_op / 1e9);
        if (r.paper_ops_per_second > 0)
            std::printf("%12.4g %9.3f\n", r.paper_ops_per_second, r.paper_ops_per_second / kPaperInverse);
        else
            std::printf("%12s %9s\n", "-", "-");
    }
    std::printf("\nA^-1 b vs Eigen::JacobiSVD: %.1fx faster (paper: %.1fx)\n",
                inverse / ops_of(rows, "Eigen::JacobiSVD"), kPaperInverse / kPaperJacobi);
    std::printf("cells rejected by minimizer_positive_definite: %zu of %zu; by LDL^T: %zu\n", facts.rejected_inverse, n,
                facts.rejected_ldlt);
    std::printf("max |x(A^-1 b) - x(JacobiSVD)| over the SVD cells: %.3g (cell size 1)\n", facts.max_diff_jacobi);
    std::printf("timing: thread CPU time, fastest pass; wall/CPU time over all passes %.2f (1.00 = a core to ourselves)\n",
                total_wall / total_cpu);
    std::printf("checksums:");
    for (const row_result& r : rows) std::printf(" %.6g", r.checksum);
    std::printf("\n");
}

}  // namespace

int main(int argc, char** argv) {
    bool quick = false, csv = false;
    for (int i = 1; i < argc; ++i) {
        if (std::strcmp(argv[i], "--quick") == 0) {
            quick = true;
        } else if (std::strcmp(argv[i], "--csv") == 0) {
            csv = true;
        } else if (std::strcmp(argv[i], "--help") == 0 || std::strcmp(argv[i], "-h") == 0) {
            usage(stdout);
            return 0;
        } else {
            std::fprintf(stderr, "bench_table1: unknown argument '%s'\n", argv[i]);
            usage(stderr);
            return 2;
        }
    }

    // 4M construction inputs: ~0.5 GB of input arrays, far beyond the caches.
    // SVD rows take ~0.3 us per op, so they sweep a 256K prefix of the cells.
    const std::size_t n = quick ? (std::size_t(1) << 14) : (std::size_t(1) << 22);
    const std::size_t n_svd = quick ? (std::size_t(1) << 10) : (std::size_t(1) << 18);
    const run_config cfg = quick ? run_config{0.0, 1} : run_config{0.5, 3};

    const inputs in = make_inputs(n, n);
    std::vector<qf> out_q(n);  // value-initialized: pages are touched before timing
    std::vector<vf> out_x(n);
    std::vector<row_result> rows;
    construction_rows(in, n, cfg, out_q, rows);
    const SolveFacts facts = solve_rows(in, n, n_svd, cfg, out_x, rows);

    if (csv) {
        // Names contain commas ("(A,b)"): quote them (RFC 4180).
        std::printf("row,ops_per_second\n");
        for (const row_result& r : rows) std::printf("\"%s\",%.0f\n", r.name.c_str(), r.ops_per_second);
        return 0;
    }
    print_table(rows, facts, n, n_svd, quick);
    return 0;
}
