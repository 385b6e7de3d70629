// pqdc-measure: quality measures of a mesh as JSON on stdout.
// Exit codes: 0 ok, 1 runtime error (unreadable input...), 2 usage error.

#include "pqdc/exceptions.hpp"
#include "pqdc/measure.hpp"
#include "pqdc/mesh_io.hpp"
#include "pqdc/procedural.hpp"
#include "pqdc/self_intersections.hpp"
#include "pqdc/volume_io.hpp"

#include "cli_util.hpp"

#include <openvdb/openvdb.h>
#include <tbb/global_control.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace {

using pqdc_cli::UsageError;
using pqdc_cli::parse_finite;
using pqdc_cli::parse_integer;

const char* kUsage = R"(usage: pqdc-measure MESH.(obj|ply|off|stl) [--against-procedural NAME [figure3 options]]
                    [--against VOLUME.vdb [--grid NAME]] [--against-mesh REF.(obj|ply|off|stl)]
                    [--threads N]

Prints quality measures of a mesh as one JSON object on stdout:
  topology          manifoldness, orientation, boundary edges, components...
  triangle_quality  smallest angle per triangle (quads split 0-2)
  self_intersections
                    pairs of triangles (quads split 0-2) that share a point
                    other than a shared edge or vertex, found exactly, and
                    degenerate (collinear) triangles; first_pairs lists up to
                    10 pairs of triangle numbers (triangles, then 2 per quad)
  procedural        with --against-procedural: vertex distances to the field's
                    surface f = 0 and normal deviation from grad f (world units,
                    degrees)
  volume            with --against: vertex distances to the level set's zero
                    crossing (trilinear samples, world units)
  reference_mesh    with --against-mesh: vertex distances to the reference
                    mesh's triangles and quads (exact at any distance, world
                    units; mean_signed counts inside a closed, outward-oriented
                    reference as negative))";
const std::vector<pqdc_cli::OptionSpec> kSpecs = {
    {"--against-procedural", true, "sphere, box or figure3 (default parameters, as pqdc uses)", "Against a procedural field"},
    {"--seed", true, "figure3 noise seed (default 1)", "Against a procedural field"},
    {"--noise-amplitude", true, "figure3 noise amplitude, world units (default 0.08)", "Against a procedural field"},
    {"--noise-frequency", true, "figure3 noise frequency, cycles per unit (default 4)", "Against a procedural field"},
    {"--octaves", true, "figure3 noise octaves (default 4)", "Against a procedural field"},
    {"--against", true, "FILE.vdb: a level set to measure distances against", "Against a level set"},
    {"--grid", true, "the grid in FILE.vdb (default: the first scalar grid)", "Against a level set"},
    {"--against-mesh", true, "REF: a mesh (.obj, .ply, .off or .stl) to measure distances against, e.g. the mesh a volume was made from", "Against a mesh"},
    {"--threads", true, "worker threads (default: all cores); numbers are identical for any N", "Run"},
};


struct CliOptions {
    std::string mesh;
    std::string procedural;
    pqdc::Figure3Params figure3;
    bool figure3_changed = false;
    std::string volume;
    std::string grid;
    std::string reference_mesh;
    int threads = 0;
};

CliOptions parse(int argc, char** argv, bool& done) {
    CliOptions o;
    done = false;
    std::vector<std::string> positional;
    const auto given = pqdc_cli::parse_options(argc, argv, "pqdc-measure", kUsage, kSpecs, "the mesh: .obj, .ply, .off or .stl (what pqdc writes)", positional, done);
    if (done) return o;
    for (const auto& [a, v] : given) {
        if (a == "--against-procedural") {
            o.procedural = v;
        } else if (a == "--seed") {
            o.figure3.seed = std::uint32_t(parse_integer(a, v, 0, 4294967295L));
            o.figure3_changed = true;
        } else if (a == "--noise-amplitude") {
            o.figure3.noise_amplitude = parse_finite(a, v);
            o.figure3_changed = true;
        } else if (a == "--noise-frequency") {
            o.figure3.noise_frequency = parse_finite(a, v);
            o.figure3_changed = true;
        } else if (a == "--octaves") {
            o.figure3.octaves = int(parse_integer(a, v, 1, 16));
            o.figure3_changed = true;
        } else if (a == "--against") {
            o.volume = v;
        } else if (a == "--grid") {
            o.grid = v;
        } else if (a == "--against-mesh") {
            o.reference_mesh = v;
        } else if (a == "--threads") {
            o.threads = int(parse_integer(a, v, 1, 4096));
        }
    }
    if (positional.empty()) throw UsageError{"no mesh given (see pqdc-measure --help)"};
    if (positional.size() > 1)
        throw UsageError{"more than one mesh given: '" + positional[0] + "' and '" + positional[1] + "'"};
    o.mesh = positional[0];
    if (o.figure3_changed && o.procedural != "figure3")
        throw UsageError{"--seed/--noise-*/--octaves apply to --against-procedural figure3 only"};
    if (!o.grid.empty() && o.volume.empty()) throw UsageError{"--grid names a grid in the --against file; give --against"};
    if (!o.procedural.empty()) {
        bool known = false;
        std::string names;
        for (const std::string& n : pqdc::procedural_names()) {
            known = known || n == o.procedural;
            names += (names.empty() ? "" : ", ") + n;
        }
        if (!known) throw UsageError{"unknown procedural field '" + o.procedural + "'; choose one of " + names};
    }
    return o;
}

