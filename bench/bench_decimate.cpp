// pqdc::decimate against its peers, on dual-contouring output of clean and
// noisy level sets (issue 15):
//   pqdc decimate   --metric triangle / plane / curvature
//   CGAL 5.5        Surface_mesh_simplification::edge_collapse with
//                   GarlandHeckbert_plane_policies (classic) and
//                   GarlandHeckbert_probabilistic_plane_policies (defaults)
//                   (only when CGAL was found at configure time)
//   meshoptimizer   meshopt_simplify (Debian's 0.18)
//   pqdc adaptive   extract_adaptive at several --max-error (clean input only)
//   volumeToMesh    openvdb::tools::volumeToMesh at several adaptivities (clean only)
// Cases: sphere (procedural), box (procedural rotated box: sharp edges and
// corners, the CAD case) and armadillo (CGAL's scanned Armadillo through
// meshToLevelSet; skipped when the demo data is not installed). "noisy" is
// what the issue asks for, DC output of a noisy level set: seeded Gaussian
// noise of --noise voxels on every active value (pqdc::add_gaussian_noise,
// as pqdc-add-noise does), then pqdc::extract with its defaults. "jittered"
// (not run by default) moves every vertex of the clean mesh along its
// normal by Gaussian noise of --noise voxels instead: an input that
// intersects itself, to see how each method copes with such defects.
//
// Columns: faces (triangles), percent of the input, mean and max distance
// to the true surface in voxels over points spread on every face (centroid
// and the three points halfway to the corners): "mean" averages them per
// face (every face counts the same, so many small faces where the error is
// low pull it down), "mean_a" over the surface (each point weighted by its
// face's area, as Metro's mean distance samples the surface uniformly),
// mean normal error in degrees (face normal vs the truth's gradient at the
// centroid), smallest triangle angle, non-manifold edges, self-intersecting
// triangle pairs (CGAL PMP::self_intersections with exact predicates when
// the output is a valid Surface_mesh; "*" marks a count made with pqdc's own
// exact predicates on a triangle soup), wall seconds. pqdc rows run on one thread
// (the time compared with CGAL, itself single-threaded) and again on all
// threads (t_all, collapses/s), and check that both outputs are identical.
//
// Usage: bench_decimate [--quick] [--csv] [--threads N] [--resolution N]
//                       [--noise S] [--cases sphere,box,armadillo] [--no-cgal]
//   --resolution N  lattice cells along the longest side (default 160; quick 48)
//   --noise S       noise of the noisy inputs, voxels (default 0.3)
//   --sigma S, --sigma-normal S   pqdc's sigma_position_voxels and sigma_normal
//                   (defaults: DecimateOptions')
//   --budgets LIST  percents of the input faces (default 1,2,5,10,20,40)
//   --methods LIST  run only these (default all): pqdc-triangle, pqdc-plane,
//                   pqdc-curvature, meshopt, cgal-classic, cgal-prob, adaptive
//   --inputs LIST   clean, noisy, jittered (default clean,noisy)
// Issue scale (1-6 M faces): --resolution 400 gives about 1.5 M triangles
// on the sphere, 640 about 3.9 M; e.g.
//   bench_decimate --resolution 400 --cases sphere --inputs noisy --budgets 10
//                  --methods pqdc-triangle,meshopt,cgal-prob
// PQDC_BENCH_VERBOSE=1 prints pqdc's passes and refusal counts to stderr.
// PQDC_BENCH_SAVE_INPUTS=DIR writes each input mesh to DIR/<case>-<input>.ply (to profile pqdc-decimate on it).
#include "pqdc/adaptive.hpp"
#include "pqdc/decimate.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/measure.hpp"
#include "pqdc/mesh_io.hpp"
#include "pqdc/noise.hpp"
#include "pqdc/procedural.hpp"

#include "decimate/exact_predicates.hpp"  // src/: the exact predicates it checks outputs with

