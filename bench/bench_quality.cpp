// Mesh quality on clean and noisy volumes (issue 11): pqdc (uniform and
// adaptive, defaults and fixed sigma_n) against openvdb::tools::volumeToMesh,
// raw and after OpenVDB's Gaussian level-set filter, measured against the
// exact surface.
//
// Suite (quality_cases.hpp), each at --resolution cells across (default 128):
//   sphere, box (rotated), csg (box - cylinder + sphere, rotated; sharp
//   edges), and CGAL's demo meshes fandisk and armadillo converted with
//   pqdc::mesh_to_level_set (exact distances, as pqdc-mesh-to-volume;
//   skipped when libcgal-dev's data.tar.gz is not installed).
// Noise: i.i.d. Gaussian of --noise sigmas (voxels; default 0, 0.1, 0.2, 0.3)
// on every active value, seeded (pqdc::add_gaussian_noise, as pqdc-add-noise).
//
// Meshers: pqdc / adapt = pqdc::extract / extract_adaptive with default
// options; -s0, -s0.1, -s0.25 = fixed sigma_n; -sharp0 = sigma_n 0 with
// GridNormals::sharp; vdb = volumeToMesh (isovalue 0, adaptivity 0);
// vdb-gauss = volumeToMesh after LevelSetFilter::gaussian(1) once on a copy
// (what `vdb_tool -gauss i=1 -l2m` does; its time includes the filter).
//
// Metrics (all against the exact surface; distances in voxels):
//   dist     mean distance of the mesh vertices to the surface
//            (pqdc::measure_distance against the field or the source mesh)
//   normal   mean angle between each face's normal and the true normal at the
//            surface point nearest to the face's centroid, degrees
//   feature  sharp-edge error: mean distance from points sampled every 1/4
//            voxel on the true sharp edges (box and CSG: the analytic edges and
//            circles; fandisk: source edges whose faces meet at more than 45
//            degrees) to the mesh ("-" for smooth shapes). A rounded edge
//            shows its rounding depth here; dist, sampled at vertices, barely
//            sees it.
//   ang5     5th-percentile smallest triangle angle, degrees (quads split 0-2)
//   selfx    pairs of triangles that intersect other than along a shared edge
//            or vertex (pqdc::find_self_intersections, exact); "+Nd" adds the
//            degenerate triangles it lists apart
//   comps    connected components (truth: 1 for every shape here)
//   kept     components left by pqdc::remove_small_components with its default
//            (bounding-box diagonal >= 3.5 voxels); the CSV adds the largest
//            removed and the smallest kept diagonal, voxels
//   nm       non-manifold edges + non-manifold vertices
//   open     boundary edges (0 for a closed mesh)
//   time     wall seconds of the mesher call alone, one run (a shared machine:
//            for speed use bench_extract)
//
// Usage: bench_quality [--quick] [--csv] [--resolution N] [--noise LIST]
//                      [--cases LIST] [--meshers LIST] [--seed S] [--threads N]
//   --quick        resolution 32, noise 0 and 0.3 (smoke test; numbers meaningless)
//   --csv          one machine-readable row per (case, noise, mesher)
//   --resolution N cells across each shape, [16, 1024]; default 128
//   --noise LIST   comma-separated sigmas in voxels, >= 0; default 0,0.1,0.2,0.3
//   --cases LIST   of sphere,box,csg,fandisk,armadillo; default all
//   --meshers LIST of the names above; default all
//   --seed S       noise seed; default 1
//   --threads N    TBB worker limit; default all cores
#include "quality_cases.hpp"

#include "pqdc/adaptive.hpp"
#include "pqdc/components.hpp"
#include "pqdc/exceptions.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/measure.hpp"
#include "pqdc/noise.hpp"
#include "pqdc/self_intersections.hpp"

#include <openvdb/tools/LevelSetFilter.h>
#include <openvdb/tools/VolumeToMesh.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#ifndef PQDC_BENCH_CGAL_MESHES  // directory of CGAL's demo meshes, extracted at configure time
#define PQDC_BENCH_CGAL_MESHES ""
#endif

