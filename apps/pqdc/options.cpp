#include "options.hpp"

#include "../cli_util.hpp"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iostream>

namespace pqdc_app {
namespace {

using pqdc_cli::UsageError;
using pqdc_cli::parse_finite;
using pqdc_cli::parse_integer;
using pqdc_cli::parse_number;

const char* kDescription =
    "Meshes the isosurface of a scalar OpenVDB grid (level set or fog volume) or of a procedural\n"
    "field by dual contouring with probabilistic plane quadrics.\n\n"
    "usage: pqdc INPUT.vdb [options] -o OUTPUT.(obj|ply|off|stl)\n"
    "       pqdc STORE.bricks [options] -o OUTPUT.(obj|ply|off|stl)   (a pqdc-bricks store)\n"
    "       pqdc --procedural NAME [--resolution N] [options] -o OUTPUT.(obj|ply|off|stl)\n"
    "       cat in.vdb | pqdc - --format ply -o - > out.ply";

const char* kMpiDescription =
    "pqdc with the work shared among the ranks of an MPI job: each rank reads and meshes its own\n"
    "bricks and writes its part of the file. The same options and the same output bytes as pqdc.\n\n"
    "usage: mpirun -np N pqdc-mpi INPUT.vdb [options] -o OUTPUT.(obj|ply|off|stl)\n"
    "       mpirun -np N pqdc-mpi STORE.bricks [options] -o OUTPUT.(obj|ply|off|stl)\n"
    "       mpirun -np N pqdc-mpi --procedural NAME [--resolution N] [options] -o OUTPUT.(obj|ply|off|stl)";

const char* kFooter = R"(Choosing --sigma-n (normal noise as a fraction of the unit normal):
  auto       the default: pqdc estimates the volume's noise (residuals of local quadratic fits,
             in --stats as noise_voxels) and picks sigma_n, --gradient and --denoise for it:
             clean data keep sharp edges, noisy data are denoised
  0.01-0.05  clean signed distance fields from meshes or CAD (sharp edges and corners kept;
             with --gradient sharp for the crispest corners)
  0.1        level sets from simulation or sculpting, smooth with some features
  0.2-0.5    noisy or resampled data: CT/MRI/microscopy density, filtered fog volumes
  inf        the mass point: smoothest, rounds every feature, never overshoots
  0          classical quadrics (pseudo-inverse): sharpest, but turns noise into spikes

Options take their value as `--opt value` or `--opt=value`; an option given twice takes the
last value (--triangles/--quads: the last one given). Every file is written to a temporary
name and renamed into place when complete: an error or an interrupt never leaves a partial or
clobbered file (standard output, -o -, excepted). An empty surface (no sign change) is a
warning and writes an empty mesh. Progress is shown on a terminal, never otherwise.
Exit codes: 0 ok, 1 error, 2 usage error, 128+N killed by signal N (130 for Ctrl-C).)";

struct Text {
    std::string input_list, output, grid, isovalue, interior, procedural, resolution, seed, amplitude,
        frequency, octaves, write_volume, sigma_n, cutoff, containment, gradient, denoise, normals_old, max_error,
        max_cell, stats, threads, memory, format, precision, target_faces, target_ratio, max_distance, bbox, mask, min_component,
        brick_size, brick_runs, active_band;
    bool triangles = false, quads = false;  ///< --triangles, --quads (=false: as if not given)
};

