// pqdc: mesh an OpenVDB grid or a procedural field by dual contouring with
// probabilistic plane quadrics. Parses options, calls the library, prints.
// Exit codes: 0 ok, 1 runtime error (input, output, resources), 2 usage
// error, 128 + signal number when interrupted (130 SIGINT, 143 SIGTERM).

#include "pqdc/adaptive.hpp"
#include "pqdc/decimate.hpp"
#include "pqdc/exceptions.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/mesh_io.hpp"
#include "pqdc/procedural.hpp"
#include "pqdc/volume_io.hpp"

#include "cli_util.hpp"

#include <openvdb/io/Stream.h>
#include <openvdb/openvdb.h>
#include <tbb/global_control.h>

#include <fcntl.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <limits>
#include <memory>
#include <optional>
#include <set>
#include <sstream>
#include <streambuf>
#include <string>
#include <type_traits>
#include <vector>

#if defined(__SANITIZE_ADDRESS__)
#define PQDC_CLI_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define PQDC_CLI_ASAN 1
#endif
#endif

namespace {

using pqdc_cli::UsageError;
using pqdc_cli::parse_number;
using pqdc_cli::parse_finite;
using pqdc_cli::parse_integer;
using pqdc_cli::json_number;
using pqdc_cli::json_string;

constexpr const char* kVersion = "0.1.0";

const char* kUsage = R"(usage: pqdc INPUT.vdb [options] -o OUTPUT.(obj|ply|off|stl)
       pqdc --procedural NAME [--resolution N] [options] -o OUTPUT.(obj|ply|off|stl)

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
  --pseudo-inverse-cutoff C relative eigenvalue cutoff for --sigma-n 0 (default 0.01)
  --containment clamp|none  keep each vertex inside its cell (default clamp)
  --normals central|sharp   grid normals: central differences (default), or one-sided
                            where the field kinks, for clean SDFs with sharp features

Output:
  -o, --output FILE         .obj, .ply (binary), .off (ASCII) or .stl (binary); written atomically
  --triangles               split quads along the better diagonal (default)
  --quads                   keep one quad per crossing edge

Adaptive mode (octree dual marching cubes):
  --adaptive                merge cells where the surface is flat (fewer faces)
  --max-error E             largest merge error, voxels (a distance; default 0.1)
  --max-cell-size N         largest octree cell, voxels, a power of two (default 64)
  --decimate                decimate the mesh before writing (pqdc-decimate --help):
  --target-faces N, --target-ratio R, --max-distance E (voxels); at least one
  --stats FILE.json         counts, timings and settings as JSON (written atomically)

Run:
  --threads N               worker threads (default: all cores); output is identical for any N
  --memory-limit MIB        refuse jobs estimated to need more (default: 80% of RAM);
                            also bounds the memory the .vdb reader may use
  --progress                show progress even when stderr is not a terminal
  --quiet                   print errors only
  --help                    this text
  --version                 version and library versions

Every file is written to a temporary name and renamed into place when
complete: an error or an interrupt never leaves a partial or clobbered file.
An empty surface (no sign change) is a warning and writes an empty mesh.
Exit codes: 0 ok, 1 error, 2 usage error, 128+N killed by signal N (130 for Ctrl-C).
)";

/// A signal arrived while a file was being written; that file is complete.
struct Interrupted {
    int signal;
    std::string written;
};

// ------------------------------------------------------------------ signals
//
// Sampling a procedural field and reading a file have no cancellation
// points, so waiting for the library to notice a flag can take many seconds.
// Outside of writes nothing on disk needs cleaning up, so the handler exits
// at once. During a write (phase_writing) it only records the signal; the
// write finishes (or fails and removes its temporary) and the signal is acted
// on right after. The phase switch is a compare-exchange so the handler and
// the main thread can never both win.
constexpr int phase_computing = 0, phase_writing = 1, phase_exiting = 2;
std::atomic<int> g_phase{phase_computing};
std::atomic<int> g_signal{0};
std::atomic<bool> g_wrote_something{false};

extern "C" void on_signal(int sig) {
    g_signal.store(sig);
    int expected = phase_computing;
    if (g_phase.compare_exchange_strong(expected, phase_exiting)) {
        static const char nothing[] = "\npqdc: interrupted; no output written\n";
        static const char partial[] =
            "\npqdc: interrupted; files reported as written are complete, nothing else was written\n";
        if (g_wrote_something.load())
            (void)!::write(STDERR_FILENO, partial, sizeof partial - 1);
        else
            (void)!::write(STDERR_FILENO, nothing, sizeof nothing - 1);
        ::_exit(128 + sig);
    }
}

void install_signal_handlers() {
    struct sigaction sa {};
    sa.sa_handler = on_signal;
    sigemptyset(&sa.sa_mask);
    sa.sa_flags = SA_RESTART;
    sigaction(SIGINT, &sa, nullptr);
    sigaction(SIGTERM, &sa, nullptr);
    // With a file size limit (ulimit -f) write() must fail with EFBIG and be
    // reported, not kill the process with SIGXFSZ and a core dump.
    std::signal(SIGXFSZ, SIG_IGN);
}

/// Runs `write` (which creates one file atomically) with signals deferred.
void write_deferring_signals(const std::string& path, const std::function<void()>& write) {
    int expected = phase_computing;
    if (!g_phase.compare_exchange_strong(expected, phase_writing)) {
        for (;;) ::pause();  // another thread's signal handler is exiting the process
    }
    struct Leave {
        ~Leave() { g_phase.store(phase_computing); }
    } leave;
    write();
    g_wrote_something.store(true);
    if (const int sig = g_signal.load()) throw Interrupted{sig, path};
}

// ----------------------------------------------------------- option parsing

std::string lowercase_extension(const std::string& path) {
    const std::size_t slash = path.find_last_of('/'), dot = path.find_last_of('.');
    if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
    std::string ext = path.substr(dot);
    for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    return ext;
}

