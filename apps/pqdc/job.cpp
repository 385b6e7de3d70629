#include "job.hpp"

#include "../progress.hpp"
#include "report.hpp"
#include "signals.hpp"

#include "../cli_util.hpp"

#include "pqdc/brick_store.hpp"
#include "pqdc/bricks.hpp"
#include "pqdc/exceptions.hpp"
#include "pqdc/file_io.hpp"
#include "pqdc/components.hpp"
#include "pqdc/mesh_stream.hpp"
#include "pqdc/distributed.hpp"
#include "pqdc/vertex_normals.hpp"
#include "pqdc/volume_io.hpp"

#include <openvdb/openvdb.h>
#include <tbb/global_control.h>

#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <functional>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>
#include <type_traits>

namespace pqdc_app {
namespace {

double seconds_since(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

/// The last line of defence for "never a NaN vertex or a dangling index".
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

/// The library's memory messages name its own options ("options.region",
/// "the memory limit"); the CLI names its flags. `could_stream`: an in-core
/// uniform run, which --out-of-core would write brick by brick.
std::string memory_hint_in_cli_names(std::string text, bool could_stream) {
    auto replace = [&text](const std::string& from, const std::string& to) {
        const std::size_t at = text.find(from);
        if (at == std::string::npos) return false;
        text.replace(at, from.size(), to);
        return true;
    };
    replace("(options.region: a box or a mask)", "(--bbox or --mask)");
    replace("smaller bricks need less: BrickOptions::brick_size", "smaller bricks need less: --brick-size, down to 128");
    const std::string stream = could_stream ? ", or add --out-of-core to write the mesh brick by brick" : "";
    if (replace("raise the memory limit", "raise --memory-limit MIB" + stream)) return text;
    return text + " (pqdc: --bbox or --mask for a region, --memory-limit MIB" + stream + ")";
}

template <class F>
auto with_memory_hint(const F& extract, bool could_stream = false) {
    try {
        return extract();
    } catch (const pqdc::resource_error& e) {
        throw pqdc::resource_error(memory_hint_in_cli_names(e.what(), could_stream));
    }
}

/// Standard input, copied into an anonymous in-memory file so the reader can
/// check sizes against offsets and seek as in a regular file.
std::string stdin_as_file(Progress& progress) {
    const int fd = ::memfd_create("pqdc-stdin", MFD_CLOEXEC);
    if (fd < 0) throw pqdc::resource_error(std::string("cannot buffer standard input: ") + std::strerror(errno));
    progress.stage("reading standard input");
    std::vector<char> buf(1 << 20);
    for (;;) {
        const ssize_t n = ::read(STDIN_FILENO, buf.data(), buf.size());
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) throw pqdc::input_error(std::string("cannot read standard input: ") + std::strerror(errno));
        if (n == 0) break;
        for (ssize_t done = 0; done < n;) {
            const ssize_t w = ::write(fd, buf.data() + done, std::size_t(n - done));
            if (w < 0 && errno == EINTR) continue;
            if (w <= 0) throw pqdc::resource_error(std::string("cannot buffer standard input: ") + std::strerror(errno));
            done += w;
        }
    }
    return "/proc/self/fd/" + std::to_string(fd);
}

/// "'a', 'b', 'c'": names for a message.
std::string quoted_list(const std::vector<std::string>& names) {
    std::string list;
    for (const auto& n : names) list += (list.empty() ? "'" : ", '") + n + "'";
    return list;
}

/// An error from reading `path` with the file called what the user called it.
[[noreturn]] void rethrow_named(const std::string& path, const std::string& display) {
    const std::string quoted = "'" + path + "'";
    auto rename = [&](std::string m) {
        if (display == quoted) return m;
        for (std::size_t at = m.find(quoted); at != std::string::npos; at = m.find(quoted, at + display.size()))
            m.replace(at, quoted.size(), display);
        return m;
    };
    try {
        throw;
    } catch (const pqdc::resource_error& e) {
        throw pqdc::resource_error(rename(e.what()));
    } catch (const pqdc::input_error& e) {
        throw pqdc::input_error(rename(e.what()));
    }
}

class Job {
public:
    /// `ranks`: the group of a pqdc-mpi run (null for pqdc); only its rank 0
    /// prints and writes.
    Job(const CliOptions& o, SupervisorLink& link, pqdc::RankGroup* ranks)
        : o_(o), link_(link), ranks_(ranks), root_(!ranks || ranks->rank() == 0),
          progress_(root_ && !o.quiet && (o.force_progress || ::isatty(STDERR_FILENO)), ranks ? "pqdc-mpi" : "pqdc") {}