void add_options(CLI::App& app, Text& t, CliOptions& o, std::vector<std::string>& positional) {
    using pqdc_cli::add_text;
    const std::string in = "Input", q = "Quadrics", out = "Output", ad = "Adaptive mode (octree dual marching cubes)",
                      run = "Run";
    app.add_option("input", positional, "a .vdb file with a float or double grid; - reads standard input")
        ->group(in);
    add_text(app, "--grid", t.grid,
             "grids to mesh: NAME, a comma list (a name that holds commas is taken whole when the file has it), "
             "or * for every scalar grid (default: the first scalar "
             "grid in the order vdb_print lists)", in);
    add_text(app, "--isovalue", t.isovalue, "surface level in grid value units (default 0)", in);
    add_text(app, "--interior", t.interior,
             "auto|below|above: inside is below/above the isovalue (default auto: below for level sets, "
             "above for fog volumes; other grids: inside is the side the background value is not on, then "
             "the side the active region's boundary is not on; the summary says which and why)", in);
    add_text(app, "--procedural", t.procedural, "mesh a procedural field instead: sphere, box, figure3", in);
    add_text(app, "--resolution", t.resolution, "procedural lattice cells along the longest side (default 128)", in);
    add_text(app, "--active-band", t.active_band,
             "procedural: voxels around the surface sampled as active too, >= 0, inf = every voxel (default 0)", in);
    add_text(app, "--seed", t.seed, "figure3 noise seed (default 1)", in);
    add_text(app, "--noise-amplitude", t.amplitude, "figure3 noise amplitude, world units (default 0.08)", in);
    add_text(app, "--noise-frequency", t.frequency, "figure3 noise frequency, cycles per unit (default 4)", in);
    add_text(app, "--octaves", t.octaves, "figure3 noise octaves (default 4)", in);
    add_text(app, "--write-volume", t.write_volume, "also write the procedural field's sampled level set (.vdb); with --bbox or --mask only the part around the region, what the mesh is made from", in);

    const std::string reg = "Region (the mesh is open where the surface leaves it; inside, it is the whole grid's)";
    add_text(app, "--bbox", t.bbox,
             "xmin,ymin,zmin,xmax,ymax,zmax: mesh only cells whose centre lies in this box, WORLD units", reg);
    add_text(app, "--mask", t.mask,
             "FILE.vdb[:GRID]: mesh only cells in the mask's active voxels (bool/mask/fog/other grids) or "
             "inside it (level sets); any transform (default GRID: the file's first usable grid)", reg);
    app.add_flag("--invert-mask", o.invert_mask, "mesh outside the mask instead")->group(reg);

    add_text(app, "--sigma-n", t.sigma_n,
             "auto or the normal noise as a fraction of the unit normal (default auto); 0 = classical "
             "quadrics, inf = mass point (see below)", q);
    add_text(app, "--pseudo-inverse-cutoff", t.cutoff, "relative eigenvalue cutoff for --sigma-n 0 (default 0.01)", q);
    add_text(app, "--containment", t.containment, "clamp|none: keep each vertex inside its cell (default clamp)", q);
    add_text(app, "--gradient", t.gradient,
             "auto|central|sharp|least-squares: grid gradients (default auto: sharp on level sets, central "
             "on fog volumes, least-squares on noisy data with --denoise off); central differences, one-sided "
             "where the field kinks (SDFs with sharp features), or the 3x3x3 least-squares fit", q);
    add_text(app, "--denoise", t.denoise,
             "auto|on|off: filter each cell's quadric with its neighbours', weighted by distance and normal "
             "agreement (default auto: on when the estimated noise is >= 0.08 voxel)", q);
    // Hidden; explained when used, also without a value ("--normals needs a value" said nothing of the rename).
    add_text(app, "--normals", t.normals_old, "renamed --gradient", q)->expected(0, 1)->group("");

    add_text(app, "-o,--output", t.output,
             "the mesh: .obj, .ply (binary), .off (ASCII) or .stl (binary); - = standard output (needs "
             "--format); {grid} in the name = one file per grid", out);
    add_text(app, "--format", t.format, "obj|ply|off|stl: the output format (default: from the extension)", out);
    add_text(app, "--precision", t.precision,
             "float|double: vertex precision of PLY, OBJ and OFF (default float; STL is always float)", out);
    app.add_flag("--vertex-normals", o.vertex_normals,
                 "write unit outward vertex normals from the field's gradient (OBJ vn, PLY nx ny nz)")
        ->group(out);
    app.add_flag("--triangles", t.triangles, "split quads along the better diagonal (default)")->group(out);
    app.add_flag("--quads", t.quads, "keep one quad per crossing edge")->group(out);
    add_text(app, "--stats", t.stats, "counts, timings and settings as JSON (written atomically; {grid} as for -o)",
             out);

    app.add_flag("--adaptive", o.adaptive, "merge cells where the surface is flat (fewer faces)")->group(ad);
    add_text(app, "--max-error", t.max_error,
             "largest merge error, voxels (a distance; default 0.1; inf = merge wherever the topology allows)", ad);
    add_text(app, "--max-cell-size", t.max_cell, "largest octree cell, voxels, a power of two (default 64)", ad);

    add_text(app, "--min-component", t.min_component,
             "remove connected components whose bounding-box diagonal is below this many voxels (default 0: keep "
             "all; 3.5 removes every noise island of bench_quality's suite and keeps droplets of radius >= 1 voxel)",
             out);
    const std::string dec = "Decimation (edge collapses with probabilistic quadrics, pqdc-decimate --help)";
    app.add_flag("--decimate", o.decimate, "decimate the mesh before writing; needs a target below")->group(dec);
    add_text(app, "--target-faces", t.target_faces, "stop at this many triangles", dec);
    add_text(app, "--target-ratio", t.target_ratio, "stop at this fraction of the input triangles, (0, 1]", dec);
    add_text(app, "--max-distance", t.max_distance, "largest vertex distance to the input surface, voxels (> 0)", dec);

    add_text(app, "--threads", t.threads, "worker threads (default: all cores); output is identical for any N", run);
    add_text(app, "--memory-limit", t.memory,
             "MiB: refuse jobs estimated to need more (default: 80% of RAM); also bounds the memory the "
             ".vdb reader may use", run);
    const std::string ooc = "Out-of-core (same output as in core)";
    app.add_flag("--out-of-core", o.out_of_core,
                 "read the .vdb grid brick by brick (delayed loading: voxel values stay in the file until a "
                 "brick needs them); in uniform mode the mesh is written brick by brick as well, through "
                 "scratch files next to the output, unless --decimate needs it whole; automatic when the grid "
                 "would need more than --memory-limit in memory")
        ->group(ooc);
    add_text(app, "--brick-size", t.brick_size,
             "voxels per brick as a cube edge, a power of two from 128 to 4096 (default 256); implies "
             "--out-of-core", ooc);
    add_text(app, "--brick-runs", t.brick_runs,
             "runs of bricks meshed at once, each on its own thread, when the mesh is written brick by brick "
             "(1 to 64; default: the threads available, at most 4, fewer when memory is short); the output "
             "does not depend on it; implies --out-of-core", ooc);
    app.add_flag("--progress", o.force_progress, "show progress even when stderr is not a terminal")->group(run);
    app.add_flag("-q,--quiet", o.quiet, "print errors only")->group(run);
    app.set_version_flag("--version",
                         std::string("pqdc ") + kVersion + " (OpenVDB " + openvdb::getLibraryVersionString() + ")",
                         "version and library versions");
    app.set_help_flag("-h,--help", "this text");
}

