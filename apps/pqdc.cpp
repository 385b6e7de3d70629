// pqdc: mesh an OpenVDB grid or a procedural field by dual contouring with
// probabilistic plane quadrics. Parses options, calls the library, prints.
// Exit codes: 0 ok, 1 runtime error, 2 usage error, 130 interrupted.

#include "pqdc/exceptions.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/mesh_io.hpp"
#include "pqdc/procedural.hpp"
#include "pqdc/volume_io.hpp"

#include <openvdb/openvdb.h>
#include <tbb/global_control.h>

#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

namespace {

constexpr const char* kVersion = "0.1.0";

const char* kUsage = R"(usage: pqdc INPUT.vdb [options] -o OUTPUT.(obj|ply|stl)
       pqdc --procedural NAME [--resolution N] [options] -o OUTPUT.(obj|ply|stl)

Meshes the isosurface of a scalar OpenVDB grid (level set or fog volume) or of
a procedural field by dual contouring with probabilistic plane quadrics.

Input:
  INPUT.vdb                 a .vdb file with a float or double grid
  --grid NAME               the grid to mesh (default: the first scalar grid)
  --isovalue V              surface level in grid value units (default 0)
  --interior auto|below|above
                            inside is below/above the isovalue (default auto:
                            above for fog volumes, below otherwise)
  --procedural NAME         mesh a procedural field instead: sphere, box, figure3
  --resolution N            procedural lattice cells along the longest side (default 128)
  --seed S                  figure3 noise seed (default 1)
  --noise-amplitude A       figure3 noise amplitude, world units (default 0.08)
  --noise-frequency F       figure3 noise frequency, cycles per unit (default 4)
  --octaves K               figure3 noise octaves (default 4)
  --write-volume F.vdb      also write the procedural field's sampled level set

Quadrics:
  --sigma-n S               normal noise, fraction of the unit normal (default 0.1);
                            0 = classical quadrics (pseudo-inverse), inf = mass point
  --pseudo-inverse-cutoff C relative eigenvalue cutoff for --sigma-n 0 (default 0.1)
  --containment clamp|none  keep each vertex inside its cell (default clamp)

Output:
  -o, --output FILE         .obj, .ply (binary) or .stl (binary); written atomically
  --triangles               split quads along the better diagonal (default)
  --quads                   keep one quad per crossing edge
  --stats FILE.json         counts, timings and settings as JSON (written atomically)

Run:
  --threads N               worker threads (default: all cores); output is identical for any N
  --memory-limit MIB        refuse jobs estimated to need more (default: 80% of RAM)
  --progress                show progress even when stderr is not a terminal
  --quiet                   print errors only
  --help                    this text
  --version                 version and library versions
)";

struct UsageError {
    std::string message;
};

std::atomic<int> g_signal{0};
extern "C" void on_signal(int sig) { g_signal.store(sig); }

double parse_number(const std::string& option, const std::string& text) {
    if (text == "inf" || text == "infinity" || text == "Inf") return INFINITY;
    char* end = nullptr;
    errno = 0;
    const double v = std::strtod(text.c_str(), &end);
    if (text.empty() || end != text.c_str() + text.size() || errno == ERANGE || std::isnan(v))
        throw UsageError{option + " expects a number, got '" + text + "'"};
    return v;
}

long parse_integer(const std::string& option, const std::string& text, long lo, long hi) {
    char* end = nullptr;
    errno = 0;
    const long v = std::strtol(text.c_str(), &end, 10);
    if (text.empty() || end != text.c_str() + text.size() || errno == ERANGE)
        throw UsageError{option + " expects a whole number, got '" + text + "'"};
    if (v < lo || v > hi)
        throw UsageError{option + " must be between " + std::to_string(lo) + " and " + std::to_string(hi) +
                         ", got " + text};
    return v;
}

struct CliOptions {
    std::string input;
    std::string output;
    std::string grid;
    std::string procedural;
    std::string write_volume;
    std::string stats_path;
    pqdc::ExtractOptions extract;
    pqdc::ProceduralSampling sampling;
    pqdc::Figure3Params figure3;
    bool figure3_changed = false;
    int threads = 0;
    bool quiet = false;
    bool force_progress = false;
};