    int run() {
        if (!o_.output.empty()) pqdc_cli::check_output_path("-o", pqdc_app::expand_grid_pattern(o_.output, "g"));
        if (!o_.stats_path.empty()) pqdc_cli::check_output_path("--stats", pqdc_app::expand_grid_pattern(o_.stats_path, "g"));
        if (!o_.write_volume.empty()) pqdc_cli::check_output_path("--write-volume", o_.write_volume);
        if (!o_.mask_path.empty()) load_mask();
        if (!o_.procedural.empty()) return run_procedural();
        return run_volume();
    }

private:
    pqdc::ExtractOptions extract_options() {
        pqdc::ExtractOptions eo = o_.extract;
        eo.region.mask = mask_;
        eo.region.invert_mask = o_.invert_mask && mask_;
        eo.stored_precision = stored_precision();
        // --decimate moves the vertices: their normals are computed after it instead.
        eo.vertex_normals = o_.vertex_normals && !o_.decimate;
        eo.min_component_voxels = o_.min_component_voxels;
        eo.progress = [this](double f) {
            if (pending_signal()) return false;
            progress_.set(f);
            return true;
        };
        return eo;
    }

    /// What the writer will store (pqdc::stored_vertex_precision).
    pqdc::VertexPrecision stored_precision() const {
        std::optional<pqdc::MeshFormat> format = o_.format;
        if (!format && !o_.output.empty() && o_.output != "-") {
            try {
                format = pqdc::mesh_format_from_path(o_.output);
            } catch (const pqdc::error&) {  // the writer reports it
            }
        }
        return format ? pqdc::stored_vertex_precision(*format, o_.precision) : o_.precision;
    }

    void log(const std::string& line) { progress_.log(line, o_.quiet || !root_); }

    /// `bricks`: mesh brick by brick (--out-of-core, or a delay-loaded grid).
    /// `values_done`: an in-core uniform run of a grid calls it once it has
    /// read the grid for the last time (ExtractOptions::values_done).
    template <class Input>
    pqdc::Mesh extract(const Input& input, MeshReport& report, bool bricks = false,
                       const std::function<void()>& values_done = {}) {
        const pqdc::ExtractOptions eo = extract_options();
        if (!o_.adaptive) {
            if constexpr (std::is_base_of_v<pqdc::ScalarField, Input>) {
                if (ranks_) return pqdc::extract_distributed(input, o_.sampling, eo, o_.bricks, *ranks_, &report.stats);
                if (bricks) return pqdc::extract_bricks(input, o_.sampling, eo, o_.bricks, &report.stats);
                return pqdc::extract(input, o_.sampling, eo, &report.stats);
            } else {
                if (ranks_) return pqdc::extract_distributed(input, eo, o_.bricks, *ranks_, &report.stats);
                if (bricks) return pqdc::extract_bricks(input, eo, o_.bricks, &report.stats);
                pqdc::ExtractOptions in_core = eo;
                in_core.values_done = values_done;
                return pqdc::extract(input, in_core, &report.stats);
            }
        }
        pqdc::AdaptiveOptions ao;
        ao.base = eo;
        ao.max_error_voxels = o_.max_error_voxels;
        ao.max_cell_size_voxels = o_.max_cell_size_voxels;
        pqdc::AdaptiveStats as;
        pqdc::Mesh m;
        if constexpr (std::is_base_of_v<pqdc::ScalarField, Input>) {
            if (ranks_) m = pqdc::extract_adaptive_distributed(input, o_.sampling, ao, o_.bricks, *ranks_, &as);
            else if (bricks) m = pqdc::extract_adaptive_bricks(input, o_.sampling, ao, o_.bricks, &as);
            else m = pqdc::extract_adaptive(input, o_.sampling, ao, &as);
        } else {
            if (ranks_) m = pqdc::extract_adaptive_distributed(input, ao, o_.bricks, *ranks_, &as);
            else if (bricks) m = pqdc::extract_adaptive_bricks(input, ao, o_.bricks, &as);
            else m = pqdc::extract_adaptive(input, ao, &as);
        }
        report.stats = as;  // the shared record; the octree's figures go to --stats too
        report.adaptive = as;
        return m;
    }