void parse_decimation(const Text& t, CliOptions& o) {
    const bool any_target = o.has("--target-faces") || o.has("--target-ratio") || o.has("--max-distance");
    if (any_target && !o.decimate)
        throw UsageError{"--target-faces, --target-ratio and --max-distance apply to --decimate only"};
    if (o.decimate && !any_target)
        throw UsageError{"--decimate needs a target: --target-faces N, --target-ratio R or --max-distance E"};
    pqdc::DecimateOptions& d = o.decimation;
    if (o.has("--target-faces")) d.target_faces = std::size_t(parse_integer("--target-faces", t.target_faces, 1, 2000000000L));
    if (o.has("--target-ratio")) {
        d.target_ratio = parse_number("--target-ratio", t.target_ratio);
        if (!(d.target_ratio > 0 && d.target_ratio <= 1))
            throw UsageError{"--target-ratio must be in (0, 1], got " + t.target_ratio};
    }
    if (o.has("--min-component")) {
        o.min_component_voxels = parse_number("--min-component", t.min_component);
        if (!(o.min_component_voxels >= 0))
            throw UsageError{"--min-component is a size in voxels, >= 0 (0 keeps every component), got " +
                             t.min_component};
    }
    if (o.has("--max-distance")) {
        d.max_distance_voxels = parse_number("--max-distance", t.max_distance);
        if (!(d.max_distance_voxels > 0) || std::isinf(d.max_distance_voxels))
            throw UsageError{"--max-distance is a distance in voxels, > 0, got " + t.max_distance};
    }
}

template <class Enum>
Enum choose(const std::string& option, const std::string& v, std::initializer_list<std::pair<const char*, Enum>> names) {
    std::string list;
    std::size_t i = 0;
    for (const auto& [name, value] : names) {
        if (v == name) return value;
        list += std::string(i == 0 ? "" : (i + 1 == names.size() ? " or " : ", ")) + name;
        ++i;
    }
    throw UsageError{option + " expects " + list + ", got '" + v + "'"};
}