#include <meshoptimizer.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/MeshToVolume.h>
#include <openvdb/tools/VolumeToMesh.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#ifdef PQDC_BENCH_HAVE_CGAL
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/self_intersections.h>
#include <CGAL/Simple_cartesian.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/Count_ratio_stop_predicate.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/GarlandHeckbert_plane_policies.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/GarlandHeckbert_probabilistic_plane_policies.h>
#include <CGAL/Surface_mesh_simplification/edge_collapse.h>
#include <CGAL/box_intersection_d.h>
#endif

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <random>
#include <string>
#include <vector>

#ifndef PQDC_BENCH_ARMADILLO_OFF
#define PQDC_BENCH_ARMADILLO_OFF ""
#endif

using openvdb::Vec3d;

namespace {

struct Options {
    bool quick = false, csv = false, cgal = true;
    int threads = 0;
    int resolution = 160;
    double noise = 0.3;
    double sigma = pqdc::DecimateOptions{}.sigma_position_voxels;
    double sigma_normal = pqdc::DecimateOptions{}.sigma_normal;
    std::vector<std::string> cases{"sphere", "box", "armadillo"};
    std::vector<double> budgets;          // empty = the default curve
    std::vector<std::string> methods;     // empty = all
    std::vector<std::string> inputs{"clean", "noisy"};
    bool runs(const std::string& m) const {
        return methods.empty() || std::find(methods.begin(), methods.end(), m) != methods.end();
    }
};

std::vector<std::string> split_list(const std::string& list) {
    std::vector<std::string> out;
    std::string item;
    for (char ch : list + ",") {
        if (ch != ',') item += ch;
        else if (!item.empty()) out.push_back(item), item.clear();
    }
    return out;
}

[[noreturn]] void usage_error(const std::string& m) {
    std::fprintf(stderr, "bench_decimate: %s (see the usage at the top of bench/bench_decimate.cpp)\n", m.c_str());
    std::exit(2);
}

double now() { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); }

struct Case {
    std::string name;
    openvdb::FloatGrid::Ptr grid;
    std::function<double(const Vec3d&)> signed_distance;  // world units, negative inside
    double voxel = 1;
};

struct Row {
    std::string input, method;
    double budget = 0;  // percent asked for; 0 = not a budget row
    std::size_t faces = 0;
    double percent = 0, mean = 0, max = 0, normal = 0, min_angle = 0;
    double mean_area = 0;  // over the surface: each sample weighted by its face's area
    std::size_t non_manifold = 0, self_intersections = 0;
    bool si_soup = false;
    double seconds = 0, seconds_all = 0, collapses_per_second = 0, collapses_per_second_1 = 0;
};

// ------------------------------------------------------------------ measures

std::size_t soup_self_intersections(const pqdc::Mesh& m);