    /// What --min-component removed (the extraction did it).
    void log_islands(const pqdc::ExtractStats& stats) {
        if (!(o_.min_component_voxels > 0) || stats.components.components == 0) return;
        const pqdc::ComponentFilterStats& s = stats.components;
        std::ostringstream line;
        line << "removed " << s.removed_components << " of " << s.components << " components smaller than "
             << o_.min_component_voxels << " voxels (" << s.removed_faces << " faces)";
        log(line.str());
    }

    /// --decimate, with lengths in the extraction's voxels; its figures go
    /// into the report.
    void decimate(pqdc::Mesh& mesh, double voxel_size, MeshReport& report) {
        if (!o_.decimate || mesh.empty()) return;
        pqdc::DecimateOptions d = o_.decimation;
        d.voxel_size = voxel_size;
        d.stored_precision = stored_precision();  // checked as the file will hold it
        d.threads = o_.threads;
        d.memory_limit_bytes = o_.extract.memory_limit_bytes;  // --memory-limit, as for the extraction
        d.progress = [this](double f) {
            if (pending_signal()) return false;  // Ctrl-C: exit 130 between passes and their stages
            progress_.set(f);
            return true;
        };
        pqdc::DecimateStats s;
        progress_.stage("decimating");
        with_memory_hint([&] {  // its memory refusal names the options too
            pqdc::decimate(mesh, d, &s);
            return 0;
        });
        report.decimation = s;
        std::ostringstream line;
        line << "decimated " << s.input_faces << " -> " << s.output_faces << " triangles (" << s.collapses
             << " collapses, sigma " << s.sigma_position_voxels << " voxel) in " << s.seconds << " s";
        log(line.str());
        if (const std::string w = pqdc_cli::decimation_short_of_target(s, d); !w.empty())
            report.stats.warnings.push_back(w);  // printed and in --stats with the extraction's
    }

    pqdc::MeshWriteOptions write_options() {
        pqdc::MeshWriteOptions wo;
        wo.format = o_.format;
        wo.precision = o_.precision;
        wo.progress = [this](double f) { progress_.set(f); };
        return wo;
    }

    void write(const pqdc::Mesh& mesh, MeshReport& report) {
        if (pending_signal()) throw pqdc::cancelled_error("interrupted");
        if (!root_) return;  // the other ranks' meshes are empty: rank 0 holds the whole
        check_mesh_sane(mesh);
        write_and_report(report, [&] { pqdc::write_mesh(mesh, report.output, write_options()); });
    }

    /// write_file() (which writes report.output) timed and with signals
    /// deferred, then the --stats file and the summary.
    template <class WriteFile>
    void write_and_report(MeshReport& report, const WriteFile& write_file) {
        progress_.stage(report.output == "-" ? "writing to standard output" : "writing '" + report.output + "'");
        const auto start = std::chrono::steady_clock::now();
        write_deferring_signals(report.output, write_file);
        report.write_seconds = seconds_since(start);
        if (!o_.stats_path.empty()) {
            const std::string path = expand_grid_pattern(o_.stats_path, report.grid);
            write_deferring_signals(path, [&] { pqdc::write_file(path, stats_json(o_, report)); });
        }
        log(summary_line(o_, report));
        for (const std::string& w : report.stats.warnings) log("warning: " + w);
    }