std::vector<std::string> split_grid_list(const std::string& text) {
    std::vector<std::string> names;
    std::size_t start = 0;
    for (;;) {
        const std::size_t comma = text.find(',', start);
        const std::string name = text.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
        if (name.empty()) throw UsageError{"--grid needs grid names separated by commas, got '" + text + "'"};
        names.push_back(name);
        if (comma == std::string::npos) break;
        start = comma + 1;
    }
    if (names.size() > 1)
        for (std::size_t i = 0; i < names.size(); ++i) {
            if (names[i] == "*") throw UsageError{"--grid '*' means every scalar grid; do not mix it with names"};
            if (std::find(names.begin(), names.begin() + std::ptrdiff_t(i), names[i]) != names.begin() + std::ptrdiff_t(i))
                throw UsageError{"--grid lists '" + names[i] + "' twice; list each grid once"};
        }
    return names;
}

/// --bbox xmin,ymin,zmin,xmax,ymax,zmax (world units).
openvdb::BBoxd parse_bbox(const std::string& text) {
    std::vector<double> v;
    std::size_t start = 0;
    for (;;) {
        const std::size_t comma = text.find(',', start);
        const std::string part = text.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
        double x = 0;
        if (!pqdc_cli::read_double(part, x) || !std::isfinite(x))
            throw UsageError{"--bbox expects six finite numbers xmin,ymin,zmin,xmax,ymax,zmax (world units), got '" +
                             text + "'"};
        v.push_back(x);
        if (comma == std::string::npos) break;
        start = comma + 1;
    }
    if (v.size() != 6)
        throw UsageError{"--bbox expects six numbers xmin,ymin,zmin,xmax,ymax,zmax (world units), got " +
                         std::to_string(v.size()) + " in '" + text + "'"};
    for (int a = 0; a < 3; ++a)
        if (!(v[std::size_t(a)] <= v[std::size_t(a + 3)]))
            throw UsageError{"--bbox '" + text + "': the minimum exceeds the maximum along " +
                             std::string(1, char('x' + a)) + " (the order is xmin,ymin,zmin,xmax,ymax,zmax)"};
    return openvdb::BBoxd(openvdb::Vec3d(v[0], v[1], v[2]), openvdb::Vec3d(v[3], v[4], v[5]));
}

/// --mask FILE.vdb[:GRID]: the grid name follows the last ".vdb:" (a path may hold colons).
void parse_mask(const std::string& text, CliOptions& o) {
    if (text.empty()) throw UsageError{"--mask needs FILE.vdb or FILE.vdb:GRID, got ''"};
    const std::size_t at = text.rfind(".vdb:");
    o.mask_path = at == std::string::npos ? text : text.substr(0, at + 4);
    o.mask_grid = at == std::string::npos ? "" : text.substr(at + 5);
    if (at != std::string::npos && o.mask_grid.empty())
        throw UsageError{"--mask '" + text + "': no grid name after ':' (give FILE.vdb or FILE.vdb:GRID)"};
}

