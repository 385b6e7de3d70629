// pqdc-decimate: decimate a triangle/quad mesh with probabilistic quadrics
// (pqdc::decimate). Parses options, calls the library, prints.
// Exit codes: 0 ok, 1 runtime error (input, output), 2 usage error.

#include "pqdc/decimate.hpp"
#include "pqdc/exceptions.hpp"
#include "pqdc/file_io.hpp"
#include "pqdc/mesh_io.hpp"
#include "pqdc/version.hpp"

#include "cli_util.hpp"
#include "progress.hpp"

#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <cstdint>
#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

namespace {

using pqdc_cli::UsageError;
using pqdc_cli::parse_finite;
using pqdc_cli::parse_integer;

const char* kUsage = R"(usage: pqdc-decimate INPUT.(obj|ply|off|stl) -o OUTPUT.ply [options]

Decimates a mesh by edge collapses to the minimizer of summed probabilistic
quadrics. Boundary and non-manifold vertices stay where they are; a closed
manifold stays closed, manifold, of the same genus and free of new
self-intersections. Quads are split; the output has triangles only. STL
input is welded (corners at the same position are one vertex); faces
that repeat a point (such as welded needles) are left out, with a warning.
Give at least one target; decimation stops at the first one reached.)";
const std::vector<pqdc_cli::OptionSpec> kSpecs = {
    {"--target-faces", true, "at most N triangles", "Targets"},
    {"--target-ratio", true, "at most R times the input's triangles, R in (0, 1]", "Targets"},
    {"--max-distance", true,
     "keep every vertex within E voxels of the input surface (guaranteed for vertices; face interiors are not "
     "bounded)",
     "Targets"},
    {"-o,--output", true, ".ply (binary), .obj, .off or .stl; written atomically; - = standard output (with --format)"},
    {"--format", true, "obj|ply|off|stl: the output format (default: from the extension)"},
    {"--precision", true, "float|double: vertex precision of PLY, OBJ and OFF (default float; STL is always float)"},
    {"--voxel-size", true, "world units per voxel, the unit of the lengths here (default: the input's mean edge length)"},
    {"--metric", true,
     "triangle|plane|curvature: probabilistic triangle quadrics (default), plane quadrics, or triangle placement "
     "with an algebraic sphere curvature cost"},
    {"--sigma-position", true,
     "S|auto: vertex position noise, voxels (default auto: estimated from the input, 0.7 x the estimate, at least "
     "0.02)"},
    {"--sigma-normal", true, "normal noise of --metric plane (default 0.05)"},
    {"--max-normal-change", true, "largest normal turn per collapse, degrees (default 75)"},
    {"--min-quality", true, "smallest created triangle quality in [0, 1) (default 0.1)"},
    {"--threads", true, "worker threads (default: all cores); output is identical for any N"},
    {"--memory-limit", true,
     "MiB the decimation may use (default 80% of physical memory); a larger input is refused before it starts"},
    {"-q,--quiet", false, "print errors only"},
    {"--progress", false, "show progress even when stderr is not a terminal"},
    {"--stats", true,
     "FILE: write the decimation's figures as JSON (triangles before and after, collapses, passes, sigma, "
     "refusals by reason, seconds per step), as pqdc --decimate --stats does"},
};

struct CliOptions {
    std::string input, output, stats;
    pqdc::DecimateOptions decimate;
    pqdc::MeshWriteOptions write;
    bool quiet = false;
    bool force_progress = false;
};