/// True when a and b name the same file (existing or not).
bool same_file(const std::string& a, const std::string& b) {
    std::error_code ea, eb;
    const auto ca = std::filesystem::weakly_canonical(a, ea), cb = std::filesystem::weakly_canonical(b, eb);
    return (!ea && !eb) ? ca == cb : a == b;
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
    bool interior_changed = false;
    bool adaptive = false;
    double max_error_voxels = pqdc::AdaptiveOptions{}.max_error_voxels;
    int max_cell_size_voxels = pqdc::AdaptiveOptions{}.max_cell_size_voxels;
    int threads = 0;
    bool quiet = false;
    bool force_progress = false;
};

CliOptions parse(int argc, char** argv, bool& done) {
    CliOptions o;
    done = false;
    std::vector<std::string> args(argv + 1, argv + argc);
    std::vector<std::string> positional;
    std::set<std::string> seen;  // value options and face-type flags, by canonical name
    bool triangles = false, quads = false;
    for (std::size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        auto value = [&]() -> std::string {
            const std::string key = a == "-o" ? "--output" : a;
            if (!seen.insert(key).second) throw UsageError{a + " given more than once"};
            if (i + 1 >= args.size()) throw UsageError{a + " needs a value"};
            const std::string& v = args[++i];
            // "-o --quads" is a forgotten value, not an output named "--quads".
            if (v.size() > 2 && v.compare(0, 2, "--") == 0)
                throw UsageError{a + " needs a value, got the option '" + v + "'"};
            return v;
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
            if (o.output.empty()) throw UsageError{a + " needs a file name, got ''"};
        } else if (a == "--grid") {
            o.grid = value();
            if (o.grid.empty()) throw UsageError{"--grid needs a grid name, got ''"};
        } else if (a == "--isovalue") {
            o.extract.isovalue = parse_finite(a, value());
        } else if (a == "--interior") {
            const std::string v = value();
            o.interior_changed = true;
            if (v == "auto") o.extract.interior = pqdc::Interior::automatic;
            else if (v == "below") o.extract.interior = pqdc::Interior::below_isovalue;
            else if (v == "above") o.extract.interior = pqdc::Interior::above_isovalue;
            else throw UsageError{"--interior expects auto, below or above, got '" + v + "'"};
        } else if (a == "--sigma-n") {
            const std::string v = value();
            o.extract.sigma_n = parse_number(a, v);
            if (!(o.extract.sigma_n >= 0))
                throw UsageError{"--sigma-n must be >= 0 (0 = classical quadrics, inf = mass point), got " + v};
        } else if (a == "--pseudo-inverse-cutoff") {
            const std::string v = value();
            o.extract.pseudo_inverse_cutoff = parse_number(a, v);
            if (!(o.extract.pseudo_inverse_cutoff >= 0 && o.extract.pseudo_inverse_cutoff < 1))
                throw UsageError{"--pseudo-inverse-cutoff must be in [0, 1), got " + v};
        } else if (a == "--normals") {
            const std::string v = value();
            if (v == "central") o.extract.normals = pqdc::GridNormals::central;
            else if (v == "sharp") o.extract.normals = pqdc::GridNormals::sharp;
            else throw UsageError{"--normals expects central or sharp, got '" + v + "'"};
        } else if (a == "--containment") {
            const std::string v = value();
            if (v == "clamp") o.extract.containment = pqdc::Containment::clamp_to_cell;
            else if (v == "none") o.extract.containment = pqdc::Containment::unconstrained;
            else throw UsageError{"--containment expects clamp or none, got '" + v + "'"};
        } else if (a == "--triangles") {
            triangles = true;
            o.extract.faces = pqdc::FaceType::triangles;
        } else if (a == "--quads") {
            quads = true;
            o.extract.faces = pqdc::FaceType::quads;
        } else if (a == "--adaptive") {
            o.adaptive = true;
        } else if (a == "--max-error") {
            const std::string v = value();
            o.max_error_voxels = parse_number(a, v);
            if (!(o.max_error_voxels >= 0) || std::isinf(o.max_error_voxels))
                throw UsageError{"--max-error is a distance in voxels, >= 0, got " + v};
        } else if (a == "--max-cell-size") {
            o.max_cell_size_voxels = int(parse_integer(a, value(), 1, 4096));
            if (o.max_cell_size_voxels & (o.max_cell_size_voxels - 1))
                throw UsageError{"--max-cell-size must be a power of two, got " + std::to_string(o.max_cell_size_voxels)};
        } else if (a == "--stats") {
            o.stats_path = value();
            if (o.stats_path.empty()) throw UsageError{"--stats needs a file name, got ''"};
        } else if (a == "--procedural") {
            o.procedural = value();
        } else if (a == "--resolution") {
            o.sampling.resolution = int(parse_integer(a, value(), 4, 16384));
        } else if (a == "--seed") {
            o.figure3.seed = std::uint32_t(parse_integer(a, value(), 0, 4294967295L));
            o.figure3_changed = true;
        } else if (a == "--noise-amplitude") {
            const std::string v = value();
            o.figure3.noise_amplitude = parse_finite(a, v);
            if (o.figure3.noise_amplitude < 0) throw UsageError{"--noise-amplitude must be >= 0, got " + v};
            o.figure3_changed = true;
        } else if (a == "--noise-frequency") {
            const std::string v = value();
            o.figure3.noise_frequency = parse_finite(a, v);
            if (!(o.figure3.noise_frequency > 0)) throw UsageError{"--noise-frequency must be > 0, got " + v};
            o.figure3_changed = true;
        } else if (a == "--octaves") {
            o.figure3.octaves = int(parse_integer(a, value(), 1, 16));
            o.figure3_changed = true;
        } else if (a == "--write-volume") {
            o.write_volume = value();
            if (lowercase_extension(o.write_volume) != ".vdb")
                throw UsageError{"--write-volume writes an OpenVDB file; give a path ending in .vdb, got '" +
                                 o.write_volume + "'"};
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
    if (triangles && quads) throw UsageError{"--triangles and --quads contradict each other; give one"};
    if (!o.adaptive && (seen.count("--max-error") || seen.count("--max-cell-size")))
        throw UsageError{"--max-error and --max-cell-size apply to --adaptive only"};
    if (positional.size() > 1)
        throw UsageError{"more than one input given: '" + positional[0] + "' and '" + positional[1] +
                         "' (pqdc meshes one file per run)"};
    if (!positional.empty()) o.input = positional[0];
    if (o.input.empty() && o.procedural.empty())
        throw UsageError{"no input: give a .vdb file or --procedural NAME (see pqdc --help)"};
    if (!o.input.empty() && !o.procedural.empty())
        throw UsageError{"give either an input file ('" + o.input + "') or --procedural, not both"};
    if (o.output.empty() && !o.stats_path.empty())
        throw UsageError{"--stats describes the mesh; it needs -o FILE.obj|.ply|.off|.stl"};
    if (o.output.empty() && o.write_volume.empty()) throw UsageError{"no output: give -o FILE.obj|.ply|.off|.stl"};
    if (!o.write_volume.empty() && o.procedural.empty())
        throw UsageError{"--write-volume writes a procedural field; it needs --procedural"};
    if (o.figure3_changed && o.procedural != "figure3")
        throw UsageError{"--seed/--noise-*/--octaves apply to --procedural figure3 only"};
    if (!o.procedural.empty() && (!o.grid.empty() || seen.count("--isovalue") || o.interior_changed))
        throw UsageError{"--grid, --isovalue and --interior apply to .vdb input, not to --procedural"};
    if (!o.procedural.empty() && seen.count("--normals"))
        throw UsageError{"--normals applies to .vdb input; procedural fields use their exact gradient"};
    if (o.procedural.empty() && seen.count("--resolution"))
        throw UsageError{"--resolution applies to --procedural fields; a .vdb grid is meshed at its own resolution"};
    try {
        pqdc::validate(o.extract);
        if (!o.output.empty()) pqdc::mesh_format_from_path(o.output);
    } catch (const pqdc::error& e) {
        throw UsageError{e.what()};
    }
    // Every pair of paths the run reads or writes must differ.
    const std::vector<std::pair<std::string, std::string>> paths = {
        {"the input", o.input}, {"-o", o.output}, {"--stats", o.stats_path}, {"--write-volume", o.write_volume}};
    for (std::size_t i = 0; i < paths.size(); ++i)
        for (std::size_t j = i + 1; j < paths.size(); ++j)
            if (!paths[i].second.empty() && !paths[j].second.empty() && same_file(paths[i].second, paths[j].second))
                throw UsageError{paths[j].first + " '" + paths[j].second + "' is the same file as " + paths[i].first +
                                 "; give different paths"};
    return o;
}

// --------------------------------------------------------- output preflight

/// Fails before any work when a result could not be written at all, rather
/// than after a long extraction. (Disk full is still only seen when writing.)
void check_output_path(const std::string& option, const std::string& path) {
    struct stat st {};
    if (::stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode))
        throw pqdc::io_error("cannot write '" + path + "' (" + option + "): it is a directory; give a file name");
    const std::size_t slash = path.find_last_of('/');
    const std::string dir = slash == std::string::npos ? "." : (slash == 0 ? "/" : path.substr(0, slash));
    if (::stat(dir.c_str(), &st) != 0)
        throw pqdc::io_error("cannot write '" + path + "' (" + option + "): the directory '" + dir + "' " +
                             (errno == ENOENT ? "does not exist; create it first or choose another path"
                                              : std::string("cannot be accessed: ") + std::strerror(errno)));
    if (!S_ISDIR(st.st_mode))
        throw pqdc::io_error("cannot write '" + path + "' (" + option + "): '" + dir + "' is not a directory");
    if (::access(dir.c_str(), W_OK | X_OK) != 0)
        throw pqdc::io_error("cannot write '" + path + "' (" + option + "): cannot create files in '" + dir +
                             "' (" + std::strerror(errno) + "); choose a writable directory");
}

// ------------------------------------------- reading in a child process
//
// OpenVDB's reader trusts the sizes and masks in a file. A flipped bit can
// make it overflow a heap buffer (io::bloscFromStream reads a chunk of the
// size stored in the file into a buffer of the expected size and only then
// compares the two) or copy a metadata string of gigabytes. So the file is
// parsed in a child process under an address-space limit; the child sends the
// grid back through a pipe, re-serialized by OpenVDB's writer from the tree
// it built (a stream whose sizes and masks are consistent by construction).
// A crash or a blown limit in the child becomes an error naming the file.
//
// The child is this executable started afresh (fork, then exec of
// /proc/self/exe with a hidden first argument), never a bare fork: loading
// libopenvdb starts log4cplus's thread pool, so pqdc is multithreaded from
// its first line, and a forked copy that allocates can deadlock on a lock one
// of those threads held at the fork (seen with ASan's allocator).

class FdInBuf : public std::streambuf {
public:
    explicit FdInBuf(int fd) : fd_(fd) {}

protected:
    int_type underflow() override {
        for (;;) {
            const ssize_t n = ::read(fd_, buffer_, sizeof buffer_);
            if (n < 0 && errno == EINTR) continue;
            if (n <= 0) return traits_type::eof();
            setg(buffer_, buffer_, buffer_ + n);
            return traits_type::to_int_type(buffer_[0]);
        }
    }

private:
    int fd_;
    char buffer_[1 << 16];
};

class FdOutBuf : public std::streambuf {
public:
    explicit FdOutBuf(int fd) : fd_(fd) { setp(buffer_, buffer_ + sizeof buffer_); }

protected:
    int_type overflow(int_type c) override {
        if (!drain()) return traits_type::eof();
        if (!traits_type::eq_int_type(c, traits_type::eof())) {
            *pptr() = traits_type::to_char_type(c);
            pbump(1);
        }
        return traits_type::not_eof(c);
    }
    int sync() override { return drain() ? 0 : -1; }

private:
    bool drain() {
        const char* p = pbase();
        while (p < pptr()) {
            const ssize_t n = ::write(fd_, p, std::size_t(pptr() - p));
            if (n < 0 && errno == EINTR) continue;
            if (n <= 0) return false;
            p += n;
        }
        setp(buffer_, buffer_ + sizeof buffer_);
        return true;
    }

    int fd_;
    char buffer_[1 << 16];
};

void put_u32(std::ostream& os, std::uint32_t v) { os.write(reinterpret_cast<const char*>(&v), 4); }
void put_string(std::ostream& os, const std::string& s) {
    put_u32(os, std::uint32_t(s.size()));
    os.write(s.data(), std::streamsize(s.size()));
}
std::uint32_t get_u32(std::istream& is) {
    std::uint32_t v = 0;
    is.read(reinterpret_cast<char*>(&v), 4);
    return v;
}
std::string get_string(std::istream& is) {
    const std::uint32_t n = get_u32(is);
    if (!is || n > (1u << 24)) {  // the child never sends more; a bad length means a broken pipe
        is.setstate(std::ios::failbit);
        return {};
    }
    std::string s(n, '\0');
    is.read(s.data(), n);
    return s;
}

constexpr char kReplyMagic[4] = {'P', 'Q', 'R', 'D'};
constexpr int kReaderExitOutOfMemory = 5, kReaderExitTerminated = 6, kReaderExitNoExec = 127;
enum class Reply : char { grid = 'G', input_error = 'I', resource_error = 'R', other_error = 'E' };

std::size_t physical_memory_bytes() {
    const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGE_SIZE);
    if (pages <= 0 || page <= 0) return std::numeric_limits<std::size_t>::max();
    return std::size_t(pages) * std::size_t(page);
}