namespace {

struct Options {
    bool quick = false, csv = false;
    int resolution = 128;
    std::vector<double> noise{0.0, 0.1, 0.2, 0.3};
    std::vector<std::string> cases{"sphere", "box", "csg", "fandisk", "armadillo"};
    std::vector<std::string> meshers;  // empty: all
    std::uint64_t seed = 1;
    int threads = 0;
};

[[noreturn]] void usage_error(const std::string& message) {
    std::fprintf(stderr, "bench_quality: %s\n(see the usage at the top of bench/bench_quality.cpp)\n", message.c_str());
    std::exit(2);
}

std::vector<std::string> split_list(const std::string& s) {
    std::vector<std::string> out;
    std::stringstream in(s);
    for (std::string item; std::getline(in, item, ',');)
        if (!item.empty()) out.push_back(item);
    return out;
}

double parse_number(const std::string& option, const std::string& text) {
    char* end = nullptr;
    const double v = std::strtod(text.c_str(), &end);
    if (text.empty() || *end != '\0' || !std::isfinite(v)) usage_error(option + " needs a number, not '" + text + "'");
    return v;
}

Options parse(int argc, char** argv) {
    Options o;
    bool resolution_given = false, noise_given = false;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        auto value = [&]() -> std::string {
            if (i + 1 >= argc) usage_error(a + " needs a value");
            return argv[++i];
        };
        if (a == "--quick") {
            o.quick = true;
        } else if (a == "--csv") {
            o.csv = true;
        } else if (a == "--resolution") {
            const double r = parse_number(a, value());
            if (r < 16 || r > 1024 || r != std::floor(r)) usage_error("--resolution must be a whole number in [16, 1024]");
            o.resolution = int(r);
            resolution_given = true;
        } else if (a == "--noise") {
            o.noise.clear();
            for (const std::string& s : split_list(value())) {
                o.noise.push_back(parse_number(a, s));
                if (o.noise.back() < 0) usage_error("--noise sigmas must be >= 0 voxels");
            }
            if (o.noise.empty()) usage_error("--noise needs at least one sigma");
            noise_given = true;
        } else if (a == "--cases") {
            o.cases = split_list(value());
        } else if (a == "--meshers") {
            o.meshers = split_list(value());
        } else if (a == "--seed") {
            o.seed = std::uint64_t(parse_number(a, value()));
        } else if (a == "--threads") {
            const double t = parse_number(a, value());
            if (t < 1 || t > 4096 || t != std::floor(t)) usage_error("--threads must be a whole number in [1, 4096]");
            o.threads = int(t);
        } else {
            usage_error("unknown option '" + a + "'");
        }
    }
    if (o.quick) {
        if (!resolution_given) o.resolution = 32;
        if (!noise_given) o.noise = {0.0, 0.3};
    }
    for (const std::string& c : o.cases)
        if (c != "sphere" && c != "box" && c != "csg" && c != "fandisk" && c != "armadillo")
            usage_error("unknown case '" + c + "'; choose from sphere,box,csg,fandisk,armadillo");
    return o;
}

// ---------------------------------------------------------------- meshers

struct Mesher {
    std::string name;
    std::function<pqdc::Mesh(const openvdb::FloatGrid&)> run;
};

/// volumeToMesh winds its polygons clockwise seen from outside; reversed to
/// pqdc's convention (counter-clockwise) so that face normals compare.
pqdc::Mesh from_openvdb(const std::vector<openvdb::Vec3s>& points, const std::vector<openvdb::Vec3I>& triangles,
                        const std::vector<openvdb::Vec4I>& quads) {
    pqdc::Mesh m;
    m.points.assign(points.begin(), points.end());
    for (const openvdb::Vec3I& t : triangles) m.triangles.emplace_back(t[0], t[2], t[1]);
    for (const openvdb::Vec4I& q : quads) m.quads.emplace_back(q[0], q[3], q[2], q[1]);
    return m;
}

pqdc::Mesh volume_to_mesh(const openvdb::FloatGrid& grid) {
    std::vector<openvdb::Vec3s> points;
    std::vector<openvdb::Vec3I> triangles;
    std::vector<openvdb::Vec4I> quads;
    openvdb::tools::volumeToMesh(grid, points, triangles, quads, 0.0, 0.0);
    return from_openvdb(points, triangles, quads);
}

