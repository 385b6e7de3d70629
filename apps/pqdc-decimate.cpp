// pqdc-decimate: decimate a triangle/quad mesh with probabilistic quadrics
// (pqdc::decimate). Parses options, calls the library, prints.
// Exit codes: 0 ok, 1 runtime error (input, output), 2 usage error.

#include "pqdc/decimate.hpp"
#include "pqdc/exceptions.hpp"
#include "pqdc/mesh_io.hpp"

#include "cli_util.hpp"

#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

namespace {

using pqdc_cli::UsageError;
using pqdc_cli::parse_finite;
using pqdc_cli::parse_integer;

const char* kUsage = R"(usage: pqdc-decimate INPUT.(obj|ply|off) -o OUTPUT.ply [options]

Decimates a mesh by edge collapses to the minimizer of summed probabilistic
quadrics. Boundary and non-manifold vertices stay where they are; a closed
manifold stays closed, manifold, of the same genus and free of new
self-intersections. Quads are split; the output has triangles only.

Targets (at least one; decimation stops at the first one reached):
  --target-faces N          at most N triangles
  --target-ratio R          at most R times the input's triangles, R in (0, 1]
  --max-distance E          keep every vertex within E voxels of the input
                            surface (guaranteed for vertices; face interiors
                            are not bounded)
Options:
  -o, --output FILE         .ply (binary), .obj, .off or .stl; written atomically
  --voxel-size V            world units per voxel, the unit of the lengths here
                            (default: the input's mean edge length)
  --metric triangle|plane|curvature
                            probabilistic triangle quadrics (default), plane
                            quadrics, or triangle placement with an algebraic
                            sphere curvature cost
  --sigma-position S|auto   vertex position noise, voxels (default auto: estimated
                            from the input, 0.7 x the estimate, at least 0.02)
  --sigma-normal S          normal noise of --metric plane (default 0.05)
  --max-normal-change DEG   largest normal turn per collapse (default 75)
  --min-quality Q           smallest created triangle quality in [0, 1) (default 0.1)
  --threads N               worker threads (default: all cores); output is identical for any N
  --quiet                   print errors only
  --help                    this text
)";

struct CliOptions {
    std::string input, output;
    pqdc::DecimateOptions decimate;
    bool quiet = false;
};

CliOptions parse(int argc, char** argv, bool& done) {
    CliOptions o;
    done = false;
    const std::vector<std::string> args(argv + 1, argv + argc);
    std::vector<std::string> positional;
    for (std::size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        auto value = [&]() -> std::string {
            if (i + 1 >= args.size()) throw UsageError{a + " needs a value"};
            return args[++i];
        };
        auto positive = [&](double lo_exclusive) {
            const double v = parse_finite(a, value());
            if (!(v > lo_exclusive)) throw UsageError{a + " must be > " + std::to_string(int(lo_exclusive)) + ", got " + args[i]};
            return v;
        };
        if (a == "--help" || a == "-h") {
            std::cout << kUsage;
            done = true;
            return o;
        } else if (a == "-o" || a == "--output") {
            o.output = value();
        } else if (a == "--target-faces") {
            o.decimate.target_faces = std::size_t(parse_integer(a, value(), 1, 2000000000L));
        } else if (a == "--target-ratio") {
            const double r = parse_finite(a, value());
            if (!(r > 0 && r <= 1)) throw UsageError{"--target-ratio must be in (0, 1], got " + args[i]};
            o.decimate.target_ratio = r;
        } else if (a == "--max-distance") {
            o.decimate.max_distance_voxels = positive(0);
        } else if (a == "--voxel-size") {
            o.decimate.voxel_size = positive(0);
        } else if (a == "--metric") {
            const std::string v = value();
            if (v == "triangle") o.decimate.metric = pqdc::DecimateMetric::triangle;
            else if (v == "plane") o.decimate.metric = pqdc::DecimateMetric::plane;
            else if (v == "curvature") o.decimate.metric = pqdc::DecimateMetric::curvature;
            else throw UsageError{"--metric expects triangle, plane or curvature, got '" + v + "'"};
        } else if (a == "--sigma-position") {
            if (i + 1 < args.size() && args[i + 1] == "auto") {
                ++i;
                o.decimate.sigma_position_voxels = pqdc::sigma_position_auto;
            } else {
                o.decimate.sigma_position_voxels = positive(0);
            }
        } else if (a == "--sigma-normal") {
            o.decimate.sigma_normal = positive(0);
        } else if (a == "--max-normal-change") {
            o.decimate.max_normal_change_degrees = parse_finite(a, value());
        } else if (a == "--min-quality") {
            o.decimate.min_triangle_quality = parse_finite(a, value());
        } else if (a == "--threads") {
            o.decimate.threads = int(parse_integer(a, value(), 1, 4096));
        } else if (a == "--quiet" || a == "-q") {
            o.quiet = true;
        } else if (a.size() > 1 && a[0] == '-') {
            throw UsageError{"unknown option '" + a + "' (see pqdc-decimate --help)"};
        } else {
            positional.push_back(a);
        }
    }
    if (positional.empty()) throw UsageError{"no input mesh given (see pqdc-decimate --help)"};
    if (positional.size() > 1)
        throw UsageError{"more than one input given: '" + positional[0] + "' and '" + positional[1] + "'"};
    o.input = positional[0];
    if (o.output.empty()) throw UsageError{"no output: give -o OUTPUT.ply"};
    const pqdc::DecimateOptions& d = o.decimate;
    if (d.target_faces == 0 && d.target_ratio == 0 && d.max_distance_voxels == 0)
        throw UsageError{"no target: give --target-faces N, --target-ratio R or --max-distance E"};
    try {
        if (pqdc::mesh_format_from_path(o.input) == pqdc::mesh_format::stl)
            throw UsageError{"cannot read STL input '" + o.input + "'; convert it to .ply, .obj or .off"};
        pqdc::mesh_format_from_path(o.output);
    } catch (const pqdc::error& e) {
        throw UsageError{e.what()};
    }
    return o;
}

}  // namespace

int main(int argc, char** argv) {
    try {
        bool done = false;
        const CliOptions o = parse(argc, argv, done);
        if (done) return 0;
        pqdc::Mesh mesh = pqdc::read_mesh(o.input);
        pqdc::DecimateStats s;
        pqdc::decimate(mesh, o.decimate, &s);
        pqdc::write_mesh(mesh, o.output);
        if (!o.quiet)
            std::fprintf(stderr,
                         "pqdc-decimate: %zu -> %zu triangles, %zu collapses in %zu passes, %.3f s (voxel %g, sigma %g voxel); "
                         "%zu locked vertices; refused: %zu link, %zu flip, %zu quality, %zu intersection, %zu distance\n",
                         s.input_faces, s.output_faces, s.collapses, s.passes, s.seconds, s.voxel_size,
                         s.sigma_position_voxels, s.locked_vertices,
                         s.rejected_link, s.rejected_flip, s.rejected_quality, s.rejected_intersection, s.rejected_distance);
        return 0;
    } catch (...) {
        return pqdc_cli::report_current_exception("pqdc-decimate");
    }
}