/// How much the reader may allocate. OpenVDB data does not expand much when
/// read: masks are stored raw, so an 8^3 leaf (>= ~130 bytes on disk) or an
/// internal node (>= 1 KiB of masks) takes at most ~40x its file size in
/// memory; 256x the file size plus 1 GiB is a generous ceiling that still
/// stops a corrupt 100 KiB file from allocating 10 GiB.
constexpr std::size_t kReaderMinimumBytes = std::size_t(64) << 20;

struct ReadBudget {
    std::size_t bytes = 0;
    bool from_file_size = false;  ///< the file-size ceiling, not the memory limit, is the smaller one
};

ReadBudget read_budget(const std::string& path, std::size_t memory_limit_bytes) {
    ReadBudget b;
    b.bytes = memory_limit_bytes ? memory_limit_bytes : std::size_t(double(physical_memory_bytes()) * 0.8);
    // The reader is a fresh process: below a few MiB, blosc and OpenVDB's
    // first allocations fail in code that does not expect it (the child then
    // dies without a useful message). A --memory-limit that small is enforced
    // by the extractor's estimate instead, with a clear message.
    b.bytes = std::max(b.bytes, kReaderMinimumBytes);
    struct stat st {};
    if (::stat(path.c_str(), &st) == 0 && st.st_size > 0) {
        const double ceiling = 256.0 * double(st.st_size) + double(std::size_t(1) << 30);
        if (ceiling < double(b.bytes)) {
            b.bytes = std::size_t(ceiling);
            b.from_file_size = true;
        }
    }
    return b;
}