/// One given option's value into `o` (the option's checks and messages).
void apply_option(const std::string& a, const std::string& v, CliOptions& o) {
    auto positive = [&] {
        const double x = parse_finite(a, v);
        if (!(x > 0)) throw UsageError{a + " must be > 0, got " + v};
        return x;
    };
    pqdc::DecimateOptions& d = o.decimate;
    if (a == "--output") {
        o.output = v;
    } else if (a == "--target-faces") {
        d.target_faces = std::size_t(parse_integer(a, v, 1, 2000000000L));
    } else if (a == "--target-ratio") {
        const double r = parse_finite(a, v);
        if (!(r > 0 && r <= 1)) throw UsageError{"--target-ratio must be in (0, 1], got " + v};
        d.target_ratio = r;
    } else if (a == "--max-distance") {
        d.max_distance_voxels = positive();
    } else if (a == "--format") {
        o.write.format = pqdc_cli::parse_mesh_format(v);
    } else if (a == "--precision") {
        o.write.precision = pqdc_cli::parse_vertex_precision(v);
    } else if (a == "--voxel-size") {
        d.voxel_size = positive();
    } else if (a == "--metric") {
        if (v == "triangle") d.metric = pqdc::DecimateMetric::triangle;
        else if (v == "plane") d.metric = pqdc::DecimateMetric::plane;
        else if (v == "curvature") d.metric = pqdc::DecimateMetric::curvature;
        else throw UsageError{"--metric expects triangle, plane or curvature, got '" + v + "'"};
    } else if (a == "--sigma-position") {
        d.sigma_position_voxels = v == "auto" ? pqdc::sigma_position_auto : positive();
    } else if (a == "--sigma-normal") {
        d.sigma_normal = positive();
    } else if (a == "--max-normal-change") {
        d.max_normal_change_degrees = parse_finite(a, v);
    } else if (a == "--min-quality") {
        d.min_triangle_quality = parse_finite(a, v);
    } else if (a == "--threads") {
        d.threads = int(parse_integer(a, v, 1, 4096));
    } else if (a == "--memory-limit") {
        d.memory_limit_bytes = std::size_t(parse_integer(a, v, 1, 1L << 40)) << 20;
    } else if (a == "--quiet") {
        o.quiet = true;
    } else if (a == "--progress") {
        o.force_progress = true;
    } else if (a == "--stats") {
        o.stats = v;
    }
}

CliOptions parse(int argc, char** argv, bool& done) {
    CliOptions o;
    std::vector<std::string> positional;
    const auto given =
        pqdc_cli::parse_options(argc, argv, "pqdc-decimate", kUsage, kSpecs, "the input mesh", positional, done);
    if (done) return o;
    for (const auto& [a, v] : given) apply_option(a, v, o);
    if (pqdc_cli::option_given(given, "--sigma-normal") && o.decimate.metric != pqdc::DecimateMetric::plane)
        throw UsageError{"--sigma-normal is the normal noise of --metric plane; add --metric plane or drop it"};
    if (positional.empty()) throw UsageError{"no input mesh given (see pqdc-decimate --help)"};
    if (positional.size() > 1)
        throw UsageError{"more than one input given: '" + positional[0] + "' and '" + positional[1] + "'"};
    o.input = positional[0];
    if (o.output.empty()) throw UsageError{"no output: give -o OUTPUT.ply"};
    const pqdc::DecimateOptions& d = o.decimate;
    if (d.target_faces == 0 && d.target_ratio == 0 && d.max_distance_voxels == 0)
        throw UsageError{"no target: give --target-faces N, --target-ratio R or --max-distance E"};
    pqdc_cli::check_with_option_names([&] { pqdc::validate(o.decimate); },
                                      {{"decimate: max_normal_change_degrees", "--max-normal-change"},
                                       {"decimate: min_triangle_quality", "--min-quality"},
                                       {"decimate: sigma_position_voxels", "--sigma-position"},
                                       {"decimate: sigma_normal", "--sigma-normal"},
                                       {"decimate: max_distance_voxels", "--max-distance"},
                                       {"decimate: target_ratio", "--target-ratio"},
                                       {"decimate: voxel_size", "--voxel-size"}});
    pqdc_cli::check_output_format(o.output, o.write.format);
    // A directory is no mesh: say so before the check below calls it the
    // input that -o "lies inside" (the reader says it for any other non-file).
    if (std::error_code ec; std::filesystem::is_directory(o.input, ec))
        throw pqdc::input_error("cannot read mesh '" + o.input + "': not a regular file (a directory)");
    pqdc_cli::check_distinct_files({{"the input", o.input}, {"-o", o.output}, {"--stats", o.stats}});
    try {
        pqdc::mesh_format_from_path(o.input);
        if (!o.write.format) pqdc::mesh_format_from_path(o.output);
    } catch (const pqdc::error& e) {
        throw UsageError{e.what()};
    }
    return o;
}

/// Refuses a file too large to decimate from its header, before reading it
/// can take the memory (OBJ has no count: checked after reading).
void check_header_face_count(const CliOptions& o) {
    const auto faces = pqdc::mesh_file_face_count(o.input);
    if (!faces) return;
    try {
        pqdc::check_decimate_memory(std::size_t(*faces), o.decimate);
    } catch (const pqdc::resource_error& e) {
        throw pqdc::resource_error("'" + o.input + "' announces " + std::to_string(*faces) +
                                   " faces in its header, refused before reading it: " + e.what() +
                                   " (--memory-limit MIB)");
    }
}

/// Wall seconds of reading and writing (the decimation's are DecimateStats::seconds).
struct Seconds {
    double read = 0, write = 0;
};