void convert(const Text& t, CliOptions& o) {
    pqdc::ExtractOptions& e = o.extract;
    if (o.has("--output") && t.output.empty()) throw UsageError{"-o needs a file name, got ''"};
    o.output = t.output;
    if (o.has("--grid")) o.grids = split_grid_list(t.grid);
    o.grid_text = t.grid;
    if (o.has("--isovalue")) e.isovalue = parse_finite("--isovalue", t.isovalue);
    if (o.has("--interior"))
        e.interior = choose<pqdc::Interior>("--interior", t.interior,
                                            {{"auto", pqdc::Interior::automatic},
                                             {"below", pqdc::Interior::below_isovalue},
                                             {"above", pqdc::Interior::above_isovalue}});
    if (o.has("--bbox")) e.region.bbox = parse_bbox(t.bbox);
    if (o.has("--mask")) parse_mask(t.mask, o);
    o.procedural = t.procedural;
    if (o.has("--resolution")) o.sampling.resolution = int(parse_integer("--resolution", t.resolution, 4, 16384));
    if (o.has("--active-band")) {
        o.sampling.active_band_voxels = parse_number("--active-band", t.active_band);
        if (!(o.sampling.active_band_voxels >= 0))
            throw UsageError{"--active-band must be >= 0 voxels (or inf), got " + t.active_band};
    }
    if (o.has("--seed")) o.figure3.seed = std::uint32_t(parse_integer("--seed", t.seed, 0, 4294967295L));
    if (o.has("--noise-amplitude")) {
        o.figure3.noise_amplitude = parse_finite("--noise-amplitude", t.amplitude);
        if (o.figure3.noise_amplitude < 0) throw UsageError{"--noise-amplitude must be >= 0, got " + t.amplitude};
    }
    if (o.has("--noise-frequency")) {
        o.figure3.noise_frequency = parse_finite("--noise-frequency", t.frequency);
        if (!(o.figure3.noise_frequency > 0)) throw UsageError{"--noise-frequency must be > 0, got " + t.frequency};
    }
    if (o.has("--octaves")) o.figure3.octaves = int(parse_integer("--octaves", t.octaves, 1, 16));
    o.write_volume = t.write_volume;
    if (o.has("--sigma-n") && t.sigma_n == "auto") {
        e.sigma_n = pqdc::sigma_n_auto;
    } else if (o.has("--sigma-n")) {
        e.sigma_n = parse_number("--sigma-n", t.sigma_n);
        if (!(e.sigma_n >= 0))
            throw UsageError{"--sigma-n must be auto or >= 0 (0 = classical quadrics, inf = mass point), got " +
                             t.sigma_n};
    }
    if (o.has("--pseudo-inverse-cutoff")) {
        e.pseudo_inverse_cutoff = parse_number("--pseudo-inverse-cutoff", t.cutoff);
        if (!(e.pseudo_inverse_cutoff >= 0 && e.pseudo_inverse_cutoff < 1))
            throw UsageError{"--pseudo-inverse-cutoff must be in [0, 1), got " + t.cutoff};
        // Accepted and ignored, it would look like a setting that did nothing.
        if (!(o.has("--sigma-n") && e.sigma_n == 0))
            throw UsageError{"--pseudo-inverse-cutoff applies with --sigma-n 0 (classical quadrics) only; the "
                             "probabilistic quadrics of sigma_n > 0 and auto are never singular"};
    }
    if (o.has("--containment"))
        e.containment = choose<pqdc::Containment>("--containment", t.containment,
                                                  {{"clamp", pqdc::Containment::clamp_to_cell},
                                                   {"none", pqdc::Containment::unconstrained}});
    if (o.has("--gradient"))
        e.normals = choose<pqdc::GridNormals>("--gradient", t.gradient,
                                              {{"auto", pqdc::GridNormals::automatic},
                                               {"central", pqdc::GridNormals::central},
                                               {"sharp", pqdc::GridNormals::sharp},
                                               {"least-squares", pqdc::GridNormals::least_squares}});
    if (o.has("--denoise"))
        e.denoise = choose<pqdc::Denoise>("--denoise", t.denoise,
                                          {{"auto", pqdc::Denoise::automatic},
                                           {"on", pqdc::Denoise::on},
                                           {"off", pqdc::Denoise::off}});
    if (o.has("--format")) o.format = pqdc_cli::parse_mesh_format(t.format);
    if (o.has("--precision")) o.precision = pqdc_cli::parse_vertex_precision(t.precision);
    if (o.has("--max-error")) {
        o.max_error_voxels = parse_number("--max-error", t.max_error);
        if (!(o.max_error_voxels >= 0))
            throw UsageError{"--max-error is a distance in voxels, >= 0 (inf allowed), got " + t.max_error};
    }
    if (o.has("--max-cell-size")) {
        o.max_cell_size_voxels = int(parse_integer("--max-cell-size", t.max_cell, 1, 4096));
        if (o.max_cell_size_voxels & (o.max_cell_size_voxels - 1))
            throw UsageError{"--max-cell-size must be a power of two, got " + std::to_string(o.max_cell_size_voxels)};
    }
    parse_decimation(t, o);
    if (o.has("--stats") && t.stats.empty()) throw UsageError{"--stats needs a file name, got ''"};
    o.stats_path = t.stats;
    if (o.has("--threads")) o.threads = int(parse_integer("--threads", t.threads, 1, 4096));
    if (o.has("--memory-limit"))
        e.memory_limit_bytes = std::size_t(parse_integer("--memory-limit", t.memory, 1, 1L << 40)) << 20;
    if (o.has("--brick-size")) {
        o.bricks.brick_size = pqdc_cli::parse_brick_size(t.brick_size);
        o.out_of_core = true;
    }
    if (o.has("--brick-runs")) {  // like --brick-size: asked for, it was ignored in core without a word
        o.bricks.concurrent_runs = int(parse_integer("--brick-runs", t.brick_runs, 1, 64));
        o.out_of_core = true;
    }
}