std::string mib(std::size_t bytes) { return std::to_string((bytes + (1u << 20) - 1) >> 20) + " MiB"; }

std::string out_of_memory_message(const std::string& path, const ReadBudget& budget) {
    return "reading '" + path + "' needs more than " + mib(budget.bytes) +
           (budget.from_file_size
                ? "; a valid OpenVDB file of this size never needs that much, so the file is corrupt (a size "
                  "field holds garbage): re-export it or check that the copy is complete"
                : "; give a higher --memory-limit if the machine has the memory, or check the file: it may be "
                  "corrupt");
}

void limit_address_space(std::size_t extra_bytes) {
#ifndef PQDC_CLI_ASAN  // ASan reserves terabytes of shadow address space; no limit there
    long pages = 0;
    if (std::FILE* f = std::fopen("/proc/self/statm", "r")) {
        if (std::fscanf(f, "%ld", &pages) != 1) pages = 0;
        std::fclose(f);
    }
    const double current = double(pages) * double(::sysconf(_SC_PAGE_SIZE));
    const double wanted = current + double(extra_bytes);
    if (wanted < double(std::numeric_limits<rlim_t>::max()) * 0.5) {
        struct rlimit rl {};
        ::getrlimit(RLIMIT_AS, &rl);
        if (rl.rlim_cur == RLIM_INFINITY || rlim_t(wanted) < rl.rlim_cur) {
            rl.rlim_cur = rlim_t(wanted);
            ::setrlimit(RLIMIT_AS, &rl);
        }
    }
#else
    (void)extra_bytes;
#endif
}

void lift_address_space_limit() {
#ifndef PQDC_CLI_ASAN
    struct rlimit rl {};
    ::getrlimit(RLIMIT_AS, &rl);
    rl.rlim_cur = rl.rlim_max;
    ::setrlimit(RLIMIT_AS, &rl);
#endif
}

constexpr const char* kReaderArgument = "--internal-vdb-reader";