void measure(Row& r, const pqdc::Mesh& m, const Case& c, std::size_t input_faces) {
    r.faces = m.triangles.size() + 2 * m.quads.size();
    r.percent = 100.0 * double(r.faces) / double(input_faces);
    double sum = 0, nsum = 0, area_sum = 0, area = 0;
    std::size_t count = 0, ncount = 0;
    r.max = 0;
    const double h = c.voxel;
    for (const auto& t : m.triangles) {
        const Vec3d a = m.points[t[0]], b = m.points[t[1]], d = m.points[t[2]];
        const Vec3d g = (a + b + d) / 3.0;
        const double w = 0.5 * (b - a).cross(d - a).length();
        area += w;
        for (const Vec3d& p : {g, (g + a) * 0.5, (g + b) * 0.5, (g + d) * 0.5}) {
            const double e = std::abs(c.signed_distance(p)) / h;
            sum += e;
            area_sum += w * e / 4;
            r.max = std::max(r.max, e);
            ++count;
        }
        Vec3d n = (b - a).cross(d - a);
        const double s = 0.25 * h;
        Vec3d grad(c.signed_distance(g + Vec3d(s, 0, 0)) - c.signed_distance(g - Vec3d(s, 0, 0)),
                   c.signed_distance(g + Vec3d(0, s, 0)) - c.signed_distance(g - Vec3d(0, s, 0)),
                   c.signed_distance(g + Vec3d(0, 0, s)) - c.signed_distance(g - Vec3d(0, 0, s)));
        if (n.length() > 0 && grad.length() > 0) {
            // Orientation-blind: volumeToMesh winds the other way.
            const double cosv = std::abs(n.dot(grad)) / (n.length() * grad.length());
            nsum += std::acos(std::min(1.0, cosv)) * 180 / M_PI;
            ++ncount;
        }
    }
    r.mean = count ? sum / double(count) : 0;
    r.mean_area = area > 0 ? area_sum / area : 0;
    r.normal = ncount ? nsum / double(ncount) : 0;
    r.min_angle = pqdc::measure_triangle_quality(m).min_angle_min_degrees;
    r.non_manifold = pqdc::measure_topology(m).non_manifold_edge_count;
#ifdef PQDC_BENCH_HAVE_CGAL
    using K = CGAL::Exact_predicates_inexact_constructions_kernel;
    using SM = CGAL::Surface_mesh<K::Point_3>;
    SM sm;
    std::vector<SM::Vertex_index> vs;
    for (const auto& p : m.points) vs.push_back(sm.add_vertex(K::Point_3(p[0], p[1], p[2])));
    bool valid = true;
    for (const auto& t : m.triangles)
        if (sm.add_face(vs[t[0]], vs[t[1]], vs[t[2]]) == SM::null_face()) {
            valid = false;
            break;
        }
    if (valid) {
        std::vector<std::pair<SM::Face_index, SM::Face_index>> pairs;
        CGAL::Polygon_mesh_processing::self_intersections(sm, std::back_inserter(pairs));
        r.self_intersections = pairs.size();
        r.si_soup = false;
        return;
    }
#endif
    r.self_intersections = soup_self_intersections(m);
    r.si_soup = true;
}

/// Triangle pairs meeting beyond shared vertices, exact (pqdc's predicates),
/// candidates from a sort-and-sweep over x.
std::size_t soup_self_intersections(const pqdc::Mesh& m) {
    using pqdc::exact::point;
    const auto& T = m.triangles;
    std::vector<std::pair<double, std::size_t>> order;
    std::vector<std::array<Vec3d, 2>> box(T.size());
    for (std::size_t i = 0; i < T.size(); ++i) {
        Vec3d lo = m.points[T[i][0]], hi = lo;
        for (int k = 1; k < 3; ++k) {
            lo = openvdb::math::minComponent(lo, m.points[T[i][k]]);
            hi = openvdb::math::maxComponent(hi, m.points[T[i][k]]);
        }
        box[i] = {lo, hi};
        order.emplace_back(lo[0], i);
    }
    std::sort(order.begin(), order.end());
    auto P = [&](unsigned v) { return point{m.points[v][0], m.points[v][1], m.points[v][2]}; };
    std::size_t hits = 0;
    for (std::size_t oi = 0; oi < order.size(); ++oi) {
        const std::size_t i = order[oi].second;
        for (std::size_t oj = oi + 1; oj < order.size() && order[oj].first <= box[i][1][0]; ++oj) {
            const std::size_t j = order[oj].second;
            if (box[j][0][1] > box[i][1][1] || box[i][0][1] > box[j][1][1] || box[j][0][2] > box[i][1][2] ||
                box[i][0][2] > box[j][1][2])
                continue;
            const unsigned a[3] = {T[i][0], T[i][1], T[i][2]}, b[3] = {T[j][0], T[j][1], T[j][2]};
            int shared = 0, si[3], sj[3];
            for (int x = 0; x < 3; ++x)
                for (int y = 0; y < 3; ++y)
                    if (a[x] == b[y]) {
                        si[shared] = x;
                        sj[shared] = y;
                        ++shared;
                    }
            const point pa[3] = {P(a[0]), P(a[1]), P(a[2])}, pb[3] = {P(b[0]), P(b[1]), P(b[2])};
            bool hit;
            if (shared == 0) hit = pqdc::exact::triangles_intersect(pa, pb);
            else if (shared == 1)
                hit = pqdc::exact::triangles_intersect_sharing_vertex(pa[si[0]], pa[(si[0] + 1) % 3], pa[(si[0] + 2) % 3],
                                                                      pb[(sj[0] + 1) % 3], pb[(sj[0] + 2) % 3]);
            else if (shared == 2)
                hit = pqdc::exact::triangles_overlap_sharing_edge(pa[si[0]], pa[si[1]], pa[3 - si[0] - si[1]],
                                                                  pb[3 - sj[0] - sj[1]]);
            else hit = true;
            hits += hit;
        }
    }
    return hits;
}