std::string lowercase_extension(const std::string& path) {
    const std::size_t slash = path.find_last_of('/'), dot = path.find_last_of('.');
    if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
    std::string ext = path.substr(dot);
    for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    return ext;
}

bool in_directory_part(const std::string& pattern) {
    const std::size_t at = pattern.find("{grid}"), slash = pattern.find_last_of('/');
    return at != std::string::npos && slash != std::string::npos && at < slash;
}

void check_combinations(const CliOptions& o, const std::vector<std::string>& positional) {
    if (positional.size() > 1)
        throw UsageError{"more than one input given: '" + positional[0] + "' and '" + positional[1] +
                         "' (pqdc meshes one file per run)"};
    if (o.has("--normals"))
        throw UsageError{"--normals was renamed: the grid gradient method is --gradient central|sharp; "
                         "--vertex-normals writes vertex normals into the mesh"};
    if (o.has("--invert-mask") && !o.has("--mask"))
        throw UsageError{"--invert-mask inverts a mask: give --mask FILE.vdb[:GRID] too"};
    if (o.has("--mask") && o.mask_path == "-")
        throw UsageError{"--mask reads a .vdb file; standard input (-) holds at most the input volume"};
    if (o.decimate && o.extract.faces == pqdc::FaceType::quads)
        throw UsageError{"--decimate writes triangles (its edge collapses work on triangles): drop --quads, or "
                         "drop --decimate to keep the quads"};
    if (!o.adaptive && (o.has("--max-error") || o.has("--max-cell-size")))
        throw UsageError{"--max-error and --max-cell-size apply to --adaptive only"};
    if (o.input.empty() && o.procedural.empty())
        throw UsageError{"no input: give a .vdb file or --procedural NAME (see pqdc --help)"};
    if (!o.input.empty() && !o.procedural.empty())
        throw UsageError{"give either an input file ('" + o.input + "') or --procedural, not both"};
    if (o.output.empty() && !o.stats_path.empty())
        throw UsageError{"--stats describes the mesh; it needs -o FILE.obj|.ply|.off|.stl"};
    if (o.output.empty() && o.write_volume.empty()) throw UsageError{"no output: give -o FILE.obj|.ply|.off|.stl"};
    if (!o.write_volume.empty() && o.procedural.empty())
        throw UsageError{"--write-volume writes a procedural field; it needs --procedural"};
    if (!o.write_volume.empty() && lowercase_extension(o.write_volume) != ".vdb")
        throw UsageError{"--write-volume writes an OpenVDB file; give a path ending in .vdb, got '" + o.write_volume +
                         "'"};
    const bool figure3 = o.has("--seed") || o.has("--noise-amplitude") || o.has("--noise-frequency") || o.has("--octaves");
    if (figure3 && o.procedural != "figure3")
        throw UsageError{"--seed/--noise-*/--octaves apply to --procedural figure3 only"};
    if (!o.procedural.empty() && (o.has("--grid") || o.has("--isovalue") || o.has("--interior")))
        throw UsageError{"--grid, --isovalue and --interior apply to .vdb input, not to --procedural"};
    if (!o.procedural.empty() && o.has("--gradient"))
        throw UsageError{"--gradient applies to .vdb input; procedural fields use their exact gradient"};
    if (o.procedural.empty() && o.has("--resolution"))
        throw UsageError{"--resolution applies to --procedural fields; a .vdb grid is meshed at its own resolution"};
    if (o.procedural.empty() && o.has("--active-band"))
        throw UsageError{"--active-band applies to --procedural fields; a .vdb grid keeps its own active voxels"};
    pqdc_cli::check_output_format(o.output, o.format);
    if (o.stats_path == "-" || o.write_volume == "-")
        throw UsageError{"--stats and --write-volume write files; only -o accepts - (standard output)"};
    // Only '*' is several grids for sure here: a comma list may be one name
    // with commas (Job::check_one_file_per_grid decides once the file is read).
    if (o.several_grids() && o.grids[0] == "*") check_one_mesh_per_file(o);
    for (const auto& [option, path] : {std::pair<std::string, std::string>{"-o", o.output}, {"--stats", o.stats_path}})
        if (in_directory_part(path))
            throw UsageError{option + " '" + path + "': {grid} may appear in the file name only, not in a directory"};
}

}  // namespace