[[noreturn]] void reader_child(int fd, pid_t parent, const std::string& path, const std::string& grid,
                               const ReadBudget& budget) {
    // The parent set PR_SET_PDEATHSIG (we die with an interrupted pqdc); it
    // may have died before that took effect.
    if (::getppid() != parent) ::_exit(3);
    // Under the address-space limit a bad_alloc can also escape from a
    // noexcept corner of OpenVDB; say so through the exit code rather than
    // abort() and be mistaken for a crash on corrupt data.
    std::set_terminate([] {
        int code = kReaderExitTerminated;
        if (const std::exception_ptr e = std::current_exception()) {
            try {
                std::rethrow_exception(e);
            } catch (const std::bad_alloc&) {
                code = kReaderExitOutOfMemory;
            } catch (...) {
            }
        }
        ::_exit(code);
    });
#ifndef PQDC_CLI_ASAN
    // glibc's "malloc(): corrupted ..." lines would only repeat what the parent reports.
    if (const int null = ::open("/dev/null", O_WRONLY | O_CLOEXEC); null >= 0) ::dup2(null, STDERR_FILENO);
#endif
    FdOutBuf buf(fd);
    std::ostream os(&buf);
    os.write(kReplyMagic, 4);
    auto reply_error = [&](Reply kind, const std::string& message) {
        os.put(char(kind));
        put_string(os, message);
    };
    limit_address_space(budget.bytes);
    try {
        try {
            const pqdc::LoadedGrid loaded = pqdc::read_scalar_grid(path, grid);
            lift_address_space_limit();  // re-serializing may allocate; the grid is known good now
            os.put(char(Reply::grid));
            os.put(loaded.chosen_automatically ? 1 : 0);
            for (const auto* names : {&loaded.grid_names, &loaded.scalar_grid_names}) {
                put_u32(os, std::uint32_t(names->size()));
                for (const auto& n : *names) put_string(os, n);
            }
            openvdb::io::Stream stream(os);
            // Active-mask compression is lossless (inactive values are kept).
            stream.setCompression(openvdb::io::COMPRESS_ACTIVE_MASK);
            stream.write(openvdb::GridCPtrVec{loaded.grid});
        } catch (const std::bad_alloc&) {
            throw pqdc::resource_error("out of memory");
        }
    } catch (const pqdc::resource_error&) {
        lift_address_space_limit();
        // Its text is the generic "ran out of memory"; the budget says more.
        reply_error(Reply::resource_error, out_of_memory_message(path, budget));
    } catch (const pqdc::input_error& e) {
        reply_error(Reply::input_error, e.what());
    } catch (const std::exception& e) {
        reply_error(Reply::other_error, "reading '" + path + "' failed: " + e.what());
    }
    os.flush();
    ::_exit(os ? 0 : 4);
}

std::string describe_wait_status(int status) {
    if (WIFSIGNALED(status)) {
        const int sig = WTERMSIG(status);
        const char* name = ::strsignal(sig);
        return std::string("signal ") + std::to_string(sig) + (name ? std::string(", ") + name : std::string());
    }
    if (WIFEXITED(status)) return "exit code " + std::to_string(WEXITSTATUS(status));
    return "unknown status";
}

pqdc::LoadedGrid read_grid_isolated(const std::string& path, const std::string& grid,
                                    std::size_t memory_limit_bytes) {
    openvdb::initialize();
    const ReadBudget budget = read_budget(path, memory_limit_bytes);
    int fds[2];
    if (::pipe2(fds, O_CLOEXEC) != 0)
        throw pqdc::resource_error(std::string("cannot start the .vdb reader: pipe: ") + std::strerror(errno));
    std::cout.flush();
    std::cerr.flush();
    const pid_t parent = ::getpid();
    // Everything the child needs is built before the fork: between fork and
    // exec only async-signal-safe calls are allowed.
    std::vector<std::string> args{"pqdc",
                                  kReaderArgument,
                                  std::to_string(fds[1]),
                                  std::to_string(parent),
                                  std::to_string(budget.bytes),
                                  budget.from_file_size ? "1" : "0",
                                  path,
                                  grid};
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    const pid_t pid = ::fork();
    if (pid < 0) {
        const int err = errno;
        ::close(fds[0]);
        ::close(fds[1]);
        throw pqdc::resource_error(std::string("cannot start the .vdb reader: fork: ") + std::strerror(err));
    }
    if (pid == 0) {
        // Die with pqdc (an interrupted parent exits without waiting for us).
        ::prctl(PR_SET_PDEATHSIG, SIGKILL);
        // Signals pqdc catches are reset by exec; SIGXFSZ stays ignored, as it should.
        ::fcntl(fds[1], F_SETFD, 0);  // the write end survives exec, the read end (O_CLOEXEC) does not
        ::execv("/proc/self/exe", argv.data());
        ::_exit(kReaderExitNoExec);
    }
    ::close(fds[1]);

    // Closes our end (a child blocked on a full pipe then gets EPIPE) and reaps the child.
    struct Child {
        pid_t pid;
        int fd;
        int status = 0;
        bool reaped = false;
        int finish() {
            if (fd >= 0) ::close(fd), fd = -1;
            while (!reaped) {
                if (::waitpid(pid, &status, 0) == pid) reaped = true;
                else if (errno != EINTR) break;
            }
            return status;
        }
        ~Child() {
            if (!reaped && fd >= 0) ::kill(pid, SIGKILL);
            finish();
        }
    } child{pid, fds[0]};

    FdInBuf buf(child.fd);
    std::istream is(&buf);
    char magic[4] = {};
    is.read(magic, 4);
    const int kind = is ? is.get() : -1;
    auto crashed = [&](const std::string& detail) {
        const int status = child.finish();
        if (WIFEXITED(status) && WEXITSTATUS(status) == kReaderExitOutOfMemory)
            throw pqdc::resource_error(out_of_memory_message(path, budget));
        if (WIFEXITED(status) && WEXITSTATUS(status) == kReaderExitNoExec)
            throw pqdc::resource_error("cannot start the .vdb reader: exec of /proc/self/exe failed; is /proc mounted?");
        const bool signalled = WIFSIGNALED(status) && WTERMSIG(status) != SIGPIPE;
        if (signalled)
            throw pqdc::input_error("'" + path + "' is corrupt: OpenVDB's reader crashed on it (" +
                                    describe_wait_status(status) +
                                    "); re-export the file or check that the copy is complete");
        throw pqdc::input_error("reading '" + path + "' failed: the reader process ended (" +
                                describe_wait_status(status) + ")" + (detail.empty() ? "" : ": " + detail));
    };
    if (!is || std::memcmp(magic, kReplyMagic, 4) != 0 || kind < 0) crashed("");
    if (kind != int(Reply::grid)) {
        const std::string message = get_string(is);
        if (!is) crashed("");
        child.finish();
        if (kind == int(Reply::input_error)) throw pqdc::input_error(message);
        if (kind == int(Reply::resource_error)) throw pqdc::resource_error(message);
        throw pqdc::input_error(message);
    }
    pqdc::LoadedGrid out;
    out.chosen_automatically = is.get() == 1;
    for (auto* names : {&out.grid_names, &out.scalar_grid_names}) {
        const std::uint32_t n = get_u32(is);
        for (std::uint32_t i = 0; i < n && is; ++i) names->push_back(get_string(is));
    }
    std::string parse_error;
    try {
        openvdb::io::Stream stream(is, /*delayLoad=*/false);
        const openvdb::GridPtrVecPtr grids = stream.getGrids();
        if (grids && grids->size() == 1) out.grid = grids->front();
    } catch (const std::exception& e) {
        parse_error = e.what();
    }
    const int status = child.finish();
    if (!out.grid || !is || !WIFEXITED(status) || WEXITSTATUS(status) != 0) crashed(parse_error);
    return out;
}