// ------------------------------------------------------------------- peers

double g_sigma = pqdc::sigma_position_auto, g_sigma_normal = 0.05;

pqdc::Mesh pqdc_decimate(const pqdc::Mesh& in, pqdc::DecimateMetric metric, double ratio, double voxel, int threads,
                         pqdc::DecimateStats* st) {
    pqdc::Mesh m = in;
    pqdc::DecimateOptions o;
    o.sigma_position_voxels = g_sigma;
    o.sigma_normal = g_sigma_normal;
    o.target_ratio = ratio;
    o.metric = metric;
    o.voxel_size = voxel;
    o.threads = threads;
    pqdc::decimate(m, o, st);
    return m;
}

pqdc::Mesh meshopt(const pqdc::Mesh& in, double ratio) {
    Vec3d centre(0);
    for (const auto& p : in.points) centre += p;
    centre /= double(std::max<std::size_t>(1, in.points.size()));
    std::vector<float> pos;
    for (const auto& p : in.points)
        for (int k = 0; k < 3; ++k) pos.push_back(float(p[k] - centre[k]));
    std::vector<unsigned> idx;
    for (const auto& t : in.triangles)
        for (int k = 0; k < 3; ++k) idx.push_back(t[k]);
    std::vector<unsigned> out(idx.size());
    float err = 0;
    const std::size_t target = std::size_t(ratio * double(in.triangles.size())) * 3;
    out.resize(meshopt_simplify(out.data(), idx.data(), idx.size(), pos.data(), in.points.size(), 12, target, 1e30f, 0,
                                &err));
    pqdc::Mesh m;
    std::vector<unsigned> remap(in.points.size(), ~0u);
    for (std::size_t i = 0; i + 2 < out.size(); i += 3) {
        unsigned t[3];
        for (int k = 0; k < 3; ++k) {
            unsigned& r = remap[out[i + k]];
            if (r == ~0u) {
                r = unsigned(m.points.size());
                m.points.push_back(in.points[out[i + k]]);
            }
            t[k] = r;
        }
        m.triangles.emplace_back(t[0], t[1], t[2]);
    }
    return m;
}

#ifdef PQDC_BENCH_HAVE_CGAL
pqdc::Mesh cgal_collapse(const pqdc::Mesh& in, double ratio, bool probabilistic) {
    using K = CGAL::Simple_cartesian<double>;
    using SM = CGAL::Surface_mesh<K::Point_3>;
    namespace SMS = CGAL::Surface_mesh_simplification;
    SM sm;
    std::vector<SM::Vertex_index> vs;
    for (const auto& p : in.points) vs.push_back(sm.add_vertex(K::Point_3(p[0], p[1], p[2])));
    for (const auto& t : in.triangles) sm.add_face(vs[t[0]], vs[t[1]], vs[t[2]]);
    SMS::Count_ratio_stop_predicate<SM> stop(ratio);
    if (probabilistic) {
        SMS::GarlandHeckbert_probabilistic_plane_policies<SM, K> gh(sm);
        SMS::edge_collapse(sm, stop, CGAL::parameters::get_cost(gh.get_cost()).get_placement(gh.get_placement()));
    } else {
        SMS::GarlandHeckbert_plane_policies<SM, K> gh(sm);
        SMS::edge_collapse(sm, stop, CGAL::parameters::get_cost(gh.get_cost()).get_placement(gh.get_placement()));
    }
    sm.collect_garbage();
    pqdc::Mesh m;
    for (auto v : sm.vertices()) {
        const auto& p = sm.point(v);
        m.points.emplace_back(p.x(), p.y(), p.z());
    }
    for (auto f : sm.faces()) {
        unsigned t[3], k = 0;
        for (auto v : CGAL::vertices_around_face(sm.halfedge(f), sm)) t[k++ % 3] = unsigned(v.idx());
        m.triangles.emplace_back(t[0], t[1], t[2]);
    }
    return m;
}
#endif