    int run_procedural() {
        const std::unique_ptr<pqdc::ScalarField> field =
            o_.procedural == "figure3" ? pqdc::make_figure3(o_.figure3) : pqdc::make_procedural(o_.procedural);
        MeshReport report;
        report.source = "procedural " + o_.procedural + " at resolution " + std::to_string(o_.sampling.resolution);
        if (!o_.write_volume.empty() && root_) {
            progress_.stage("sampling " + report.source);
            // What the mesh is made from: within --memory-limit, and only
            // around --bbox or --mask's region when one is given.
            const openvdb::FloatGrid::Ptr grid = with_memory_hint(
                [&] { return pqdc::sample_field_within_limits(*field, o_.sampling, extract_options()); });
            write_deferring_signals(o_.write_volume, [&] { pqdc::write_grid(*grid, o_.write_volume); });
            log("wrote the sampled level set of " + report.source + " to '" + o_.write_volume + "'");
        }
        if (o_.output.empty()) return 0;
        progress_.stage("meshing " + report.source);
        pqdc::Mesh mesh = with_memory_hint([&] { return extract(*field, report, o_.out_of_core); });
        log_islands(report.stats);
        decimate(mesh, pqdc::procedural_transform(*field, o_.sampling)->voxelSize()[0], report);
        if (o_.vertex_normals && o_.decimate) pqdc::compute_outward_vertex_normals(mesh, *field);
        report.output = o_.output;
        write(mesh, report);
        return 0;
    }

    /// --mask, read once under the same sandbox as the input.
    void load_mask() {
        pqdc_cli::start_openvdb();
        const std::string display = "'" + o_.mask_path + "' (--mask)";
        mask_ = read(o_.mask_path, display, o_.mask_grid, /*for_mask=*/true).grid;
        log("mask: grid '" + mask_->getName() + "' (" + mask_->valueType() + ", " +
            (mask_->getGridClass() == openvdb::GRID_LEVEL_SET ? "level set: its inside"
                                                              : "its active voxels") +
            (o_.invert_mask ? ", inverted" : "") + ") from " + display);
    }

    pqdc::LoadedGrid read(const std::string& path, const std::string& display, const std::string& grid,
                          bool for_mask = false) {
        if (!for_mask && pqdc::is_brick_store(path)) return read_store(path, grid);
        struct stat st {};
        progress_.reading("reading " + display, path, ::stat(path.c_str(), &st) == 0 ? std::uint64_t(st.st_size) : 1);
        // Out of core when asked, or when the grid would not fit in the memory
        // limit. A delayed read, and the parallel decoding of a whole one, map
        // the file: its size joins the reader's budget.
        const pqdc::VolumeLoading loading =
            o_.out_of_core ? pqdc::VolumeLoading::delayed : pqdc::VolumeLoading::delayed_if_larger;
        const std::size_t limit = o_.extract.memory_limit_bytes;
        try {
            ReaderSandbox sandbox(link_, path, display, limit && loading != pqdc::VolumeLoading::whole
                                                            ? limit + std::size_t(st.st_size) : limit);
            try {
                return for_mask ? pqdc::read_mask_grid(path, grid)
                                : pqdc::read_scalar_grid(path, grid, loading, pqdc::effective_memory_limit(o_.extract),
                                                         pqdc::LeafDecoding::parallel);
            } catch (const std::bad_alloc&) {
                throw pqdc::resource_error(sandbox.out_of_memory_message());
            } catch (const pqdc::resource_error&) {
                throw pqdc::resource_error(sandbox.out_of_memory_message());
            }
        } catch (const pqdc::error&) {
            rethrow_named(path, display);
        }
    }