std::vector<Mesher> all_meshers() {
    std::vector<Mesher> out;
    struct Variant {
        const char* suffix;
        std::optional<double> sigma;  // nullopt: defaults
        bool sharp;
    };
    const Variant variants[] = {{"", std::nullopt, false},
                                {"-s0", 0.0, false},
                                {"-s0.1", 0.1, false},
                                {"-s0.25", 0.25, false},
                                {"-sharp0", 0.0, true},
                                {"-free", std::nullopt, false},
                                {"-dn", std::nullopt, false}};
    for (const Variant& v : variants) {
        pqdc::ExtractOptions base;
        if (std::string(v.suffix) == "-free") base.containment = pqdc::Containment::unconstrained;
        if (std::string(v.suffix) == "-dn") base.denoise = pqdc::Denoise::on;
        if (v.sigma) base.sigma_n = *v.sigma;
        if (v.sharp) base.normals = pqdc::GridNormals::sharp;
        out.push_back({std::string("pqdc") + v.suffix, [base](const openvdb::FloatGrid& g) { return pqdc::extract(g, base); }});
    }
    for (const Variant& v : variants) {
        pqdc::AdaptiveOptions options;
        if (v.sigma) options.base.sigma_n = *v.sigma;
        if (v.sharp) options.base.normals = pqdc::GridNormals::sharp;
        out.push_back({std::string("adapt") + v.suffix,
                       [options](const openvdb::FloatGrid& g) { return pqdc::extract_adaptive(g, options); }});
    }
    out.push_back({"vdb", volume_to_mesh});
    out.push_back({"vdb-gauss", [](const openvdb::FloatGrid& g) {
                       openvdb::FloatGrid::Ptr copy = g.deepCopy();
                       openvdb::tools::LevelSetFilter<openvdb::FloatGrid> filter(*copy);
                       filter.gaussian(1);
                       return volume_to_mesh(*copy);
                   }});
    return out;
}

// ---------------------------------------------------------------- metrics

struct Metrics {
    double dist = NAN, normal = NAN, feature = NAN, ang5 = NAN, seconds = 0;
    std::size_t selfx = 0, degenerate = 0, comps = 0, kept = 0, nm = 0, open = 0, faces = 0;
    double largest_removed = NAN, smallest_kept = NAN;  // component diagonals, voxels
};

Metrics measure(const pqdc::Mesh& mesh, const quality::Case& c) {
    Metrics m;
    m.faces = mesh.face_count();
    if (m.faces == 0) return m;
    if (c.field) {
        m.dist = pqdc::measure_distance(mesh, *c.field).mean / c.voxel;
        m.normal = pqdc::measure_normal_deviation(mesh, *c.field).mean_degrees;
    } else {
        m.dist = pqdc::measure_distance(mesh, *c.reference).mean / c.voxel;
        m.normal = pqdc::measure_normal_deviation(mesh, *c.reference).mean_degrees;
    }
    if (!c.feature_points.empty()) {
        const pqdc::MeshDistance to_mesh(mesh);
        double sum = 0;
        for (const openvdb::Vec3d& p : c.feature_points) sum += to_mesh(p);
        m.feature = sum / double(c.feature_points.size()) / c.voxel;
    }
    m.ang5 = pqdc::measure_triangle_quality(mesh).min_angle_p05_degrees;
    const pqdc::SelfIntersections si = pqdc::find_self_intersections(mesh);
    m.selfx = si.pair_count;
    m.degenerate = si.degenerate_triangles.size();
    const pqdc::TopologyReport t = pqdc::measure_topology(mesh);
    m.comps = t.connected_component_count;
    m.nm = t.non_manifold_edge_count + t.non_manifold_vertex_count;
    m.open = t.boundary_edge_count;
    pqdc::ComponentFilterStats components;
    pqdc::remove_small_components(mesh, c.voxel, {}, &components);
    m.kept = components.components - components.removed_components;
    if (components.removed_components) m.largest_removed = components.largest_removed_diagonal_voxels;
    if (m.kept) m.smallest_kept = components.smallest_kept_diagonal_voxels;
    return m;
}

// ---------------------------------------------------------------- report