pqdc::Mesh volume_to_mesh(const openvdb::FloatGrid& grid, double adaptivity) {
    std::vector<openvdb::Vec3s> points;
    std::vector<openvdb::Vec3I> tris;
    std::vector<openvdb::Vec4I> quads;
    openvdb::tools::volumeToMesh(grid, points, tris, quads, 0.0, adaptivity);
    pqdc::Mesh m;
    for (const auto& p : points) m.points.emplace_back(p.x(), p.y(), p.z());
    m.triangles = std::move(tris);
    for (const auto& q : quads) {  // as triangles, so the angle and SI checks see what is drawn
        m.triangles.emplace_back(q[0], q[1], q[2]);
        m.triangles.emplace_back(q[0], q[2], q[3]);
    }
    return m;
}

// ------------------------------------------------------------------- inputs

Case make_case(const std::string& name, int resolution) {
    Case c;
    c.name = name;
    if (name == "armadillo") {
        const std::string off = PQDC_BENCH_ARMADILLO_OFF;
        if (off.empty() || !std::filesystem::exists(off)) return c;  // grid stays null: skipped
        const pqdc::Mesh source = pqdc::read_mesh(off);
        std::vector<openvdb::Vec3s> pts(source.points.begin(), source.points.end());
        openvdb::BBoxd box;
        for (const auto& p : pts) box.expand(Vec3d(p));
        c.voxel = box.extents()[box.maxExtent()] / resolution;
        auto xf = openvdb::math::Transform::createLinearTransform(c.voxel);
        c.grid = openvdb::tools::meshToLevelSet<openvdb::FloatGrid>(*xf, pts, source.triangles, source.quads, 3.0f);
        pqdc::Mesh reference;
        reference.points.assign(pts.begin(), pts.end());
        reference.triangles = source.triangles;
        reference.quads = source.quads;
        const pqdc::MeshDistance dist(reference);
        c.signed_distance = [dist](const Vec3d& p) { return dist.signed_distance(p); };
        return c;
    }
    std::shared_ptr<pqdc::ScalarField> field(pqdc::make_procedural(name).release());
    pqdc::ProceduralSampling s;
    s.resolution = resolution;
    c.grid = pqdc::sample_field(*field, s);
    c.voxel = c.grid->voxelSize()[0];
    c.signed_distance = [field](const Vec3d& p) { return field->value(p); };
    return c;
}

/// DC output (pqdc's defaults) of the level set with Gaussian noise of
/// `noise_voxels` on every active value.
pqdc::Mesh noisy_level_set_mesh(const openvdb::FloatGrid& grid, double noise_voxels) {
    const openvdb::FloatGrid::Ptr noisy = grid.deepCopy();
    pqdc::add_gaussian_noise(*noisy, noise_voxels * grid.voxelSize()[0], 12345);
    return pqdc::extract(*noisy, pqdc::ExtractOptions{});
}

pqdc::Mesh with_noise(const pqdc::Mesh& clean, double sigma_world, unsigned seed) {
    pqdc::Mesh m = clean;
    std::vector<Vec3d> normal(m.points.size(), Vec3d(0));
    for (const auto& t : m.triangles) {
        const Vec3d n = (m.points[t[1]] - m.points[t[0]]).cross(m.points[t[2]] - m.points[t[0]]);
        for (int k = 0; k < 3; ++k) normal[t[k]] += n;
    }
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> g(0, sigma_world);
    for (std::size_t i = 0; i < m.points.size(); ++i) {
        const double l = normal[i].length();
        const double d = g(rng);
        if (l > 0) m.points[i] += normal[i] * (d / l);
    }
    return m;
}

// ------------------------------------------------------------------- output