CliOptions parse(int argc, char** argv, bool& done) {
    CliOptions o;
    done = false;
    std::vector<std::string> args(argv + 1, argv + argc);
    std::vector<std::string> positional;
    for (std::size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        auto value = [&]() -> std::string {
            if (i + 1 >= args.size()) throw UsageError{a + " needs a value"};
            return args[++i];
        };
        if (a == "--help" || a == "-h") {
            std::cout << kUsage;
            done = true;
            return o;
        } else if (a == "--version") {
            std::cout << "pqdc " << kVersion << " (OpenVDB " << openvdb::getLibraryVersionString() << ")\n";
            done = true;
            return o;
        } else if (a == "-o" || a == "--output") {
            o.output = value();
        } else if (a == "--grid") {
            o.grid = value();
        } else if (a == "--isovalue") {
            o.extract.isovalue = parse_number(a, value());
        } else if (a == "--interior") {
            const std::string v = value();
            if (v == "auto") o.extract.interior = pqdc::Interior::automatic;
            else if (v == "below") o.extract.interior = pqdc::Interior::below_isovalue;
            else if (v == "above") o.extract.interior = pqdc::Interior::above_isovalue;
            else throw UsageError{"--interior expects auto, below or above, got '" + v + "'"};
        } else if (a == "--sigma-n") {
            o.extract.sigma_n = parse_number(a, value());
        } else if (a == "--pseudo-inverse-cutoff") {
            o.extract.pseudo_inverse_cutoff = parse_number(a, value());
        } else if (a == "--containment") {
            const std::string v = value();
            if (v == "clamp") o.extract.containment = pqdc::Containment::clamp_to_cell;
            else if (v == "none") o.extract.containment = pqdc::Containment::unconstrained;
            else throw UsageError{"--containment expects clamp or none, got '" + v + "'"};
        } else if (a == "--triangles") {
            o.extract.faces = pqdc::FaceType::triangles;
        } else if (a == "--quads") {
            o.extract.faces = pqdc::FaceType::quads;
        } else if (a == "--stats") {
            o.stats_path = value();
        } else if (a == "--procedural") {
            o.procedural = value();
        } else if (a == "--resolution") {
            o.sampling.resolution = int(parse_integer(a, value(), 4, 16384));
        } else if (a == "--seed") {
            o.figure3.seed = std::uint32_t(parse_integer(a, value(), 0, 4294967295L));
            o.figure3_changed = true;
        } else if (a == "--noise-amplitude") {
            o.figure3.noise_amplitude = parse_number(a, value());
            o.figure3_changed = true;
        } else if (a == "--noise-frequency") {
            o.figure3.noise_frequency = parse_number(a, value());
            o.figure3_changed = true;
        } else if (a == "--octaves") {
            o.figure3.octaves = int(parse_integer(a, value(), 1, 16));
            o.figure3_changed = true;
        } else if (a == "--write-volume") {
            o.write_volume = value();
        } else if (a == "--threads") {
            o.threads = int(parse_integer(a, value(), 1, 4096));
        } else if (a == "--memory-limit") {
            o.extract.memory_limit_bytes = std::size_t(parse_integer(a, value(), 1, 1L << 40)) << 20;
        } else if (a == "--progress") {
            o.force_progress = true;
        } else if (a == "--quiet" || a == "-q") {
            o.quiet = true;
        } else if (a.size() > 1 && a[0] == '-') {
            throw UsageError{"unknown option '" + a + "' (see pqdc --help)"};
        } else {
            positional.push_back(a);
        }
    }
    if (positional.size() > 1) throw UsageError{"more than one input given: '" + positional[0] + "' and '" + positional[1] + "'"};
    if (!positional.empty()) o.input = positional[0];
    if (o.input.empty() && o.procedural.empty())
        throw UsageError{"no input: give a .vdb file or --procedural NAME (see pqdc --help)"};
    if (!o.input.empty() && !o.procedural.empty())
        throw UsageError{"give either an input file ('" + o.input + "') or --procedural, not both"};
    if (o.output.empty() && o.write_volume.empty()) throw UsageError{"no output: give -o FILE.obj|.ply|.stl"};
    if (!o.write_volume.empty() && o.procedural.empty())
        throw UsageError{"--write-volume writes a procedural field; it needs --procedural"};
    if (o.figure3_changed && o.procedural != "figure3")
        throw UsageError{"--seed/--noise-*/--octaves apply to --procedural figure3 only"};
    if (!o.procedural.empty() && (!o.grid.empty() || o.extract.isovalue != 0.0))
        throw UsageError{"--grid and --isovalue apply to .vdb input, not to --procedural"};
    try {
        pqdc::validate(o.extract);
        if (!o.output.empty()) pqdc::mesh_format_from_path(o.output);
    } catch (const pqdc::error& e) {
        throw UsageError{e.what()};
    }
    if (!o.output.empty() && o.output == o.input) throw UsageError{"the output would overwrite the input '" + o.input + "'"};
    return o;
}