struct Row {
    std::string case_name;
    double voxel = 0, noise = 0;
    std::string mesher;
    Metrics m;
};

std::string fixed(double v, int digits) {
    if (std::isnan(v)) return "-";
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.*f", digits, v);
    return buf;
}

std::string count_with_degenerate(const Metrics& m) {
    return std::to_string(m.selfx) + (m.degenerate ? "+" + std::to_string(m.degenerate) + "d" : "");
}

void print_detail(const std::vector<Row>& rows, const Options& o) {
    std::string current;
    for (const Row& r : rows) {
        const std::string key = r.case_name + "/" + fixed(r.noise, 2);
        if (key != current) {
            current = key;
            std::printf("\n== %s, noise %s voxel (%d cells, voxel %.4g) ==\n", r.case_name.c_str(), fixed(r.noise, 2).c_str(),
                        o.resolution, r.voxel);
            std::printf("%-13s %6s %7s %7s %6s %9s %6s %5s %4s %5s %8s %7s\n", "mesher", "dist", "normal", "feature", "ang5",
                        "selfx", "comps", "kept", "nm", "open", "faces", "time");
        }
        const Metrics& m = r.m;
        std::printf("%-13s %6s %7s %7s %6s %9s %6zu %5zu %4zu %5zu %8zu %7.3f\n", r.mesher.c_str(), fixed(m.dist, 3).c_str(),
                    fixed(m.normal, 2).c_str(), fixed(m.feature, 3).c_str(), fixed(m.ang5, 1).c_str(),
                    count_with_degenerate(m).c_str(), m.comps, m.kept, m.nm, m.open, m.faces, m.seconds);
    }
}

/// "lo-hi" over the cases (one value when they agree at the shown precision).
std::string range(const std::vector<double>& values, int digits) {
    double lo = INFINITY, hi = -INFINITY;
    for (double v : values)
        if (!std::isnan(v)) lo = std::min(lo, v), hi = std::max(hi, v);
    if (lo > hi) return "-";
    const std::string a = fixed(lo, digits), b = fixed(hi, digits);
    return a == b ? a : a + "-" + b;
}

/// Per noise level, one row per mesher with the range of each metric over
/// the cases: the side-by-side view of issue 11's table.
void print_summary(const std::vector<Row>& rows, const std::vector<std::string>& mesher_names, const Options& o) {
    for (const double noise : o.noise) {
        std::printf("\n== summary, noise %s voxel, %d cells: min-max over the cases ==\n", fixed(noise, 2).c_str(),
                    o.resolution);
        std::printf("%-13s %-11s %-11s %-11s %-11s %-11s %-9s %-6s %-6s %-6s %8s\n", "mesher", "dist", "normal", "feature",
                    "ang5", "selfx", "comps", "kept", "nm", "open", "time sum");
        for (const std::string& name : mesher_names) {
            std::vector<double> dist, normal, feature, ang5, selfx, comps, kept, nm, open;
            double seconds = 0;
            for (const Row& r : rows) {
                if (r.mesher != name || r.noise != noise) continue;
                dist.push_back(r.m.dist);
                normal.push_back(r.m.normal);
                feature.push_back(r.m.feature);
                ang5.push_back(r.m.ang5);
                selfx.push_back(double(r.m.selfx + r.m.degenerate));
                comps.push_back(double(r.m.comps));
                kept.push_back(double(r.m.kept));
                nm.push_back(double(r.m.nm));
                open.push_back(double(r.m.open));
                seconds += r.m.seconds;
            }
            if (dist.empty()) continue;
            std::printf("%-13s %-11s %-11s %-11s %-11s %-11s %-9s %-6s %-6s %-6s %8.2f\n", name.c_str(),
                        range(dist, 2).c_str(), range(normal, 1).c_str(), range(feature, 2).c_str(),
                        range(ang5, 1).c_str(), range(selfx, 0).c_str(), range(comps, 0).c_str(),
                        range(kept, 0).c_str(), range(nm, 0).c_str(), range(open, 0).c_str(), seconds);
        }
    }
}