    /// A brick store directory (pqdc-bricks split): its grid, buffers left in
    /// the brick files. Not under the reader sandbox, whose budget is for one
    /// file: the brick files are mapped, one each.
    pqdc::LoadedGrid read_store(const std::string& path, const std::string& grid) {
        progress_.stage("reading the brick store '" + path + "'");
        pqdc::LoadedGrid store = pqdc::read_brick_store(path);
        check_store_grid(path, store.grid->getName(), grid);
        return store;
    }

    static void check_store_grid(const std::string& path, const std::string& holds, const std::string& asked) {
        if (!asked.empty() && asked != "*" && asked != holds)
            throw pqdc::input_error("the brick store '" + path + "' holds grid '" + holds + "', not '" + asked +
                                    "' (a store holds one grid: drop --grid, or split the file's grid '" + asked +
                                    "' into a store of its own with pqdc-bricks split --grid)");
    }

    /// A brick store meshed by the streamed run, which opens its brick files
    /// one at a time and never assembles its topology (pqdc::BrickStore).
    int run_store(const std::string& path) {
        progress_.stage("opening the brick store '" + path + "'");
        const auto start = std::chrono::steady_clock::now();
        const pqdc::BrickStore store(path);
        const double read_seconds = seconds_since(start);
        const std::vector<std::string> names = o_.grids.empty() ? std::vector<std::string>{""} : o_.grids;
        for (const std::string& name : names) check_store_grid(path, store.shell().getName(), name);
        for (std::size_t i = 0; i < names.size(); ++i)
            mesh_grid(store.shell(), "'" + path + "'", path, true, i == 0 ? read_seconds : 0.0, &store);
        return 0;
    }

    int run_volume() {
        pqdc_cli::start_openvdb();
        const bool from_stdin = o_.input == "-";
        const std::string path = from_stdin ? stdin_as_file(progress_) : o_.input;
        const std::string display = from_stdin ? std::string("standard input") : "'" + o_.input + "'";
        if (!from_stdin && pqdc::is_brick_store(path) && streamed(true)) return run_store(path);
        // One name is read at once; a list (which may be one name with
        // commas) once the file's grids are known.
        const std::string first_request = o_.grids.size() == 1 && o_.grids[0] != "*" ? o_.grids[0] : "";
        auto start = std::chrono::steady_clock::now();
        pqdc::LoadedGrid first = read(path, display, first_request);
        double read_seconds = seconds_since(start);
        std::vector<std::string> names;
        if (o_.grids.empty()) names = {first.grid->getName()};
        else if (o_.grids[0] == "*") names = first.scalar_grid_names;
        else if (o_.grids.size() > 1 && listed(first.grid_names, o_.grid_text)) names = {o_.grid_text};
        else names = o_.grids;
        if (first.chosen_automatically && first.scalar_grid_names.size() > 1 && o_.grids.empty()) {
            log(display + " has several scalar grids (" + quoted_list(first.scalar_grid_names) + "); using '" + names[0] +
                "' (choose with --grid NAME, or --grid '*' for all)");
        }
        if (!o_.grids.empty() && o_.grids[0] == "*") log_skipped_grids(first, display);
        check_one_file_per_grid(names);
        check_listed_grids(first, names, display);
        const std::string source_name = from_stdin ? std::string("-") : o_.input;
        // The grid read first is meshed first when it is the first asked for.
        const bool first_is_used = first.grid->getName() == names[0];
        if (!first_is_used) first.grid.reset();
        for (std::size_t i = 0; i < names.size(); ++i) {
            const bool reuse = i == 0 && first_is_used;
            if (!reuse) start = std::chrono::steady_clock::now();
            pqdc::LoadedGrid loaded = reuse ? std::move(first) : read(path, display, names[i]);
            if (!reuse) read_seconds = seconds_since(start);
            const openvdb::GridBase::Ptr grid = std::move(loaded.grid);
            try {
                mesh_grid(*grid, display, source_name, loaded.delay_loaded, read_seconds, nullptr, grid.get());
            } catch (const Interrupted&) {
                throw;  // says itself which file was the last written
            } catch (const pqdc::cancelled_error&) {
                throw;
            } catch (...) {
                report_batch_state(names, i);
                throw;
            }
        }
        return 0;
    }

