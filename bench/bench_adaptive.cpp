// Adaptive pqdc (octree dual marching cubes) versus uniform pqdc and
// openvdb::tools::volumeToMesh at several adaptivities, on the same grids:
//   sphere   procedural sphere sampled with pqdc::sample_field
//   box      procedural rotated box (sharp corners and edges), sampled likewise
//   figure3  the paper's Figure 3 field (noise with a sphere cut out), sampled likewise
//   mesh     fandisk.off (CGAL demo data, extracted at configure time) through
//            openvdb::tools::meshToLevelSet; volumes/fandisk.vdb when the OFF
//            is unavailable (ground truth then: the level set itself)
// Every mesher meshes the same FloatGrid (pqdc through its grid path).
//
// Errors are in voxels, against the ground truth: the analytic signed
// distance (sphere, box; exact), the field's first-order distance |f|/|grad f|
// (figure3), or the distance to the source triangle mesh (mesh case;
// pqdc::MeshDistance, exact at any distance).
// "vert" rows measure the mesh vertices, "surf" rows points spread over every
// face (centroid and the three points halfway between it and the corners),
// which is what a user sees: a coarse face can be far from the surface even
// when its corners are on it.
//
// Faces are counted as triangles (a quad counts 2), so quad-dominant and
// triangle meshes compare fairly. Times: best of --runs runs, wall clock.
// The summary prints, for each volumeToMesh adaptivity, the smallest adaptive
// pqdc mesh whose surface mean and max errors are both no larger, and the
// face ratio; adaptive time / uniform time, and volumeToMesh's adaptive
// time / its own a=0 time as the peer's figure. Speed is reported, never
// asserted.
//
// Usage: bench_adaptive [--threads N] [--runs N] [--quick] [--resolution N]
//                       [--mesh-cells N] [--cases sphere,box,figure3,mesh]
//   --resolution N   lattice cells along the longest side (procedural); default 256 (quick: 64)
//   --mesh-cells N   mesh case: cells across the mesh; default 256 (quick: 64)
#include "pqdc/adaptive.hpp"
#include "pqdc/exceptions.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/measure.hpp"
#include "pqdc/mesh_io.hpp"
#include "pqdc/procedural.hpp"
#include "pqdc/volume_io.hpp"

#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/MeshToVolume.h>
#include <openvdb/tools/VolumeToMesh.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#ifndef PQDC_SOURCE_DIR
#define PQDC_SOURCE_DIR "."
#endif
#ifndef PQDC_BENCH_FANDISK_OFF
#define PQDC_BENCH_FANDISK_OFF ""
#endif

using openvdb::Vec3d;