std::string json_escape(const std::string& s) {
    std::string out;
    for (char c : s) {
        if (c == '"' || c == '\\') out += '\\', out += c;
        else if (static_cast<unsigned char>(c) < 0x20) {
            char buf[8];
            std::snprintf(buf, sizeof buf, "\\u%04x", c);
            out += buf;
        } else out += c;
    }
    return out;
}

std::string stats_json(const CliOptions& o, const std::string& source, const pqdc::ExtractStats& s) {
    std::ostringstream j;
    j.precision(17);
    auto num = [](double v) {
        std::ostringstream t;
        t.precision(17);
        if (std::isinf(v)) t << "\"inf\"";
        else t << v;
        return t.str();
    };
    j << "{\n"
      << "  \"pqdc_version\": \"" << kVersion << "\",\n"
      << "  \"source\": \"" << json_escape(source) << "\",\n"
      << "  \"output\": \"" << json_escape(o.output) << "\",\n"
      << "  \"sigma_n\": " << num(o.extract.sigma_n) << ",\n"
      << "  \"isovalue\": " << num(o.extract.isovalue) << ",\n"
      << "  \"containment\": \"" << (o.extract.containment == pqdc::Containment::clamp_to_cell ? "clamp" : "none") << "\",\n"
      << "  \"faces\": \"" << (o.extract.faces == pqdc::FaceType::triangles ? "triangles" : "quads") << "\",\n"
      << "  \"active_cells\": " << s.active_cells << ",\n"
      << "  \"crossing_edges\": " << s.crossing_edges << ",\n"
      << "  \"boundary_crossings\": " << s.boundary_crossings << ",\n"
      << "  \"degenerate_normals\": " << s.degenerate_normals << ",\n"
      << "  \"non_finite_values\": " << s.non_finite_values << ",\n"
      << "  \"vertices\": " << s.vertices << ",\n"
      << "  \"multi_vertex_cells\": " << s.multi_vertex_cells << ",\n"
      << "  \"clamped_vertices\": " << s.clamped_vertices << ",\n"
      << "  \"fallback_vertices\": " << s.fallback_vertices << ",\n"
      << "  \"triangles\": " << s.triangles << ",\n"
      << "  \"quads\": " << s.quads << ",\n"
      << "  \"seconds\": {\"classify\": " << num(s.seconds_classify) << ", \"vertices\": " << num(s.seconds_vertices)
      << ", \"faces\": " << num(s.seconds_faces) << ", \"total\": " << num(s.seconds_total) << "}\n"
      << "}\n";
    return j.str();
}

void write_text_atomically(const std::string& path, const std::string& text) {
    const std::string tmp = path + ".tmp-" + std::to_string(::getpid());
    {
        std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
        if (!f) throw pqdc::io_error("cannot write '" + path + "': " + std::strerror(errno));
        f << text;
        f.flush();
        if (!f) {
            std::remove(tmp.c_str());
            throw pqdc::io_error("cannot write '" + path + "': write failed (disk full?)");
        }
    }
    if (std::rename(tmp.c_str(), path.c_str()) != 0) {
        const int err = errno;
        std::remove(tmp.c_str());
        throw pqdc::io_error("cannot write '" + path + "': " + std::strerror(err));
    }
}

std::unique_ptr<pqdc::ScalarField> make_field(const CliOptions& o) {
    if (o.procedural == "figure3") return pqdc::make_figure3(o.figure3);
    return pqdc::make_procedural(o.procedural);
}

