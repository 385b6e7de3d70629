// pqdc::extract versus openvdb::tools::volumeToMesh (adaptivity 0, the
// uniform dual-contouring peer) on the same grids, in one process:
//   sphere   openvdb::tools::createLevelSetSphere, radius 250 voxels, half width 3
//   figure3  the paper's Figure 3 field sampled with pqdc::sample_field at 512
//            cells; also the procedural path pqdc::extract(field, sampling)
//            (sampling + root finding on the exact field) and sample_field alone
//   mesh     a level set of a real mesh: fandisk.off (CGAL's demo data,
//            extracted at configure time) through pqdc::mesh_to_level_set
//            at 350 cells across, half width 3; volumes/fandisk.vdb (160 cells)
//            when the OFF is unavailable
//
// Times: every mesher runs --runs times on the same grid, back to back; "cold"
// is its first run (first-touch page faults of fresh allocations included),
// "best" the fastest of all runs. ratio = pqdc best / volumeToMesh best.
// "cpu s" is the least process CPU time (all threads) of the runs: on a
// shared, loaded machine it is steadier than wall time. Speed is reported,
// never asserted.
//
// Peak memory: each mesher runs once in a fresh process (this binary re-run
// with --memory-child) that builds the grid, calls malloc_trim(0), resets its
// peak RSS (writing 5 to /proc/self/clear_refs), reads VmRSS, runs the mesher
// and reads VmHWM. "peak MiB" = VmHWM - VmRSS before: the extra resident
// memory at the call's high-water mark, including the mesh it returns. It is
// page-granular and counts allocator slack, not bytes requested. When
// clear_refs is not writable the number is marked '~' (the baseline peak
// then includes the grid construction, so it can only be too low).
//
// Faces = triangles + quads, both also printed. volumeToMesh returns quads at
// adaptivity 0; pqdc returns two triangles per quad by default (choosing the
// diagonal costs time), so pqdc is also run with FaceType::quads, the
// like-for-like row. The pqdc-procedural ratio includes sampling the field
// and root finding on it, so it is not like-for-like; it shows the price of
// the exact path.
//
// Usage: bench_extract [--threads N] [--runs N] [--quick] [--csv]
//                      [--cases sphere,figure3,mesh] [--meshers LIST] [--no-memory] [--checksum]
//                      [--radius R] [--resolution N] [--mesh-cells N]
//                      [--vdb FILE] [--off FILE]
//   --threads N      TBB worker limit (tbb::global_control); default: all cores
//   --runs N         timed runs per mesher, >= 1; default 3
//   --quick          small sizes, one run (smoke test; numbers meaningless)
//   --csv            machine-readable rows only (-1 where a column does not apply)
//   --meshers LIST   only these rows: volumeToMesh, pqdc, pqdc-quads, pqdc-procedural,
//                    sample_field (ratios need volumeToMesh); default: all
//   --no-memory      skip the peak-memory child processes
//   --checksum       one extra untimed run per row printing an FNV-1a hash of the
//                    mesh arrays (pqdc must give the same hash for any --threads)
//   --radius R       sphere radius in voxels; default 250 (quick: 40)
//   --resolution N   figure3 lattice cells along the longest side; default 512 (quick: 64)
//   --mesh-cells N   mesh case: cells across the mesh's longest side; default 350 (quick: 64)
//   --vdb FILE       mesh case: a level-set .vdb to use instead of fandisk
//   --off FILE       mesh case: an OFF mesh to convert instead of fandisk.off
#include "pqdc/exceptions.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/mesh_io.hpp"
#include "pqdc/mesh_to_volume.hpp"
#include "pqdc/procedural.hpp"
#include "pqdc/volume_io.hpp"

#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <openvdb/tools/VolumeToMesh.h>
#include <tbb/global_control.h>

#include <malloc.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#ifndef PQDC_SOURCE_DIR  // set by bench/CMakeLists.txt
#define PQDC_SOURCE_DIR "."
#endif
#ifndef PQDC_BENCH_FANDISK_OFF  // extracted from libcgal-dev's data.tar.gz at configure time
#define PQDC_BENCH_FANDISK_OFF ""
#endif
#ifndef PQDC_BENCH_BUILD_TYPE
#define PQDC_BENCH_BUILD_TYPE "unknown"
#endif