    /// Before the error of grid `failed` of a several-grid run: which grids'
    /// files were written whole and stay, and which grids were not meshed.
    void report_batch_state(const std::vector<std::string>& names, std::size_t failed) {
        if (names.size() < 2 || !root_) return;
        std::vector<std::string> written, not_meshed(names.begin() + std::ptrdiff_t(failed) + 1, names.end());
        for (std::size_t i = 0; i < failed; ++i) written.push_back(expand_grid_pattern(o_.output, names[i]));
        // Printed with -q too: it belongs to the error that follows.
        progress_.log("grid '" + names[failed] + "' failed (" + std::to_string(failed + 1) + " of " +
                          std::to_string(names.size()) + "); " +
                          (written.empty() ? std::string("no file was written")
                                           : "the files of the grids before it are complete and stay: " +
                                                 quoted_list(written)) +
                          (not_meshed.empty() ? std::string() : "; not meshed: " + quoted_list(not_meshed)),
                      false);
    }

    static bool listed(const std::vector<std::string>& v, const std::string& name) {
        return std::find(v.begin(), v.end(), name) != v.end();
    }

    /// --grid '*' meshes the scalar grids; it says which others it leaves.
    void log_skipped_grids(const pqdc::LoadedGrid& first, const std::string& display) {
        std::vector<std::string> skipped;
        for (const std::string& name : first.grid_names)
            if (!listed(first.scalar_grid_names, name)) skipped.push_back(name);
        if (!skipped.empty())
            log("--grid '*': skipping " + quoted_list(skipped) + " in " + display +
                " (not float or double grids, which are what pqdc meshes)");
    }

    /// Every grid that --grid lists is in the file and can be meshed: known
    /// from the first read, so a bad name stops the run before any grid's
    /// files are written (a batch job does not get half its outputs).
    static void check_listed_grids(const pqdc::LoadedGrid& first, const std::vector<std::string>& names,
                                   const std::string& display) {
        for (const std::string& name : names) {
            const auto same = std::count(first.grid_names.begin(), first.grid_names.end(), name);
            if (same > 1)
                throw pqdc::input_error(display + " has " + std::to_string(same) + " grids named '" + name +
                                        "'; pqdc reads grids by name and cannot tell them apart: rename them (or "
                                        "mesh another grid with --grid NAME); nothing was meshed");
            if (listed(first.scalar_grid_names, name)) continue;
            if (!listed(first.grid_names, name))
                throw pqdc::input_error(display + " has no grid named '" + name + "'; its grids are " +
                                        quoted_list(first.grid_names) + " (choose with --grid); nothing was meshed");
            throw pqdc::input_error("grid '" + name + "' in " + display +
                                    " is not a float or double grid; pqdc can mesh " +
                                    (first.scalar_grid_names.empty() ? std::string("none of this file's grids")
                                                                     : quoted_list(first.scalar_grid_names)) +
                                    "; nothing was meshed");
        }
    }