// ------------------------------------------------------------------ output

/// The adaptive run's octree: what merged, what was refused and why, leaves per level.
std::string adaptive_json(const CliOptions& o, const pqdc::AdaptiveStats& a) {
    std::ostringstream j;
    j << "{\"max_cell_size_voxels\": " << o.max_cell_size_voxels << ", \"surface_leaves\": " << a.surface_leaves
      << ", \"empty_leaves\": " << a.empty_leaves << ", \"merges\": " << a.merges
      << ",\n    \"refused\": {\"error\": " << a.refused_error << ", \"topology\": " << a.refused_topology
      << ", \"containment\": " << a.refused_containment << ", \"balance\": " << a.refused_balance << "}"
      << ",\n    \"surface_leaves_by_size_voxels\": {";
    bool first = true;
    for (std::size_t level = 0; level < a.leaves_per_level.size(); ++level) {
        if (!a.leaves_per_level[level]) continue;
        j << (first ? "" : ", ") << "\"" << (1u << level) << "\": " << a.leaves_per_level[level];
        first = false;
    }
    j << "},\n    \"dual_cells\": " << a.dual_cells << ", \"collapsed_vertices\": " << a.collapsed_vertices
      << ", \"added_vertices\": " << a.added_vertices << ", \"separated_vertices\": " << a.separated_vertices
      << ",\n    \"seconds\": {\"hermite\": " << json_number(a.seconds_hermite) << ", \"octree\": "
      << json_number(a.seconds_octree) << ", \"dual\": " << json_number(a.seconds_dual)
      << ", \"polygons\": " << json_number(a.seconds_polygons) << "}}";
    return j.str();
}

std::string stats_json(const CliOptions& o, const std::string& source, const pqdc::ExtractStats& s,
                       const pqdc::AdaptiveStats* adaptive) {
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
      << "  \"source\": " << json_string(source) << ",\n"
      << "  \"output\": " << json_string(o.output) << ",\n"
      << "  \"sigma_n\": " << num(o.extract.sigma_n) << ",\n"
      << "  \"mode\": \"" << (o.adaptive ? "adaptive" : "uniform") << "\",\n"
      << "  \"max_error_voxels\": " << (o.adaptive ? num(o.max_error_voxels) : std::string("null")) << ",\n"
      << "  \"isovalue\": " << num(o.extract.isovalue) << ",\n"
      << "  \"containment\": \"" << (o.extract.containment == pqdc::Containment::clamp_to_cell ? "clamp" : "none") << "\",\n"
      << "  \"normals\": \"" << (o.extract.normals == pqdc::GridNormals::sharp ? "sharp" : "central") << "\",\n"
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
      << ", \"faces\": " << num(s.seconds_faces) << ", \"total\": " << num(s.seconds_total) << "}";
    if (adaptive) j << ",\n  \"adaptive\": " << adaptive_json(o, *adaptive);
    j << "\n}\n";
    return j.str();
}

void write_text_atomically(const std::string& path, const std::string& text) {
    const std::string tmp = path + ".tmp-" + std::to_string(::getpid());
    auto fail = [&](const std::string& why) {
        std::remove(tmp.c_str());
        throw pqdc::io_error("cannot write '" + path + "': " + why +
                             " (check that the directory exists, is writable and has free space)");
    };
    {
        std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
        if (!f) fail(std::strerror(errno));
        f << text;
        f.flush();
        if (!f) fail("write failed");
        f.close();
        if (!f) fail("closing failed");
    }
    if (std::rename(tmp.c_str(), path.c_str()) != 0) fail(std::strerror(errno));
}

/// The last line of defence for "never a NaN vertex or a dangling index":
/// refuse to write a mesh the library should never have produced.
void check_mesh_sane(const pqdc::Mesh& mesh) {
    std::size_t bad_points = 0, bad_faces = 0;
    for (const auto& p : mesh.points)
        if (!std::isfinite(p.x()) || !std::isfinite(p.y()) || !std::isfinite(p.z())) ++bad_points;
    const std::size_t n = mesh.points.size();
    for (const auto& t : mesh.triangles)
        if (t[0] >= n || t[1] >= n || t[2] >= n) ++bad_faces;
    for (const auto& q : mesh.quads)
        if (q[0] >= n || q[1] >= n || q[2] >= n || q[3] >= n) ++bad_faces;
    if (bad_points || bad_faces)
        throw std::logic_error("internal error: the mesh has " + std::to_string(bad_points) +
                               " non-finite vertices and " + std::to_string(bad_faces) +
                               " faces with out-of-range indices; nothing was written. Please report this "
                               "with the input and options");
}

/// Why a grid gave no surface, in terms the user can act on.
template <class GridT>
std::string explain_empty(const GridT& grid, const pqdc::ExtractOptions& eo, const pqdc::ExtractStats& stats) {
    double lo = INFINITY, hi = -INFINITY;
    std::uint64_t active = 0;
    for (auto it = grid.cbeginValueOn(); it; ++it) {
        ++active;
        const double v = double(*it);
        if (std::isfinite(v)) lo = std::min(lo, v), hi = std::max(hi, v);
    }
    std::ostringstream s;
    s << "warning: no surface in grid '" << grid.getName() << "'; ";
    if (active == 0) {
        s << "it has no active voxels or tiles (an empty grid); the output mesh is empty";
    } else if (!(lo <= hi)) {
        s << "all its active values are NaN or infinite; the output mesh is empty";
    } else if (eo.isovalue < lo || eo.isovalue > hi) {
        s << "its active values lie in [" << lo << ", " << hi << "] and the isovalue " << eo.isovalue
          << " is outside that range; choose --isovalue inside it (the output mesh is empty)";
    } else {
        s << "its active values [" << lo << ", " << hi << "] never change sign across the isovalue "
          << eo.isovalue << " between neighbouring lattice points";
        if (stats.non_finite_values) s << " that are finite (" << stats.non_finite_values << " NaN/Inf voxels)";
        s << "; the output mesh is empty";
    }
    return s.str();
}