namespace {

struct Options {
    int threads = 0;  // 0: TBB default
    int runs = 3;
    bool quick = false;
    bool csv = false;
    bool memory = true;
    bool checksum = false;
    std::vector<std::string> cases{"sphere", "figure3", "mesh"};
    std::vector<std::string> meshers;  // empty: all of the case's meshers
    double radius = 250;
    int resolution = 512;
    int mesh_cells = 350;
    std::string vdb, off;
    // --memory-child CASE MESHER
    std::string child_case, child_mesher;
};

[[noreturn]] void usage_error(const std::string& message) {
    std::fprintf(stderr, "bench_extract: %s\n(see the usage at the top of bench/bench_extract.cpp)\n",
                 message.c_str());
    std::exit(2);
}

int parse_int(const char* text, const char* option, int lo) {
    char* end = nullptr;
    const long v = std::strtol(text, &end, 10);
    if (!end || *end || v < lo || v > 1000000)
        usage_error(std::string(option) + " needs an integer in [" + std::to_string(lo) + ", 1000000], got '" + text +
                    "'");
    return int(v);
}

double parse_double(const char* text, const char* option) {
    char* end = nullptr;
    const double v = std::strtod(text, &end);
    if (!end || *end || !(v > 0) || !std::isfinite(v))
        usage_error(std::string(option) + " needs a positive number, got '" + text + "'");
    return v;
}

std::vector<std::string> split_commas(const std::string& s) {
    std::vector<std::string> out;
    std::stringstream in(s);
    for (std::string item; std::getline(in, item, ',');)
        if (!item.empty()) out.push_back(item);
    return out;
}

Options parse(int argc, char** argv) {
    Options o;
    bool radius_set = false, resolution_set = false, cells_set = false;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        auto value = [&]() -> const char* {
            if (i + 1 >= argc) usage_error(a + " needs a value");
            return argv[++i];
        };
        if (a == "--threads") o.threads = parse_int(value(), "--threads", 1);
        else if (a == "--runs") o.runs = parse_int(value(), "--runs", 1);
        else if (a == "--quick") o.quick = true;
        else if (a == "--csv") o.csv = true;
        else if (a == "--no-memory") o.memory = false;
        else if (a == "--checksum") o.checksum = true;
        else if (a == "--cases") o.cases = split_commas(value());
        else if (a == "--meshers") o.meshers = split_commas(value());
        else if (a == "--radius") o.radius = parse_double(value(), "--radius"), radius_set = true;
        else if (a == "--resolution") o.resolution = parse_int(value(), "--resolution", 4), resolution_set = true;
        else if (a == "--mesh-cells") o.mesh_cells = parse_int(value(), "--mesh-cells", 8), cells_set = true;
        else if (a == "--vdb") o.vdb = value();
        else if (a == "--off") o.off = value();
        else if (a == "--memory-child") {
            o.child_case = value();
            o.child_mesher = value();
        } else usage_error("unknown option '" + a + "'");
    }
    for (const auto& c : o.cases)
        if (c != "sphere" && c != "figure3" && c != "mesh")
            usage_error("unknown case '" + c + "' (sphere, figure3, mesh)");
    if (o.quick) {
        if (!radius_set) o.radius = 40;
        if (!resolution_set) o.resolution = 64;
        if (!cells_set) o.mesh_cells = 64;
        o.runs = 1;
    }
    return o;
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

/// CPU seconds of all threads of this process (user + system).
double process_cpu_seconds() {
    timespec t{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
}

bool file_exists(const std::string& path) { return !path.empty() && std::ifstream(path).good(); }

// ------------------------------------------------------------------ grids

struct Case {
    std::string name, description;
    openvdb::FloatGrid::Ptr grid;
    std::unique_ptr<pqdc::ScalarField> field;  // figure3 only
    pqdc::ProceduralSampling sampling;
    double build_seconds = 0;
};

std::string mesh_source(const Options& o, bool& is_vdb) {
    is_vdb = false;
    if (!o.vdb.empty()) return is_vdb = true, o.vdb;
    if (!o.off.empty()) return o.off;
    // volumes/fandisk.vdb has only 160 cells across (65k quads, too small to
    // time); the OFF gives the intended 350.
    if (file_exists(PQDC_BENCH_FANDISK_OFF)) return PQDC_BENCH_FANDISK_OFF;
    is_vdb = true;
    return std::string(PQDC_SOURCE_DIR) + "/volumes/fandisk.vdb";
}

/// Builds the grid of a case; empty grid when the case's input is unavailable.
Case make_case(const std::string& name, const Options& o) {
    Case c;
    c.name = name;
    const auto t0 = std::chrono::steady_clock::now();
    if (name == "sphere") {
        c.grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(float(o.radius), openvdb::Vec3f(0.f),
                                                                          /*voxelSize=*/1.f, /*halfWidth=*/3.f);
        c.description = "createLevelSetSphere radius " + std::to_string(int(o.radius)) + " voxels, half width 3";
    } else if (name == "figure3") {
        c.field = pqdc::make_figure3(pqdc::Figure3Params{});
        c.sampling.resolution = o.resolution;
        c.grid = pqdc::sample_field(*c.field, c.sampling);
        c.description = "figure3 (default params) sampled at " + std::to_string(o.resolution) + " cells";
    } else {
        bool is_vdb = false;
        const std::string src = mesh_source(o, is_vdb);
        if (is_vdb && file_exists(src)) {
            const pqdc::LoadedGrid loaded = pqdc::read_scalar_grid(src);
            c.grid = openvdb::gridPtrCast<openvdb::FloatGrid>(loaded.grid);
            if (!c.grid) throw pqdc::input_error("'" + src + "': the bench meshes float grids only");
            c.description = src;
        } else if (file_exists(src)) {
            const pqdc::Mesh mesh = pqdc::read_mesh(src);
            openvdb::BBoxd box;
            for (const auto& p : mesh.points) box.expand(p);
            pqdc::MeshToLevelSetOptions convert;
            convert.voxel_size = box.extents()[box.maxExtent()] / o.mesh_cells;
            c.grid = pqdc::mesh_to_level_set(mesh, convert);
            c.description = src + " -> mesh_to_level_set, " + std::to_string(o.mesh_cells) + " cells across, half width 3";
        }
    }
    c.build_seconds = seconds_since(t0);
    return c;
}

// ------------------------------------------------------------------ meshers

struct MeshCounts {
    std::uint64_t vertices = 0, triangles = 0, quads = 0;
    std::optional<pqdc::ExtractStats> stats;
    std::uint64_t checksum = 0;  // FNV-1a of the points and faces, when asked for
};

/// FNV-1a over the bytes of the arrays, in order.
template <class... Arrays>
std::uint64_t fnv1a(const Arrays&... arrays) {
    std::uint64_t h = 1469598103934665603ull;
    auto add = [&h](const auto& v) {
        const auto* p = reinterpret_cast<const unsigned char*>(v.data());
        for (std::size_t i = 0, n = v.size() * sizeof(v[0]); i < n; ++i) h = (h ^ p[i]) * 1099511628211ull;
    };
    (add(arrays), ...);
    return h;
}

const std::vector<std::string>& mesher_names(const std::string& case_name) {
    static const std::vector<std::string> grid_only{"volumeToMesh", "pqdc", "pqdc-quads"};
    static const std::vector<std::string> procedural{"volumeToMesh", "pqdc", "pqdc-quads", "pqdc-procedural",
                                                     "sample_field"};
    return case_name == "figure3" ? procedural : grid_only;
}

/// Runs one mesher once on the case; the result is dropped before returning
/// (its memory is part of the measured peak, not of later runs).
MeshCounts run_mesher(const Case& c, const std::string& mesher, bool checksum = false) {
    MeshCounts m;
    if (mesher == "volumeToMesh") {
        std::vector<openvdb::Vec3s> points;
        std::vector<openvdb::Vec3I> tris;
        std::vector<openvdb::Vec4I> quads;
        openvdb::tools::volumeToMesh(*c.grid, points, tris, quads, /*isovalue=*/0.0, /*adaptivity=*/0.0);
        m.vertices = points.size();
        m.triangles = tris.size();
        m.quads = quads.size();
        if (checksum) m.checksum = fnv1a(points, tris, quads);
        return m;
    }
    if (mesher == "sample_field") {
        const openvdb::FloatGrid::Ptr g = pqdc::sample_field(*c.field, c.sampling);
        m.vertices = g->activeVoxelCount();  // reported as "vertices": active lattice points
        return m;
    }
    pqdc::ExtractOptions options;
    if (mesher == "pqdc-quads") options.faces = pqdc::FaceType::quads;
    pqdc::ExtractStats stats;
    const pqdc::Mesh mesh = mesher == "pqdc-procedural" ? pqdc::extract(*c.field, c.sampling, options, &stats)
                                                        : pqdc::extract(*c.grid, options, &stats);
    m.vertices = mesh.points.size();
    m.triangles = mesh.triangles.size();
    m.quads = mesh.quads.size();
    m.stats = stats;
    if (checksum) m.checksum = fnv1a(mesh.points, mesh.triangles, mesh.quads);
    return m;
}

// ------------------------------------------------------------------ memory

long status_kib(const char* key) {
    std::ifstream in("/proc/self/status");
    for (std::string line; std::getline(in, line);)
        if (line.compare(0, std::strlen(key), key) == 0) return std::atol(line.c_str() + std::strlen(key) + 1);
    return -1;
}

int memory_child(const Options& o) {
    const Case c = make_case(o.child_case, o);
    if (!c.grid) return 3;
    malloc_trim(0);
    bool reset = false;
    {
        std::ofstream clear("/proc/self/clear_refs");
        reset = bool(clear << "5" << std::flush);
    }
    const long before = status_kib("VmRSS:");
    run_mesher(c, o.child_mesher);
    const long peak = status_kib("VmHWM:");
    std::printf("%ld %ld %d\n", before, peak, reset ? 1 : 0);
    return 0;
}

struct PeakMemory {
    double mib = -1;
    bool exact = false;
};

/// Re-runs this binary with --memory-child and parses its one-line answer.
PeakMemory measure_in_child(const Options& o, const std::string& case_name, const std::string& mesher) {
    std::vector<std::string> args{"/proc/self/exe", "--memory-child", case_name, mesher};
    auto add = [&](const std::string& k, const std::string& v) { args.push_back(k), args.push_back(v); };
    if (o.threads) add("--threads", std::to_string(o.threads));
    add("--radius", std::to_string(o.radius));
    add("--resolution", std::to_string(o.resolution));
    add("--mesh-cells", std::to_string(o.mesh_cells));
    if (!o.vdb.empty()) add("--vdb", o.vdb);
    if (!o.off.empty()) add("--off", o.off);
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);

    int fd[2];
    if (pipe(fd) != 0) return {};
    std::fflush(nullptr);
    const pid_t pid = fork();
    if (pid < 0) return {};
    if (pid == 0) {
        dup2(fd[1], STDOUT_FILENO);
        close(fd[0]);
        close(fd[1]);
        execv("/proc/self/exe", argv.data());
        _exit(127);
    }
    close(fd[1]);
    std::string out;
    char buf[256];
    for (ssize_t n; (n = read(fd[0], buf, sizeof buf)) > 0;) out.append(buf, std::size_t(n));
    close(fd[0]);
    int status = 0;
    waitpid(pid, &status, 0);
    long before = 0, peak = 0;
    int exact = 0;
    if (!WIFEXITED(status) || WEXITSTATUS(status) != 0 ||
        std::sscanf(out.c_str(), "%ld %ld %d", &before, &peak, &exact) != 3 || before < 0 || peak < 0)
        return {};
    return {double(peak - before) / 1024.0, exact == 1};
}

// ------------------------------------------------------------------ report

struct Row {
    std::string case_name, mesher;
    double cold = 0, best = 0, ratio = -1;
    double cpu = 0, cpu_ratio = -1;  // least CPU time of the runs
    MeshCounts counts;
    PeakMemory memory;
};

void print_header(const Options& o) {
    std::printf("bench_extract: pqdc::extract vs openvdb::tools::volumeToMesh (adaptivity 0, isovalue 0)\n");
    std::printf("build %s, OpenVDB %s, threads %s (hardware %u), runs %d%s\n", PQDC_BENCH_BUILD_TYPE,
                openvdb::getLibraryAbiVersionString(),
                o.threads ? std::to_string(o.threads).c_str() : "default", std::thread::hardware_concurrency(),
                o.runs, o.quick ? " (quick: numbers meaningless)" : "");
    std::printf("time: cold = first run, best = fastest of the runs; ratio = best / volumeToMesh best\n");
    std::printf("cpu s: least CPU time (all threads) of the runs, robust on a loaded machine; ratio vs volumeToMesh\n");
    std::printf("peak MiB: VmHWM - VmRSS around one call in a fresh child process (~ = peak not resettable)\n");
}

void print_row(const Options& o, const Row& r) {
    const std::uint64_t faces = r.counts.triangles + r.counts.quads;
    if (o.csv) {
        const auto& s = r.counts.stats;
        std::printf("%s,%s,%d,%d,%.6f,%.6f,%.4f,%.6f,%.4f,%llu,%llu,%llu,%llu,%.1f,%.6f,%.6f,%.6f,%016llx\n",
                    r.case_name.c_str(), r.mesher.c_str(), o.threads, o.runs, r.cold, r.best, r.ratio, r.cpu,
                    r.cpu_ratio, (unsigned long long)faces,
                    (unsigned long long)r.counts.triangles, (unsigned long long)r.counts.quads,
                    (unsigned long long)r.counts.vertices, r.memory.mib, s ? s->seconds("candidates") : -1.0,
                    s ? s->seconds("cells") + s->seconds("gather") : -1.0, s ? s->seconds("faces") : -1.0,
                    (unsigned long long)r.counts.checksum);
        return;
    }
    char ratio[16] = "", cpu_ratio[16] = "", mem[24] = "-";
    if (r.ratio >= 0) std::snprintf(ratio, sizeof ratio, "%.2f", r.ratio);
    if (r.cpu_ratio >= 0) std::snprintf(cpu_ratio, sizeof cpu_ratio, "%.2f", r.cpu_ratio);
    if (r.memory.mib >= 0) std::snprintf(mem, sizeof mem, "%s%.0f", r.memory.exact ? "" : "~", r.memory.mib);
    std::printf("  %-16s %8.3f %8.3f %6s %8.3f %6s %10llu %10llu %10llu %10llu %8s", r.mesher.c_str(), r.cold,
                r.best, ratio, r.cpu, cpu_ratio, (unsigned long long)faces, (unsigned long long)r.counts.triangles,
                (unsigned long long)r.counts.quads, (unsigned long long)r.counts.vertices, mem);
    if (const auto& s = r.counts.stats)
        for (const pqdc::StageTime& stage : s->stages) std::printf("   %s %.3f", stage.name.c_str(), stage.seconds);
    if (o.checksum) std::printf("   fnv %016llx", (unsigned long long)r.counts.checksum);
    std::printf("\n");
}

int run(const Options& o) {
    if (o.csv)
        std::printf("case,mesher,threads,runs,cold_s,best_s,ratio_vs_volumeToMesh,cpu_s,cpu_ratio,"
                    "faces,triangles,quads,vertices,"
                    "peak_mib,candidates_s,cells_s,faces_s,checksum\n");
    else
        print_header(o);
    for (const std::string& name : o.cases) {
        const Case c = make_case(name, o);
        if (!c.grid) {
            std::fprintf(stderr, "bench_extract: case '%s' skipped: no input (pass --vdb or --off)\n", name.c_str());
            continue;
        }
        if (!o.csv) {
            std::printf("\n[%s] %s\n  grid: %llu active voxels, %llu leaves, voxel %.4g, built in %.2f s\n",
                        name.c_str(), c.description.c_str(), (unsigned long long)c.grid->activeVoxelCount(),
                        (unsigned long long)c.grid->tree().leafCount(), c.grid->voxelSize()[0], c.build_seconds);
            std::printf("  %-16s %8s %8s %6s %8s %6s %10s %10s %10s %10s %8s\n", "mesher", "cold s", "best s",
                        "ratio", "cpu s", "ratio", "faces", "triangles", "quads", "vertices", "peak MiB");
        }
        double vdb_best = -1, vdb_cpu = -1;
        for (const std::string& mesher : mesher_names(name)) {
            if (!o.meshers.empty() && std::find(o.meshers.begin(), o.meshers.end(), mesher) == o.meshers.end())
                continue;
            Row r;
            r.case_name = name;
            r.mesher = mesher;
            r.best = r.cpu = std::numeric_limits<double>::infinity();
            for (int run = 0; run < o.runs; ++run) {
                const double cpu0 = process_cpu_seconds();
                const auto t0 = std::chrono::steady_clock::now();
                MeshCounts m = run_mesher(c, mesher);
                const double t = seconds_since(t0);
                r.cpu = std::min(r.cpu, process_cpu_seconds() - cpu0);
                if (run == 0) r.cold = t;
                if (t < r.best) {  // keep the stage times of the fastest run
                    r.best = t;
                    r.counts = m;
                }
            }
            if (mesher == "volumeToMesh") {
                vdb_best = r.best;
                vdb_cpu = r.cpu;
            } else if (mesher != "sample_field" && vdb_best > 0) {
                r.ratio = r.best / vdb_best;
                r.cpu_ratio = r.cpu / vdb_cpu;
            }
            if (o.checksum) r.counts.checksum = run_mesher(c, mesher, true).checksum;  // untimed extra run
            if (o.memory) r.memory = measure_in_child(o, name, mesher);
            print_row(o, r);
            std::fflush(stdout);
        }
    }
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    const Options o = parse(argc, argv);
    std::optional<tbb::global_control> limit;
    if (o.threads) limit.emplace(tbb::global_control::max_allowed_parallelism, std::size_t(o.threads));
    try {
        openvdb::initialize();
        return o.child_case.empty() ? run(o) : memory_child(o);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bench_extract: %s\n", e.what());
        return 1;
    }
}