bool parse_command_line(int argc, char** argv, CliOptions& o, Program program) {
    const bool mpi = program == Program::pqdc_mpi;
    const char* name = mpi ? "pqdc-mpi" : "pqdc";
    CLI::App app(mpi ? kMpiDescription : kDescription, name);
    app.footer(kFooter);
    pqdc_cli::use_help_layout(app, 30);
    Text t;
    std::vector<std::string> positional;
    add_options(app, t, o, positional);
    if (mpi) app.get_option("input")->description("a .vdb file or a brick store (pqdc-bricks split); every rank reads it");
    try {
        if (!pqdc_cli::parse_command_line(app, argc, argv, name)) return false;
    } catch (const CLI::CallForVersion&) {
        std::cout << app.version() << "\n";
        return false;
    }
    for (const CLI::Option* opt : app.get_options())
        if (opt->count() > 0 && !opt->get_lnames().empty()) o.given.insert("--" + opt->get_lnames().front());
    convert(t, o);
    // The last of --triangles/--quads on the command line that is on wins
    // (flag callbacks would run in declaration order instead); --quads=false
    // counts as not given, as every flag's =false does.
    for (const CLI::Option* opt : app.parse_order()) {
        if (opt->check_lname("triangles") && t.triangles) o.extract.faces = pqdc::FaceType::triangles;
        if (opt->check_lname("quads") && t.quads) o.extract.faces = pqdc::FaceType::quads;
    }
    if (!positional.empty()) o.input = positional[0];
    check_combinations(o, positional);
    try {
        pqdc::validate(o.extract);
        if (!o.output.empty()) {  // the extension names a format (option_error otherwise)
            const pqdc::MeshFormat f = o.format ? *o.format : pqdc::mesh_format_from_path(expand_grid_pattern(o.output, "g"));
            if (o.vertex_normals && !pqdc::format_holds_vertex_normals(f))
                throw UsageError{std::string("--vertex-normals: ") + pqdc::mesh_format_name(f) +
                                 " holds no vertex normals; write .ply or .obj, or drop --vertex-normals"};
        }
    } catch (const pqdc::error& e) {
        throw UsageError{e.what()};
    }
    // Every pair of paths the run reads or writes must differ.
    const std::vector<std::pair<std::string, std::string>> paths = {
        {"the input", o.input}, {"-o", o.output}, {"--stats", o.stats_path}, {"--write-volume", o.write_volume}};
    pqdc_cli::check_distinct_files(paths);
    // The mask may be a grid of the input file, never a file the run writes.
    for (std::size_t j = 1; j < paths.size() && !o.mask_path.empty(); ++j)
        pqdc_cli::check_distinct_files({{"--mask", o.mask_path}, paths[j]});
    return true;
}

void check_one_mesh_per_file(const CliOptions& o) {
    if (o.output == "-")
        throw UsageError{"-o - holds one mesh; with several grids give -o NAME_{grid}.ply (one file per grid)"};
    for (const auto& [option, path] : {std::pair<std::string, std::string>{"-o", o.output}, {"--stats", o.stats_path}})
        if (!path.empty() && path.find("{grid}") == std::string::npos)
            throw UsageError{"several grids (--grid " + o.grid_text + ") give one mesh each; " + option + " '" + path +
                             "' needs {grid} in its name, e.g. mesh_{grid}.ply"};
}

std::string expand_grid_pattern(const std::string& pattern, const std::string& grid) {
    std::string safe = grid.empty() ? "unnamed" : grid;
    for (char& c : safe)
        if (c == '/' || c == '\0' || static_cast<unsigned char>(c) < 0x20) c = '_';
    std::string out = pattern;
    for (std::size_t at = out.find("{grid}"); at != std::string::npos; at = out.find("{grid}", at + safe.size()))
        out.replace(at, 6, safe);
    return out;
}

}  // namespace pqdc_app