int run(const CliOptions& o) {
    std::optional<tbb::global_control> threads;
    if (o.threads > 0) threads.emplace(tbb::global_control::max_allowed_parallelism, std::size_t(o.threads));

    const bool show_progress = !o.quiet && (o.force_progress || ::isatty(STDERR_FILENO));
    pqdc::ExtractOptions eo = o.extract;
    int last_percent = -1;
    eo.progress = [&](double f) {
        if (g_signal.load()) return false;
        if (show_progress) {
            const int p = int(f * 100.0);
            if (p != last_percent) {
                last_percent = p;
                std::fprintf(stderr, "\rpqdc: meshing %3d%%", p);
                std::fflush(stderr);
            }
        }
        return true;
    };
    auto log = [&](const std::string& line) {
        if (!o.quiet) std::cerr << (show_progress && last_percent >= 0 ? "\r" : "") << "pqdc: " << line << "\n";
    };

    pqdc::ExtractStats stats;
    pqdc::Mesh mesh;
    std::string source;
    if (!o.procedural.empty()) {
        const auto field = make_field(o);
        source = "procedural " + o.procedural + " at resolution " + std::to_string(o.sampling.resolution);
        if (!o.write_volume.empty()) {
            const openvdb::FloatGrid::Ptr grid = pqdc::sample_field(*field, o.sampling);
            pqdc::write_grid(*grid, o.write_volume);
            log("wrote the sampled level set of " + source + " to '" + o.write_volume + "'");
        }
        if (o.output.empty()) return 0;
        mesh = pqdc::extract(*field, o.sampling, eo, &stats);
    } else {
        const pqdc::LoadedGrid loaded = pqdc::read_scalar_grid(o.input, o.grid);
        const openvdb::GridBase& g = *loaded.grid;
        source = o.input + ":" + g.getName();
        if (loaded.chosen_automatically && loaded.scalar_grid_names.size() > 1) {
            std::string names;
            for (const auto& n : loaded.scalar_grid_names) names += (names.empty() ? "'" : ", '") + n + "'";
            log("'" + o.input + "' has several scalar grids (" + names + "); using '" + g.getName() +
                "' (choose with --grid NAME)");
        } else {
            log("using grid '" + g.getName() + "' (" + g.valueType() + ", " +
                (g.getGridClass() == openvdb::GRID_FOG_VOLUME ? "fog volume" :
                 g.getGridClass() == openvdb::GRID_LEVEL_SET ? "level set" : "unknown class") +
                ", voxel size " + std::to_string(g.voxelSize()[0]) + ") from '" + o.input + "'");
        }
        mesh = pqdc::extract(g, eo, &stats);
    }
    if (g_signal.load()) throw pqdc::cancelled_error("interrupted");
    if (mesh.empty()) log("warning: no surface found (no sign change of the field across the isovalue in the active region)");

    // Signals during the write only set the flag; the write is atomic either way.
    pqdc::write_mesh(mesh, o.output);
    if (!o.stats_path.empty()) write_text_atomically(o.stats_path, stats_json(o, source, stats));
    std::ostringstream line;
    line << stats.active_cells << " active cells -> " << stats.vertices << " vertices, "
         << (stats.triangles ? stats.triangles : stats.quads) << (stats.triangles ? " triangles" : " quads") << " in "
         << stats.seconds_total << " s";
    if (stats.clamped_vertices) line << ", " << stats.clamped_vertices << " clamped";
    if (stats.fallback_vertices) line << ", " << stats.fallback_vertices << " fallbacks";
    if (stats.degenerate_normals) line << ", " << stats.degenerate_normals << " zero-gradient crossings";
    if (stats.non_finite_values) line << ", " << stats.non_finite_values << " NaN/Inf voxels skipped";
    line << "; wrote '" << o.output << "'";
    log(line.str());
    if (g_signal.load()) {
        log("interrupted after the output was complete");
        return 130;
    }
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    std::signal(SIGINT, on_signal);
    std::signal(SIGTERM, on_signal);
    try {
        bool done = false;
        const CliOptions o = parse(argc, argv, done);
        if (done) return 0;
        return run(o);
    } catch (const UsageError& e) {
        std::cerr << "pqdc: " << e.message << "\n";
        return 2;
    } catch (const pqdc::cancelled_error&) {
        std::cerr << "\npqdc: interrupted; no output written\n";
        return 130;
    } catch (const pqdc::option_error& e) {
        std::cerr << "pqdc: " << e.what() << "\n";
        return 2;
    } catch (const std::bad_alloc&) {
        std::cerr << "pqdc: out of memory; mesh a smaller region, a coarser grid, or use --memory-limit to fail early\n";
        return 1;
    } catch (const std::exception& e) {
        std::cerr << "pqdc: " << e.what() << "\n";
        return 1;
    }
}