/// The library says "raise the memory limit"; the CLI says how.
template <class F>
pqdc::Mesh with_memory_hint(const F& extract) {
    try {
        return extract();
    } catch (const pqdc::resource_error& e) {
        throw pqdc::resource_error(e.what() + std::string(" (pqdc --memory-limit MIB)"));
    }
}

std::unique_ptr<pqdc::ScalarField> make_field(const CliOptions& o) {
    if (o.procedural == "figure3") return pqdc::make_figure3(o.figure3);
    return pqdc::make_procedural(o.procedural);
}

// ---------------------------------------------------------------- --decimate
// Decimation of the extracted mesh (issue 15). Its flags are taken out of
// argv before parse() sees them, so this block and its two calls (main,
// run) are the whole of the change to this CLI.
struct DecimateFlags {
    bool on = false;
    bool any_target = false;
    pqdc::DecimateOptions options;
};
DecimateFlags g_decimate;

void take_decimate_flags(int& argc, char** argv) {
    int out = 1;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        const bool valued = a == "--target-faces" || a == "--target-ratio" || a == "--max-distance";
        if (a == "--decimate") {
            g_decimate.on = true;
            continue;
        }
        if (!valued) {
            argv[out++] = argv[i];
            continue;
        }
        if (i + 1 >= argc) throw UsageError{a + " needs a value"};
        const std::string v = argv[++i];
        g_decimate.any_target = true;
        if (a == "--target-faces") {
            g_decimate.options.target_faces = std::size_t(parse_integer(a, v, 1, 2000000000L));
        } else if (a == "--target-ratio") {
            const double r = parse_finite(a, v);
            if (!(r > 0 && r <= 1)) throw UsageError{"--target-ratio must be in (0, 1], got " + v};
            g_decimate.options.target_ratio = r;
        } else {
            const double e = parse_finite(a, v);
            if (!(e > 0)) throw UsageError{"--max-distance is a distance in voxels, > 0, got " + v};
            g_decimate.options.max_distance_voxels = e;
        }
    }
    argc = out;
    argv[argc] = nullptr;
    if (g_decimate.any_target && !g_decimate.on)
        throw UsageError{"--target-faces, --target-ratio and --max-distance apply to --decimate only"};
    if (g_decimate.on && !g_decimate.any_target)
        throw UsageError{"--decimate needs a target: --target-faces N, --target-ratio R or --max-distance E"};
}

/// Decimates with lengths in the extraction's voxels; returns the log line.
std::string decimate_for_output(pqdc::Mesh& mesh, const CliOptions& o, const pqdc::LoadedGrid& loaded) {
    pqdc::DecimateOptions d = g_decimate.options;
    if (o.procedural.empty()) {
        d.voxel_size = loaded.grid->voxelSize()[0];
    } else {  // the lattice of sample_field: longest side of bounds() / resolution
        const openvdb::Vec3d e = make_field(o)->bounds().extents();
        d.voxel_size = std::max({e[0], e[1], e[2]}) / o.sampling.resolution;
    }
    d.threads = o.threads;
    pqdc::DecimateStats s;
    pqdc::decimate(mesh, d, &s);
    std::ostringstream line;
    line << "decimated " << s.input_faces << " -> " << s.output_faces << " triangles (" << s.collapses
         << " collapses) in " << s.seconds << " s";
    return line.str();
}