void print_header(bool csv) {
    if (csv)
        std::printf("case,input,method,budget_percent,faces,percent,mean_voxels,mean_area_voxels,max_voxels,normal_degrees,min_angle_degrees,"
                    "non_manifold_edges,self_intersections,si_by_pqdc_predicates,seconds_1_thread,seconds_all_threads,"
                    "collapses_per_second_all_threads,collapses_per_second_1_thread\n");
    else
        std::printf("%-9s %-5s %-16s %6s %9s %7s %8s %8s %8s %7s %6s %6s %7s %8s %8s %10s %10s\n", "case", "input",
                    "method", "budget", "faces", "%", "mean", "mean_a", "max", "normal", "minang", "nonman", "selfint", "t_1", "t_all",
                    "coll/s", "coll/s_1");
}

void print_row(const std::string& cs, const Row& r, bool csv) {
    if (csv)
        std::printf("%s,%s,%s,%g,%zu,%.3f,%.5f,%.5f,%.5f,%.3f,%.3f,%zu,%zu,%d,%.4f,%.4f,%.0f,%.0f\n", cs.c_str(),
                    r.input.c_str(), r.method.c_str(), r.budget, r.faces, r.percent, r.mean, r.mean_area, r.max, r.normal, r.min_angle, r.non_manifold,
                    r.self_intersections, r.si_soup ? 1 : 0, r.seconds, r.seconds_all, r.collapses_per_second,
                    r.collapses_per_second_1);
    else
        std::printf("%-9s %-5s %-16s %6g %9zu %7.2f %8.4f %8.4f %8.4f %7.2f %6.2f %6zu %6zu%s %8.3f %8.3f %10.0f %10.0f\n",
                    cs.c_str(), r.input.c_str(), r.method.c_str(), r.budget, r.faces, r.percent, r.mean, r.mean_area, r.max, r.normal, r.min_angle,
                    r.non_manifold, r.self_intersections, r.si_soup ? "*" : " ", r.seconds, r.seconds_all,
                    r.collapses_per_second, r.collapses_per_second_1);
    std::fflush(stdout);
}

}  // namespace