namespace {

struct Options {
    int threads = 0;
    int runs = 3;
    bool quick = false;
    int resolution = 256;
    int mesh_cells = 256;
    std::vector<std::string> cases{"sphere", "box", "figure3", "mesh"};
};

[[noreturn]] void usage_error(const std::string& m) {
    std::fprintf(stderr, "bench_adaptive: %s (see the usage at the top of bench/bench_adaptive.cpp)\n", m.c_str());
    std::exit(2);
}

int parse_int(const char* text, const char* option, int lo) {
    char* end = nullptr;
    const long v = std::strtol(text, &end, 10);
    if (!end || *end || v < lo || v > 100000) usage_error(std::string(option) + " needs an integer >= " + std::to_string(lo));
    return int(v);
}

double now() {
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

struct Case {
    std::string name;
    openvdb::FloatGrid::Ptr grid;
    std::function<double(const Vec3d&)> distance;  // world units
    std::string truth;
};

struct Row {
    std::string method, param;
    std::size_t faces = 0, vertices = 0;  // faces as triangles
    double vert_mean = 0, vert_max = 0, surf_mean = 0, surf_max = 0;
    double seconds = 0;
};

struct Errors {
    double mean = 0, max = 0;
};

Errors errors_of(const std::vector<Vec3d>& points, const Case& c, double h) {
    Errors e;
    if (points.empty()) return e;
    double sum = 0;
    for (const Vec3d& p : points) {
        const double d = c.distance(p) / h;
        sum += d;
        e.max = std::max(e.max, d);
    }
    e.mean = sum / double(points.size());
    return e;
}

Row measure(const std::string& method, const std::string& param, const pqdc::Mesh& m, double seconds, const Case& c) {
    const double h = c.grid->voxelSize()[0];
    Row r;
    r.method = method;
    r.param = param;
    r.faces = m.triangles.size() + 2 * m.quads.size();
    r.vertices = m.points.size();
    r.seconds = seconds;
    const Errors v = errors_of(m.points, c, h);
    r.vert_mean = v.mean;
    r.vert_max = v.max;
    std::vector<Vec3d> samples;
    samples.reserve(4 * r.faces);
    auto tri = [&](const Vec3d& a, const Vec3d& b, const Vec3d& cc) {
        const Vec3d g = (a + b + cc) / 3.0;
        samples.push_back(g);
        for (const Vec3d& x : {a, b, cc}) samples.push_back((g + x) * 0.5);
    };
    for (const auto& t : m.triangles) tri(m.points[t[0]], m.points[t[1]], m.points[t[2]]);
    for (const auto& q : m.quads) {
        tri(m.points[q[0]], m.points[q[1]], m.points[q[2]]);
        tri(m.points[q[0]], m.points[q[2]], m.points[q[3]]);
    }
    const Errors s = errors_of(samples, c, h);
    r.surf_mean = s.mean;
    r.surf_max = s.max;
    return r;
}

template <class F>
std::pair<pqdc::Mesh, double> best_of(int runs, F&& mesher) {
    pqdc::Mesh mesh;
    double best = std::numeric_limits<double>::infinity();
    for (int i = 0; i < runs; ++i) {
        const double t0 = now();
        mesh = mesher();
        best = std::min(best, now() - t0);
    }
    return {std::move(mesh), best};
}

pqdc::Mesh volume_to_mesh(const openvdb::FloatGrid& grid, double adaptivity) {
    std::vector<openvdb::Vec3s> points;
    std::vector<openvdb::Vec3I> tris;
    std::vector<openvdb::Vec4I> quads;
    openvdb::tools::volumeToMesh(grid, points, tris, quads, 0.0, adaptivity);
    pqdc::Mesh m;
    m.points.reserve(points.size());
    for (const auto& p : points) m.points.emplace_back(p.x(), p.y(), p.z());
    // volumeToMesh winds faces clockwise seen from outside; orientation does
    // not matter for distances.
    m.triangles = std::move(tris);
    m.quads = std::move(quads);
    return m;
}

Case procedural_case(const std::string& name, int resolution) {
    std::shared_ptr<pqdc::ScalarField> field(pqdc::make_procedural(name).release());
    pqdc::ProceduralSampling s;
    s.resolution = resolution;
    Case c;
    c.name = name;
    c.grid = pqdc::sample_field(*field, s);
    if (name == "figure3") {
        c.distance = [field](const Vec3d& p) {
            const double g = field->gradient(p).length();
            return g > 0 ? std::abs(field->value(p)) / g : std::abs(field->value(p));
        };
        c.truth = "|f| / |grad f| of the exact field";
    } else {
        c.distance = [field](const Vec3d& p) { return std::abs(field->value(p)); };
        c.truth = "exact signed distance";
    }
    return c;
}

Case mesh_case(int cells) {
    Case c;
    c.name = "mesh";
    const std::string off = PQDC_BENCH_FANDISK_OFF;
    if (!off.empty() && std::filesystem::exists(off)) {
        const pqdc::Mesh source = pqdc::read_mesh(off);
        // meshToLevelSet takes float points; the reference is that float mesh,
        // so the ground truth is the surface the level set was made from.
        std::vector<openvdb::Vec3s> pts(source.points.begin(), source.points.end());
        openvdb::BBoxd box;
        for (const auto& p : pts) box.expand(Vec3d(p));
        const double voxel = box.extents()[box.maxExtent()] / cells;
        auto xf = openvdb::math::Transform::createLinearTransform(voxel);
        c.grid = openvdb::tools::meshToLevelSet<openvdb::FloatGrid>(*xf, pts, source.triangles, source.quads, 3.0f);
        pqdc::Mesh reference;
        reference.points.assign(pts.begin(), pts.end());
        reference.triangles = source.triangles;
        reference.quads = source.quads;
        c.distance = pqdc::MeshDistance(reference);
        c.truth = "distance to fandisk.off (" + std::to_string(cells) + " cells across)";
        return c;
    }
    const pqdc::LoadedGrid g = pqdc::read_scalar_grid(std::string(PQDC_SOURCE_DIR) + "/volumes/fandisk.vdb");
    c.grid = openvdb::gridPtrCast<openvdb::FloatGrid>(g.grid);
    auto grid = c.grid;
    c.distance = [grid](const Vec3d& p) {
        return std::abs(double(openvdb::tools::BoxSampler::sample(grid->getConstAccessor(), grid->worldToIndex(p))));
    };
    c.truth = "|trilinear SDF| of volumes/fandisk.vdb (fandisk.off unavailable)";
    return c;
}

void print_row(const Row& r) {
    std::printf("  %-10s %-8s %10zu %9zu  %8.4f %8.4f  %8.4f %8.4f  %8.3f\n", r.method.c_str(), r.param.c_str(), r.faces,
                r.vertices, r.vert_mean, r.vert_max, r.surf_mean, r.surf_max, r.seconds);
    std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
    Options o;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        auto next = [&]() -> const char* {
            if (i + 1 >= argc) usage_error(a + " needs a value");
            return argv[++i];
        };
        if (a == "--threads") o.threads = parse_int(next(), "--threads", 1);
        else if (a == "--runs") o.runs = parse_int(next(), "--runs", 1);
        else if (a == "--quick") o.quick = true;
        else if (a == "--resolution") o.resolution = parse_int(next(), "--resolution", 8);
        else if (a == "--mesh-cells") o.mesh_cells = parse_int(next(), "--mesh-cells", 8);
        else if (a == "--cases") {
            o.cases.clear();
            std::stringstream ss(next());
            for (std::string c; std::getline(ss, c, ',');) {
                if (c != "sphere" && c != "box" && c != "figure3" && c != "mesh") usage_error("unknown case '" + c + "'");
                o.cases.push_back(c);
            }
        } else usage_error("unknown argument '" + a + "'");
    }
    if (o.quick) {
        o.resolution = std::min(o.resolution, 64);
        o.mesh_cells = std::min(o.mesh_cells, 64);
        o.runs = 1;
    }
    openvdb::initialize();
    std::optional<tbb::global_control> limit;
    if (o.threads > 0) limit.emplace(tbb::global_control::max_allowed_parallelism, std::size_t(o.threads));

    const std::vector<double> max_errors{0.05, 0.1, 0.25, 0.5, 1.0};
    const std::vector<double> adaptivities{0.0, 0.1, 0.25, 0.5, 0.75, 1.0};
    std::printf("bench_adaptive: resolution %d, mesh cells %d, runs %d, threads %s\n", o.resolution, o.mesh_cells, o.runs,
                o.threads ? std::to_string(o.threads).c_str() : "all");
    for (const std::string& name : o.cases) {
        const Case c = name == "mesh" ? mesh_case(o.mesh_cells) : procedural_case(name, o.resolution);
        std::printf("\n%s: %zu active voxels; ground truth: %s; distances in voxels\n", name.c_str(),
                    std::size_t(c.grid->activeVoxelCount()), c.truth.c_str());
        std::printf("  %-10s %-8s %10s %9s  %8s %8s  %8s %8s  %8s\n", "method", "param", "faces", "vertices",
                    "vert mean", "max", "surf mean", "max", "best s");
        std::vector<Row> rows;
        pqdc::ExtractOptions uo;
        auto [um, ut] = best_of(o.runs, [&] { return pqdc::extract(*c.grid, uo); });
        rows.push_back(measure("uniform", "-", um, ut, c));
        print_row(rows.back());
        std::vector<Row> adaptive, vtm;
        for (double e : max_errors) {
            pqdc::AdaptiveOptions ao;
            ao.max_error_voxels = e;
            auto [m, t] = best_of(o.runs, [&] { return pqdc::extract_adaptive(*c.grid, ao); });
            char p[32];
            std::snprintf(p, sizeof p, "E=%g", e);
            adaptive.push_back(measure("adaptive", p, m, t, c));
            print_row(adaptive.back());
        }
        for (double a : adaptivities) {
            auto [m, t] = best_of(o.runs, [&] { return volume_to_mesh(*c.grid, a); });
            char p[32];
            std::snprintf(p, sizeof p, "a=%g", a);
            vtm.push_back(measure("vdb v2m", p, m, t, c));
            print_row(vtm.back());
        }
        std::printf("  summary (smallest adaptive pqdc mesh with surface mean and max <= volumeToMesh's):\n");
        for (const Row& v : vtm) {
            const Row* best = nullptr;
            for (const Row& a : adaptive)
                if (a.surf_mean <= v.surf_mean && a.surf_max <= v.surf_max && (!best || a.faces < best->faces)) best = &a;
            if (best)
                std::printf("    vs v2m %-6s: adaptive %-6s %8zu vs %8zu faces, ratio %.1fx\n", v.param.c_str(),
                            best->param.c_str(), best->faces, v.faces, double(v.faces) / double(best->faces));
            else
                std::printf("    vs v2m %-6s: no adaptive row is as accurate\n", v.param.c_str());
        }
        for (const Row& a : adaptive)
            std::printf("    adaptive %-6s time / uniform time = %.2f\n", a.param.c_str(), a.seconds / rows[0].seconds);
        // The peer's own price of adaptivity, measured in the same run.
        for (const Row& v : vtm)
            if (v.param != vtm.front().param)
                std::printf("    v2m %-6s time / v2m %s time = %.2f\n", v.param.c_str(), vtm.front().param.c_str(),
                            v.seconds / vtm.front().seconds);
    }
    return 0;
}