int run(const CliOptions& o) {
    // Fail before the (possibly long) work if a result could not be written.
    if (!o.output.empty()) check_output_path("-o", o.output);
    if (!o.stats_path.empty()) check_output_path("--stats", o.stats_path);
    if (!o.write_volume.empty()) check_output_path("--write-volume", o.write_volume);

    // Read first, so a bad file fails before any work and before TBB starts threads.
    pqdc::LoadedGrid loaded;
    if (!o.input.empty()) loaded = read_grid_isolated(o.input, o.grid, o.extract.memory_limit_bytes);

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
        if (!o.quiet) std::cerr << (show_progress && last_percent >= 0 ? "\n" : "") << "pqdc: " << line << "\n";
        last_percent = -1;
    };

    pqdc::ExtractStats stats;
    std::optional<pqdc::AdaptiveStats> adaptive_stats;
    // Adaptive runs report through the same summary, log line and --stats
    // (plus their octree's figures).
    auto adaptive = [&](const auto& input) {
        pqdc::AdaptiveOptions ao;
        ao.base = eo;
        ao.max_error_voxels = o.max_error_voxels;
        ao.max_cell_size_voxels = o.max_cell_size_voxels;
        pqdc::AdaptiveStats as;
        pqdc::Mesh m;
        if constexpr (std::is_base_of_v<pqdc::ScalarField, std::decay_t<decltype(input)>>)
            m = pqdc::extract_adaptive(input, o.sampling, ao, &as);
        else
            m = pqdc::extract_adaptive(input, ao, &as);
        stats.active_cells = as.surface_cells;
        stats.crossing_edges = as.crossing_edges;
        stats.degenerate_normals = as.degenerate_normals;
        stats.clamped_vertices = as.clamped_vertices;
        stats.fallback_vertices = as.fallback_vertices;
        stats.vertices = as.vertices;
        stats.triangles = as.triangles;
        stats.quads = as.quads;
        stats.seconds_classify = as.seconds_hermite;
        stats.seconds_vertices = as.seconds_octree;
        stats.seconds_faces = as.seconds_dual + as.seconds_polygons;
        stats.seconds_total = as.seconds_total;
        adaptive_stats = as;
        return m;
    };
    pqdc::Mesh mesh;
    std::string source;
    std::string empty_reason;
    if (!o.procedural.empty()) {
        const auto field = make_field(o);
        source = "procedural " + o.procedural + " at resolution " + std::to_string(o.sampling.resolution);
        if (!o.write_volume.empty()) {
            const openvdb::FloatGrid::Ptr grid = pqdc::sample_field(*field, o.sampling);
            write_deferring_signals(o.write_volume, [&] { pqdc::write_grid(*grid, o.write_volume); });
            log("wrote the sampled level set of " + source + " to '" + o.write_volume + "'");
        }
        if (o.output.empty()) return 0;
        mesh = with_memory_hint([&] { return o.adaptive ? adaptive(*field) : pqdc::extract(*field, o.sampling, eo, &stats); });
        if (mesh.empty()) empty_reason = "warning: no surface found in the procedural field; the output mesh is empty";
    } else {
        const openvdb::GridBase& g = *loaded.grid;
        source = o.input + ":" + g.getName();
        std::ostringstream voxel;
        voxel << g.voxelSize()[0];
        if (loaded.chosen_automatically && loaded.scalar_grid_names.size() > 1) {
            std::string names;
            for (const auto& n : loaded.scalar_grid_names) names += (names.empty() ? "'" : ", '") + n + "'";
            log("'" + o.input + "' has several scalar grids (" + names + "); using '" + g.getName() +
                "' (choose with --grid NAME)");
        } else {
            log("using grid '" + g.getName() + "' (" + g.valueType() + ", " +
                (g.getGridClass() == openvdb::GRID_FOG_VOLUME ? "fog volume" :
                 g.getGridClass() == openvdb::GRID_LEVEL_SET ? "level set" : "unknown class") +
                ", voxel size " + voxel.str() + ") from '" + o.input + "'");
        }
        try {
            mesh = with_memory_hint([&] { return o.adaptive ? adaptive(g) : pqdc::extract(g, eo, &stats); });
        } catch (const pqdc::input_error& e) {
            throw pqdc::input_error("'" + o.input + "': " + e.what());
        } catch (const pqdc::error&) {
            throw;
        } catch (const std::bad_alloc&) {
            throw;
        } catch (const std::exception& e) {
            // Not one of pqdc's own errors: say where it happened.
            throw std::runtime_error("meshing grid '" + g.getName() + "' of '" + o.input + "' failed: " + e.what());
        }
        if (mesh.empty()) {
            if (const auto* f = dynamic_cast<const openvdb::FloatGrid*>(&g)) empty_reason = explain_empty(*f, eo, stats);
            else if (const auto* d = dynamic_cast<const openvdb::DoubleGrid*>(&g)) empty_reason = explain_empty(*d, eo, stats);
        }
    }
    if (g_signal.load()) throw pqdc::cancelled_error("interrupted");
    if (!empty_reason.empty()) log(empty_reason);
    check_mesh_sane(mesh);
    if (g_decimate.on && !mesh.empty())
        log(decimate_for_output(mesh, o, loaded));

    write_deferring_signals(o.output, [&] { pqdc::write_mesh(mesh, o.output); });
    if (!o.stats_path.empty())
        write_deferring_signals(o.stats_path, [&] { write_text_atomically(o.stats_path, stats_json(o, source, stats, adaptive_stats ? &*adaptive_stats : nullptr)); });
    std::ostringstream line;
    line << stats.active_cells << " active cells -> " << stats.vertices << " vertices, "
         << (stats.triangles + stats.quads)
         << (o.extract.faces == pqdc::FaceType::triangles ? " triangles" : " quads") << " in "
         << stats.seconds_total << " s";
    if (stats.clamped_vertices) line << ", " << stats.clamped_vertices << " clamped";
    if (stats.fallback_vertices) line << ", " << stats.fallback_vertices << " fallbacks";
    if (stats.degenerate_normals) line << ", " << stats.degenerate_normals << " zero-gradient crossings";
    if (stats.non_finite_values) line << ", " << stats.non_finite_values << " NaN/Inf voxels skipped";
    if (stats.boundary_crossings)
        line << ", open where the surface leaves the active region (" << stats.boundary_crossings << " crossings)";
    line << "; wrote '" << o.output << "'";
    log(line.str());
    return 0;
}

int interrupted_exit(int sig) { return 128 + (sig ? sig : SIGINT); }

/// The child of read_grid_isolated: pqdc --internal-vdb-reader FD PARENT BUDGET FROM_FILE_SIZE PATH GRID.
int reader_main(int argc, char** argv) {
    if (argc != 8) return 2;
    ReadBudget budget;
    budget.bytes = std::size_t(std::strtoull(argv[4], nullptr, 10));
    budget.from_file_size = std::strcmp(argv[5], "1") == 0;
    openvdb::initialize();
    reader_child(std::atoi(argv[2]), pid_t(std::atol(argv[3])), argv[6], argv[7], budget);
}

}  // namespace

int main(int argc, char** argv) {
    if (argc > 1 && std::strcmp(argv[1], kReaderArgument) == 0) return reader_main(argc, argv);
    install_signal_handlers();
    try {
        bool done = false;
        take_decimate_flags(argc, argv);
        const CliOptions o = parse(argc, argv, done);
        if (done) return 0;
        return run(o);
    } catch (const UsageError& e) {
        std::cerr << "pqdc: " << e.message << "\n";
        return 2;
    } catch (const Interrupted& e) {
        std::cerr << "\npqdc: interrupted after '" << e.written
                  << "' was written completely; nothing after it was written\n";
        return interrupted_exit(e.signal);
    } catch (const pqdc::cancelled_error&) {
        std::cerr << "\npqdc: interrupted; no output written\n";
        return interrupted_exit(g_signal.load());
    } catch (const pqdc::option_error& e) {
        std::cerr << "pqdc: " << e.what() << "\n";
        return 2;
    } catch (const pqdc::resource_error& e) {
        std::cerr << "pqdc: " << e.what() << "\n";
        return 1;
    } catch (const std::bad_alloc&) {
        std::cerr << "pqdc: out of memory; mesh a smaller region, a coarser grid, or use --memory-limit to fail early\n";
        return 1;
    } catch (const std::exception& e) {
        std::cerr << "pqdc: " << e.what() << "\n";
        return g_signal.load() ? interrupted_exit(g_signal.load()) : 1;
    }
}