namespace {

using Summary = std::map<std::pair<std::string, double>, std::map<std::string, Row>>;

/// The input row and every budget row of one input (clean or noisy) of a case.
void run_budgets(const Options& o, const Case& c, const std::string& input_name, const pqdc::Mesh& input,
                 const std::vector<double>& budgets, int all_threads, bool cgal, Summary& summary, bool& deterministic) {
    (void)cgal;
    const std::string& name = c.name;
    const std::string cs = name;
    const std::size_t F = input.triangles.size();
    if (const char* dir = std::getenv("PQDC_BENCH_SAVE_INPUTS"))  // for profiling pqdc-decimate on the same input
        pqdc::write_mesh(input, std::string(dir) + "/" + name + "-" + input_name + ".ply");
    Row in;
    in.input = input_name;
    in.method = "input";
    measure(in, input, c, F);
    print_row(cs, in, o.csv);
    for (double b : budgets) {
        const double ratio = b / 100;
        auto add = [&](Row r) {
            r.input = input_name;
            r.budget = b;
            print_row(cs, r, o.csv);
            summary[{cs + "/" + input_name, b}][r.method] = r;
        };
        const std::pair<const char*, pqdc::DecimateMetric> metrics[] = {
            {"pqdc-triangle", pqdc::DecimateMetric::triangle},
            {"pqdc-plane", pqdc::DecimateMetric::plane},
            {"pqdc-curvature", pqdc::DecimateMetric::curvature}};
        for (const auto& [label, metric] : metrics) {
            if (!o.runs(label)) continue;
            Row r;
            r.method = label;
            pqdc::DecimateStats s1, sa;
            double t0 = now();
            const pqdc::Mesh m1 = pqdc_decimate(input, metric, ratio, c.voxel, 1, &s1);
            r.seconds = now() - t0;
            t0 = now();
            const pqdc::Mesh ma = pqdc_decimate(input, metric, ratio, c.voxel, all_threads, &sa);
            r.seconds_all = now() - t0;
            r.collapses_per_second = double(sa.collapses) / sa.seconds;
            r.collapses_per_second_1 = double(s1.collapses) / s1.seconds;
            if (std::getenv("PQDC_BENCH_VERBOSE"))
                std::fprintf(stderr, "  %s: %zu passes, %zu locked, refused %zu link %zu flip %zu quality %zu intersection\n",
                             label, sa.passes, sa.locked_vertices, sa.rejected_link, sa.rejected_flip,
                             sa.rejected_quality, sa.rejected_intersection);
            if (m1.points != ma.points || m1.triangles != ma.triangles) deterministic = false;
            measure(r, ma, c, F);
            add(r);
        }
        if (o.runs("meshopt")) {
            Row r;
            r.method = "meshopt-0.18";
            const double t0 = now();
            const pqdc::Mesh m = meshopt(input, ratio);
            r.seconds = now() - t0;
            measure(r, m, c, F);
            add(r);
        }
#ifdef PQDC_BENCH_HAVE_CGAL
        if (cgal) {
            for (bool prob : {false, true}) {
                if (!o.runs(prob ? "cgal-prob" : "cgal-classic")) continue;
                Row r;
                r.method = prob ? "cgal-gh-prob" : "cgal-gh-classic";
                const double t0 = now();
                const pqdc::Mesh m = cgal_collapse(input, ratio, prob);
                r.seconds = now() - t0;
                measure(r, m, c, F);
                add(r);
            }
        }
#endif
    }
}

/// pqdc --adaptive and volumeToMesh adaptivity on the case's grid (clean input only).
void run_adaptive_peers(const Options& o, const Case& c, const std::string& input_name, std::size_t F) {
    const std::string cs = c.name;
    for (double e : o.quick ? std::vector<double>{0.5} : std::vector<double>{0.1, 0.25, 0.5, 1, 2}) {
        Row r;
        r.input = input_name;
        r.method = "pqdc-adaptive";
        pqdc::AdaptiveOptions ao;
        ao.max_error_voxels = e;
        const double t0 = now();
        pqdc::Mesh m = pqdc::extract_adaptive(*c.grid, ao);
        r.seconds_all = now() - t0;
        measure(r, m, c, F);
        r.method += "-e" + std::to_string(e).substr(0, 4);
        print_row(cs, r, o.csv);
    }
    for (double a : o.quick ? std::vector<double>{0.5} : std::vector<double>{0.2, 0.5, 0.8, 1.0}) {
        Row r;
        r.input = input_name;
        r.method = "volumeToMesh-a" + std::to_string(a).substr(0, 3);
        const double t0 = now();
        pqdc::Mesh m = volume_to_mesh(*c.grid, a);
        r.seconds_all = now() - t0;
        measure(r, m, c, F);
        print_row(cs, r, o.csv);
    }
}
}  // namespace

int main(int argc, char** argv) {
    Options o;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        auto next = [&]() -> std::string {
            if (i + 1 >= argc) usage_error(a + " needs a value");
            return argv[++i];
        };
        if (a == "--quick") o.quick = true;
        else if (a == "--csv") o.csv = true;
        else if (a == "--no-cgal") o.cgal = false;
        else if (a == "--threads") o.threads = std::atoi(next().c_str());
        else if (a == "--resolution") o.resolution = std::atoi(next().c_str());
        else if (a == "--noise") o.noise = std::atof(next().c_str());
        else if (a == "--sigma") o.sigma = std::atof(next().c_str());
        else if (a == "--sigma-normal") o.sigma_normal = std::atof(next().c_str());
        else if (a == "--cases") o.cases = split_list(next());
        else if (a == "--methods") o.methods = split_list(next());
        else if (a == "--inputs") o.inputs = split_list(next());
        else if (a == "--budgets") {
            for (const std::string& b : split_list(next())) {
                const double v = std::atof(b.c_str());
                if (!(v > 0 && v <= 100)) usage_error("--budgets: each percent must be in (0, 100], got '" + b + "'");
                o.budgets.push_back(v);
            }
        } else usage_error("unknown option '" + a + "'");
    }
    if (o.quick) {
        o.resolution = std::min(o.resolution, 48);
        o.cases = {"sphere", "box"};
    }
    if (o.resolution < 16 || o.resolution > 4096) usage_error("--resolution must be in [16, 4096]");
    if (o.threads < 0) usage_error("--threads must be >= 0");
    openvdb::initialize();
    g_sigma = o.sigma;
    g_sigma_normal = o.sigma_normal;
    const int all_threads = o.threads > 0 ? o.threads : int(tbb::this_task_arena::max_concurrency());
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(all_threads));
    const std::vector<double> budgets = !o.budgets.empty() ? o.budgets
                                        : o.quick               ? std::vector<double>{5, 20}
                                                                : std::vector<double>{1, 2, 5, 10, 20, 40};