void print_csv(const std::vector<Row>& rows, const Options& o) {
    std::printf("case,resolution,voxel,noise_voxels,mesher,dist_voxels,normal_degrees,feature_voxels,ang5_degrees,"
                "self_intersecting_pairs,degenerate_triangles,components,components_kept,largest_removed_diagonal_voxels,"
                "smallest_kept_diagonal_voxels,non_manifold,boundary_edges,faces,seconds\n");
    for (const Row& r : rows) {
        const Metrics& m = r.m;
        auto num = [](double v) { return std::isnan(v) ? std::string("") : fixed(v, 6); };
        std::printf("%s,%d,%.9g,%g,%s,%s,%s,%s,%s,%zu,%zu,%zu,%zu,%s,%s,%zu,%zu,%zu,%.4f\n", r.case_name.c_str(),
                    o.resolution, r.voxel, r.noise, r.mesher.c_str(), num(m.dist).c_str(), num(m.normal).c_str(),
                    num(m.feature).c_str(), num(m.ang5).c_str(), m.selfx, m.degenerate, m.comps, m.kept,
                    num(m.largest_removed).c_str(), num(m.smallest_kept).c_str(), m.nm, m.open, m.faces, m.seconds);
    }
}

std::vector<quality::Case> build_cases(const Options& o) {
    std::vector<quality::Case> cases;
    const std::string cgal = PQDC_BENCH_CGAL_MESHES;
    for (const std::string& name : o.cases) {
        if (name == "sphere") cases.push_back(quality::sphere_case(o.resolution));
        if (name == "box") cases.push_back(quality::box_case(o.resolution));
        if (name == "csg") cases.push_back(quality::csg_case(o.resolution));
        if (name == "fandisk" || name == "armadillo") {
            const std::string path = cgal + "/" + name + ".off";
            if (cgal.empty() || !std::ifstream(path)) {
                std::fprintf(stderr, "bench_quality: skipping %s: %s not found (install libcgal-dev, re-run cmake)\n",
                             name.c_str(), path.c_str());
                continue;
            }
            cases.push_back(quality::mesh_case(name, path, o.resolution, name == "fandisk" ? 45.0 : 0.0));
        }
    }
    return cases;
}

}  // namespace

int main(int argc, char** argv) {
    const Options o = parse(argc, argv);
    openvdb::initialize();
    std::optional<tbb::global_control> threads;
    if (o.threads > 0) threads.emplace(tbb::global_control::max_allowed_parallelism, std::size_t(o.threads));

    std::vector<Mesher> meshers;
    for (Mesher& m : all_meshers())
        if (o.meshers.empty() || std::find(o.meshers.begin(), o.meshers.end(), m.name) != o.meshers.end())
            meshers.push_back(std::move(m));
    for (const std::string& name : o.meshers)
        if (std::none_of(meshers.begin(), meshers.end(), [&](const Mesher& m) { return m.name == name; }))
            usage_error("unknown mesher '" + name + "'");
    std::vector<std::string> mesher_names;
    for (const Mesher& m : meshers) mesher_names.push_back(m.name);

    try {
        const std::vector<quality::Case> cases = build_cases(o);
        std::vector<Row> rows;
        for (const quality::Case& c : cases) {
            for (const double noise : o.noise) {
                std::fprintf(stderr, "bench_quality: %s, noise %g voxel\n", c.name.c_str(), noise);
                openvdb::FloatGrid::Ptr grid = c.grid->deepCopy();
                if (noise > 0) pqdc::add_gaussian_noise(*grid, noise * c.voxel, o.seed);
                for (const Mesher& mesher : meshers) {
                    const auto start = std::chrono::steady_clock::now();
                    const pqdc::Mesh mesh = mesher.run(*grid);
                    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
                    Row row{c.name, c.voxel, noise, mesher.name, measure(mesh, c)};
                    row.m.seconds = seconds;
                    rows.push_back(row);
                }
            }
        }
        if (o.csv) {
            print_csv(rows, o);
        } else {
            std::printf("bench_quality: %d cells, noise seed %llu, %zu cases\n", o.resolution,
                        static_cast<unsigned long long>(o.seed), cases.size());
            print_detail(rows, o);
            print_summary(rows, mesher_names, o);
        }
    } catch (const pqdc::error& e) {
        std::fprintf(stderr, "bench_quality: %s\n", e.what());
        return 1;
    }
    return 0;
}