    /// Several grids: each must get files of its own (a {grid} pattern can
    /// give two names one file, "a/b" and "a_b"). Two grids of one name
    /// (--grid '*') are refused by check_listed_grids. Each grid's own paths
    /// are checked as the pattern's were at the start (a grid named "." or
    /// ".." makes "{grid}" a directory).
    void check_one_file_per_grid(const std::vector<std::string>& names) const {
        if (names.size() > 1) check_one_mesh_per_file(o_);
        for (const std::string& name : names)
            for (const auto& [option, pattern] : {std::pair{"-o", o_.output}, std::pair{"--stats", o_.stats_path}})
                if (!pattern.empty() && pattern != "-") pqdc_cli::check_output_path(option, expand_grid_pattern(pattern, name));
        for (std::size_t i = 0; i < names.size(); ++i)
            for (std::size_t j = i + 1; j < names.size(); ++j) {
                if (names[i] == names[j]) continue;
                for (const auto& [option, pattern] : {std::pair{"-o", o_.output}, std::pair{"--stats", o_.stats_path}}) {
                    const std::string a = expand_grid_pattern(pattern, names[i]);
                    if (pattern.empty() || a != expand_grid_pattern(pattern, names[j])) continue;
                    throw pqdc_cli::UsageError{std::string(option) + " '" + pattern + "' gives grids '" + names[i] +
                                               "' and '" + names[j] + "' the same file '" + a +
                                               "'; choose the grids with --grid NAME,... or mesh them one at a time"};
                }
            }
    }

    /// Whether a grid is meshed brick by brick and written piece by piece
    /// (pqdc::extract_bricks, or under pqdc-mpi pqdc::extract_distributed,
    /// to a MeshStreamWriter): uniform mode out of core, unless --decimate
    /// needs the whole mesh. --vertex-normals streams (each normal depends on
    /// its vertex alone), and so does --min-component (a union-find over the
    /// scratch files, joined across ranks).
    bool streamed(bool delay_loaded) const {
        return (delay_loaded || o_.out_of_core) && !o_.adaptive && !o_.decimate;
    }

    /// The streamed run of `g`: the mesh never whole in memory, the file the
    /// in-core run's bytes, written by all ranks of a pqdc-mpi run together.
    /// `store`: the brick store `g` is the shell of, read file by file.
    void stream_grid(const openvdb::GridBase& g, MeshReport& report, const pqdc::BrickStore* store) {
        pqdc::MeshStreamWriter out(report.output, write_options(), o_.vertex_normals);
        with_memory_hint([&] {
            const pqdc::ExtractOptions eo = extract_options();
            if (store && ranks_) pqdc::extract_distributed(*store, eo, o_.bricks, *ranks_, out, {}, &report.stats);
            else if (store) pqdc::extract_bricks(*store, eo, o_.bricks, out, {}, &report.stats);
            else if (ranks_) pqdc::extract_distributed(g, eo, o_.bricks, *ranks_, out, {}, &report.stats);
            else pqdc::extract_bricks(g, eo, o_.bricks, out, {}, &report.stats);
        });
        if (pending_signal()) throw pqdc::cancelled_error("interrupted");
        // Under pqdc-mpi every rank holds its part of the file; they write it together.
        const auto finish = [&] { ranks_ ? out.finish(*ranks_) : out.finish(); };
        if (!root_) return finish();
        log_islands(report.stats);
        write_and_report(report, finish);
    }