#ifdef PQDC_BENCH_HAVE_CGAL
    const bool cgal = o.cgal;
#else
    const bool cgal = false;
#endif
    if (!o.csv)
        std::printf("bench_decimate: resolution %d, noise %g voxels, %d threads for t_all, CGAL %s; distances in voxels\n",
                    o.resolution, o.noise, all_threads, cgal ? "on" : "off (not found or --no-cgal)");
    print_header(o.csv);
    Summary summary;  // [(case/input, budget)][method]
    bool deterministic = true;
    for (const std::string& name : o.cases) {
        Case c = make_case(name, o.resolution);
        if (!c.grid) {
            if (!o.csv) std::printf("%s: skipped (CGAL demo data not installed)\n", name.c_str());
            continue;
        }
        pqdc::ExtractOptions eo;
        const pqdc::Mesh clean = pqdc::extract(*c.grid, eo);
        auto wanted = [&](const char* input) { return std::find(o.inputs.begin(), o.inputs.end(), input) != o.inputs.end(); };
        const pqdc::Mesh noisy = wanted("noisy") ? noisy_level_set_mesh(*c.grid, o.noise) : pqdc::Mesh{};
        const pqdc::Mesh jittered = wanted("jittered") ? with_noise(clean, o.noise * c.voxel, 12345) : pqdc::Mesh{};
        for (const auto& [input_name, input] : {std::pair<std::string, const pqdc::Mesh&>{"clean", clean},
                                                 std::pair<std::string, const pqdc::Mesh&>{"noisy", noisy},
                                                 std::pair<std::string, const pqdc::Mesh&>{"jittered", jittered}}) {
            if (!wanted(input_name.c_str())) continue;
            run_budgets(o, c, input_name, input, budgets, all_threads, cgal, summary, deterministic);
            if (input_name == "clean" && o.runs("adaptive")) run_adaptive_peers(o, c, input_name, input.triangles.size());
        }
    }
    if (!o.csv) {
        std::printf("\nsummary, budgets 1-20%%: pqdc-triangle mean / peer mean, per face / over the surface (target <= 1 "
                    "vs CGAL prob, <= 0.5 vs meshopt), CGAL-prob time / pqdc 1-thread time (target >= 10), pqdc "
                    "collapses/s on all threads\n");
        for (const auto& [key, rows] : summary) {
            if (key.second > 20) continue;
            auto get = [&](const char* m) { auto it = rows.find(m); return it == rows.end() ? nullptr : &it->second; };
            const Row* p = get("pqdc-triangle");
            const Row* mo = get("meshopt-0.18");
            const Row* cp = get("cgal-gh-prob");
            if (!p) continue;
            std::printf("  %-16s %4g%%", key.first.c_str(), key.second);
            // Per face, then over the surface (area-weighted).
            if (mo) std::printf("  vs meshopt %.3f / %.3f", p->mean / mo->mean, p->mean_area / mo->mean_area);
            if (cp)
                std::printf("  vs cgal-prob %.3f / %.3f  speed x%.1f", p->mean / cp->mean, p->mean_area / cp->mean_area,
                            cp->seconds / p->seconds);
            std::printf("  %.2f M collapses/s (1 thread %.2f M)\n", p->collapses_per_second / 1e6,
                        p->collapses_per_second_1 / 1e6);
        }
        std::printf("pqdc output identical for 1 and %d threads: %s\n", all_threads, deterministic ? "yes" : "NO");
    }
    return deterministic ? 0 : 1;
}