void write_stats(const CliOptions& o, const pqdc::DecimateStats& s, bool normals_written, const Seconds& t) {
    const nlohmann::ordered_json j = {
        {"pqdc_version", pqdc::version_string},
        {"input", o.input},
        {"output", o.output},
        {"decimate", pqdc_cli::decimation_json(s)},
        {"vertex_normals", normals_written},
        {"seconds", {{"read", pqdc_cli::json_real(t.read)}, {"decimate", pqdc_cli::json_real(s.seconds)},
                     {"write", pqdc_cli::json_real(t.write)}}}};
    pqdc::write_file(o.stats, pqdc_cli::json_text(j));
}

void print_summary(const pqdc::DecimateStats& s, bool normals_written) {
    std::fprintf(stderr,
                 "pqdc-decimate: %zu -> %zu triangles, %zu collapses in %zu passes, %.3f s (voxel %g, sigma %g voxel); "
                 "%zu locked vertices; refused: %zu link, %zu flip, %zu quality, %zu intersection, %zu distance%s\n",
                 s.input_faces, s.output_faces, s.collapses, s.passes, s.seconds, s.voxel_size, s.sigma_position_voxels,
                 s.locked_vertices, s.rejected_link, s.rejected_flip, s.rejected_quality, s.rejected_intersection,
                 s.rejected_distance, normals_written ? "; the input's vertex normals carried over" : "");
}

/// Read, decimate, write, with progress on a terminal: reading (the
/// reader's offset), decimating (between passes) and writing (bytes written).
int run(const CliOptions& o) {
    pqdc_cli::check_output_path("-o", o.output);  // before the work, as pqdc does
    if (!o.stats.empty()) pqdc_cli::check_output_path("--stats", o.stats);
    check_header_face_count(o);
    pqdc_app::Progress progress(!o.quiet && (o.force_progress || ::isatty(STDERR_FILENO)), "pqdc-decimate");
    struct stat st {};
    progress.reading("reading '" + o.input + "'", o.input,
                     ::stat(o.input.c_str(), &st) == 0 ? std::uint64_t(st.st_size) : 1);
    using Clock = std::chrono::steady_clock;
    const auto since = [](Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); };
    Seconds seconds;
    auto t = Clock::now();
    pqdc::Mesh mesh = pqdc::read_mesh(o.input);
    seconds.read = since(t);

    const pqdc::MeshFormat format = o.write.format ? *o.write.format : pqdc::mesh_format_from_path(o.output);
    pqdc::DecimateOptions d = o.decimate;
    d.stored_precision = pqdc::stored_vertex_precision(format, o.write.precision);  // checked as the file holds it
    d.progress = [&progress](double f) {
        progress.set(f);
        return true;
    };
    pqdc::DecimateStats s;
    progress.stage("decimating");
    try {
        pqdc::decimate(mesh, d, &s);
    } catch (const pqdc::input_error& e) {  // a bad point or face: name the file it is in
        throw pqdc::input_error("'" + o.input + "': " + e.what());
    }
    if (const std::string w = pqdc_cli::decimation_short_of_target(s, d); !w.empty() && !o.quiet)
        std::fprintf(stderr, "pqdc-decimate: warning: %s\n", w.c_str());

    // The input's normals were carried over; OFF and STL hold none.
    const bool normals_written = !mesh.normals.empty() && pqdc::format_holds_vertex_normals(format);
    if (!mesh.normals.empty() && !normals_written && !o.quiet)
        std::fprintf(stderr, "pqdc-decimate: warning: the input's vertex normals are not written: %s holds none "
                             "(write .ply or .obj to keep them)\n",
                     pqdc::mesh_format_name(format));
    pqdc::MeshWriteOptions w = o.write;
    w.progress = [&progress](double f) { progress.set(f); };
    progress.stage(o.output == "-" ? "writing to standard output" : "writing '" + o.output + "'");
    t = Clock::now();
    pqdc::write_mesh(mesh, o.output, w);
    progress.finish();
    seconds.write = since(t);

    if (!o.stats.empty()) write_stats(o, s, normals_written, seconds);
    if (!o.quiet) print_summary(s, normals_written);
    if (s.dropped_faces > 0 && !o.quiet)  // welded STL facets with two equal corners, typically
        std::fprintf(stderr, "pqdc-decimate: warning: %zu faces of '%s' repeat a point (zero-area needles) and "
                             "were left out\n", s.dropped_faces, o.input.c_str());
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return pqdc_cli::run_app("pqdc-decimate", argc, argv, parse, run); }