    /// `delay_loaded`: the grid's buffers are in the file; it is meshed brick by
    /// brick. `store`: `g` is that brick store's shell (streamed runs only).
    /// `owned`: `g` itself, when the job may free it once it has been read.
    void mesh_grid(const openvdb::GridBase& g, const std::string& display, const std::string& source_name,
                   bool delay_loaded, double read_seconds, const pqdc::BrickStore* store = nullptr,
                   openvdb::GridBase* owned = nullptr) {
        MeshReport report;
        report.read_seconds = read_seconds;
        report.grid = g.getName();
        report.source = source_name + ":" + g.getName();
        report.output = expand_grid_pattern(o_.output, g.getName());
        std::ostringstream voxel;
        const openvdb::Vec3d vs = g.voxelSize();
        voxel << vs[0];
        if (std::abs(vs[1] - vs[0]) > 1e-6 * vs[0] || std::abs(vs[2] - vs[0]) > 1e-6 * vs[0]) voxel << " x " << vs[1] << " x " << vs[2];
        log("using grid '" + g.getName() + "' (" + g.valueType() + ", " +
            (g.getGridClass() == openvdb::GRID_FOG_VOLUME ? "fog volume"
             : g.getGridClass() == openvdb::GRID_LEVEL_SET ? "level set" : "unknown class") +
            ", voxel size " + voxel.str() + ") from " + display);
        progress_.stage("meshing grid '" + g.getName() + "'");
        pqdc::Mesh mesh;
        try {
            if (delay_loaded && !o_.out_of_core && !store)  // a store is always meshed brick by brick
                log("grid '" + g.getName() + "' needs more memory than the limit allows: meshing it brick by brick "
                    "(out of core)");
            if (streamed(delay_loaded)) return stream_grid(g, report, store);
            // The grid goes as soon as the extraction is done reading it (the
            // run's peak memory drops by its size), unless normals after
            // --decimate read it again.
            std::function<void()> free_grid;
            if (owned && !(o_.vertex_normals && o_.decimate))
                free_grid = [owned] { owned->clear(); };
            mesh = with_memory_hint([&] { return extract(g, report, delay_loaded || o_.out_of_core, free_grid); },
                                    !o_.adaptive && !o_.decimate);
        } catch (const pqdc::input_error& e) {
            throw pqdc::input_error((o_.input == "-" ? std::string("standard input") : "'" + o_.input + "'") + ": " +
                                    e.what());
        } catch (const pqdc::error&) {
            throw;
        } catch (const std::bad_alloc&) {
            throw;
        } catch (const std::exception& e) {
            throw std::runtime_error("meshing grid '" + g.getName() + "' of " + display + " failed: " + e.what());
        }
        log_islands(report.stats);
        // Distances in voxels: of the shortest voxel side, so a bound holds along every axis.
        decimate(mesh, std::min({vs[0], vs[1], vs[2]}), report);
        if (o_.vertex_normals && o_.decimate) {
            // The extraction's interior; a delay-loaded grid is read one node at a
            // time (its accessors would load every leaf they touch).
            const pqdc::Interior inside =
                report.stats.interior == "above" ? pqdc::Interior::above_isovalue : pqdc::Interior::below_isovalue;
            if (delay_loaded) pqdc::compute_vertex_normals_by_nodes(mesh, g, inside);
            else pqdc::compute_vertex_normals(mesh, g, inside);
        }
        write(mesh, report);
    }

    const CliOptions& o_;
    SupervisorLink& link_;
    pqdc::RankGroup* const ranks_;
    const bool root_;
    Progress progress_;
    openvdb::GridBase::ConstPtr mask_;
};

}  // namespace

int run_job(const CliOptions& options, SupervisorLink& link, pqdc::RankGroup* ranks) {
    std::optional<tbb::global_control> threads;
    if (options.threads > 0)
        threads.emplace(tbb::global_control::max_allowed_parallelism, std::size_t(options.threads));
    return Job(options, link, ranks).run();
}

int report_job_errors(const char* program, const std::function<int()>& job) {
    try {
        return job();
    } catch (const Interrupted& e) {
        std::cerr << ("\n" + std::string(program) + ": interrupted after '" + e.written +
                      "' was written completely; nothing after it was written\n");
        return interrupted_exit(e.signal);
    } catch (const pqdc::cancelled_error&) {
        std::cerr << ("\n" + std::string(program) + ": interrupted; no output written\n");
        return interrupted_exit(pending_signal());
    } catch (const pqdc::resource_error& e) {
        std::cerr << (std::string(program) + ": " + e.what() + "\n");
        return 1;
    } catch (...) {
        const int code = pqdc_cli::report_current_exception(
            program, "mesh a smaller region with --bbox or --mask, a coarser grid, or use --memory-limit to fail early");
        return code == 1 && pending_signal() ? interrupted_exit(pending_signal()) : code;
    }
}

int run_main(int argc, char** argv, SupervisorLink& link) {
    return report_job_errors("pqdc", [&] {
        CliOptions o;
        if (!parse_command_line(argc, argv, o, Program::pqdc)) return 0;
        link.writing({o.output, o.stats_path});
        return run_job(o, link, nullptr);
    });
}

}  // namespace pqdc_app