/// The library's reference checks do not know the file; name it.
pqdc::DistanceStats distance_to_mesh(const pqdc::Mesh& mesh, const std::string& reference_path) {
    const pqdc::Mesh reference = pqdc::read_mesh(reference_path);  // its errors name the file
    try {
        return pqdc::measure_distance(mesh, reference);
    } catch (const pqdc::input_error& e) {
        throw pqdc::input_error("--against-mesh '" + reference_path + "': " + e.what());
    }
}

int run(const CliOptions& o) {
    std::optional<tbb::global_control> threads;
    if (o.threads > 0) threads.emplace(tbb::global_control::max_allowed_parallelism, std::size_t(o.threads));

    const pqdc::Mesh mesh = pqdc::read_mesh(o.mesh);
    // The library's to_json pieces already write non-finite numbers as null.
    auto piece = [](const std::string& text) { return nlohmann::ordered_json::parse(text); };
    nlohmann::ordered_json j;
    j["mesh"] = o.mesh;
    j["topology"] = piece(pqdc::to_json(pqdc::measure_topology(mesh)));
    j["triangle_quality"] = piece(pqdc::to_json(pqdc::measure_triangle_quality(mesh)));
    pqdc::SelfIntersectionOptions self_intersection_options;
    self_intersection_options.max_pairs = 10;
    j["self_intersections"] = piece(pqdc::to_json(pqdc::find_self_intersections(mesh, self_intersection_options)));
    if (!o.procedural.empty()) {
        const std::unique_ptr<pqdc::ScalarField> field =
            o.procedural == "figure3" ? pqdc::make_figure3(o.figure3) : pqdc::make_procedural(o.procedural);
        j["procedural"] = {
            {"name", o.procedural},
            {"distance", piece(pqdc::to_json(pqdc::measure_distance(mesh, *field)))},
            {"normal_deviation_per_face",
             piece(pqdc::to_json(pqdc::measure_normal_deviation(mesh, *field, pqdc::NormalSampling::per_face)))},
            {"normal_deviation_per_vertex",
             piece(pqdc::to_json(pqdc::measure_normal_deviation(mesh, *field, pqdc::NormalSampling::per_vertex)))}};
    }
    if (!o.volume.empty()) {
        const pqdc::LoadedGrid loaded = pqdc::read_scalar_grid(o.volume, o.grid);
        openvdb::FloatGrid::ConstPtr grid = openvdb::GridBase::constGrid<openvdb::FloatGrid>(loaded.grid);
        if (!grid) {
            throw pqdc::input_error("grid '" + loaded.grid->getName() + "' in '" + o.volume + "' is " +
                                    loaded.grid->valueType() +
                                    "; distances are measured against float level sets only");
        }
        j["volume"] = {{"path", o.volume},
                       {"grid", grid->getName()},
                       {"distance", piece(pqdc::to_json(pqdc::measure_distance(mesh, *grid)))}};
    }
    if (!o.reference_mesh.empty())
        j["reference_mesh"] = {{"path", o.reference_mesh},
                               {"distance", piece(pqdc::to_json(distance_to_mesh(mesh, o.reference_mesh)))}};
    pqdc_cli::write_stdout(pqdc_cli::json_text(j));
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    return pqdc_cli::run_app("pqdc-measure", argc, argv, parse, [](const CliOptions& o) {
        pqdc_cli::start_openvdb();
        return run(o);
    });
}
