// pqdc-bricks: writes a brick store (pqdc/brick_store.hpp) from a .vdb grid,
// streaming the file once: its leaf buffers are read brick by brick through
// delayed loading; or from a procedural field, sampled brick by brick. pqdc
// meshes the store directory like the .vdb file, with the same output bytes.
// Exit codes: 0 ok, 1 runtime error, 2 usage error, 130/143 interrupted
// (SIGINT/SIGTERM/SIGHUP: no store and no brick files are left).
#include "pqdc/brick_store.hpp"
#include "pqdc/exceptions.hpp"
#include "pqdc/procedural.hpp"
#include "pqdc/volume_io.hpp"

#include "cli_util.hpp"
#include "progress.hpp"
#include "pqdc/signals.hpp"  // apps/pqdc/: pqdc's deferred interrupts

#include <openvdb/openvdb.h>

#include <unistd.h>

#include <iostream>
#include <memory>
#include <string>
#include <vector>

namespace {

/// Runs write(progress hook) with signals deferred (pqdc's handler, see
/// pqdc/signals.hpp): before it a signal ends the process at once, as
/// nothing is on disk yet; during it the hook sees the signal and stops the
/// split after the brick in hand, and the library removes every file it
/// wrote. Returns the exit code of an interrupted run, else 0.
template <class Write>
int write_store(const std::string& dir, bool show_progress, const Write& write) {
    pqdc_app::Progress progress(show_progress, "pqdc-bricks");
    progress.stage("writing the brick store '" + dir + "'");
    const pqdc::BrickStoreProgress hook = [&progress](double f) {
        progress.set(f);
        return pqdc_app::pending_signal() == 0;
    };
    try {
        pqdc_app::write_deferring_signals(dir, [&] { write(hook); });
    } catch (const pqdc::cancelled_error&) {
        progress.finish();
        if (pqdc_app::pending_signal() == 0) throw;
        std::cerr << "pqdc-bricks: interrupted; no store written (the files written to '" + dir + "' were removed)\n";
        return pqdc_app::interrupted_exit(pqdc_app::pending_signal());
    } catch (const pqdc_app::Interrupted& i) {  // after the last brick's check: the store is whole
        progress.finish();
        std::cerr << "pqdc-bricks: interrupted after the brick store '" + dir + "' was written completely\n";
        return pqdc_app::interrupted_exit(i.signal);
    }
    progress.finish();
    return 0;
}

const char* kUsage = R"(usage: pqdc-bricks split INPUT.vdb -o DIR [--grid NAME] [--brick-size N]
       pqdc-bricks procedural NAME -o DIR [--resolution N] [--active-band V] [--brick-size N]

split: writes a float or double grid as a brick store: DIR/grid.vdb (the
grid without voxels), one DIR/brick-N.vdb per brick of the grid, and
DIR/index.txt (written last). Mesh it with `pqdc DIR -o mesh.ply`: the same
bytes as `pqdc INPUT.vdb -o mesh.ply`.

procedural: samples a procedural field (sphere, box, figure3) brick by brick
into a store, as `pqdc --procedural NAME --write-volume` would write it,
without ever holding the whole volume: how volumes larger than memory are
made. --active-band makes the blocks within V voxels of the surface active
too (inf: every voxel of the lattice, a dense volume like a scan).)";
const std::vector<pqdc_cli::OptionSpec> kSpecs = {
    {"-o,--output", true, "the store directory (new or empty)"},
    {"--grid", true, "the grid to split (default: the first scalar grid)"},
    {"--brick-size", true, "voxels per brick file as a cube edge, a power of two from 128 to 4096 (default 256)"},
    {"--resolution", true, "procedural: lattice cells along the longest side, 4 to 16384 (default 128)"},
    {"--active-band", true, "procedural: voxels around the surface that are active too, >= 0 or inf (default 0)"},
    {"--progress", false, "show the progress line even when stderr is not a terminal"},
    {"-q,--quiet", false, "print nothing but errors (no progress line, no summary)"},
};

int run(int argc, char** argv) {
    bool done = false;
    std::vector<std::string> positional;
    const auto given =
        pqdc_cli::parse_options(argc, argv, "pqdc-bricks", kUsage, kSpecs, "split INPUT.vdb", positional, done);
    if (done) return 0;
    std::string output, grid;
    pqdc::BrickOptions bricks;
    pqdc::ProceduralSampling sampling;
    bool sampling_given = false, force_progress = false, quiet = false;
    for (const auto& [name, value] : given) {
        if (name == "--output") output = value;
        else if (name == "--progress") force_progress = true;
        else if (name == "--quiet") quiet = true;
        else if (name == "--grid") grid = value;
        else if (name == "--brick-size") bricks.brick_size = pqdc_cli::parse_brick_size(value);
        else if (name == "--resolution") sampling.resolution = int(pqdc_cli::parse_integer(name, value, 4, 16384));
        else if (name == "--active-band") {
            sampling.active_band_voxels = pqdc_cli::parse_number(name, value);
            if (!(sampling.active_band_voxels >= 0))
                throw pqdc_cli::UsageError{"--active-band must be >= 0 voxels (or inf), got " + value};
        }
        sampling_given |= name == "--resolution" || name == "--active-band";
    }
    const bool procedural = positional.size() == 2 && positional[0] == "procedural";
    if (positional.size() != 2 || (positional[0] != "split" && !procedural))
        throw pqdc_cli::UsageError{"expected: pqdc-bricks split INPUT.vdb -o DIR, or pqdc-bricks procedural NAME -o DIR "
                                   "(see --help)"};
    if (output.empty()) throw pqdc_cli::UsageError{"give the store directory with -o DIR"};
    if (procedural && !grid.empty()) throw pqdc_cli::UsageError{"--grid applies to split; a procedural field has one grid"};
    if (!procedural && sampling_given)
        throw pqdc_cli::UsageError{"--resolution and --active-band apply to procedural; split keeps the grid's voxels"};
    pqdc_cli::start_openvdb();
    const bool show_progress = !quiet && (force_progress || ::isatty(STDERR_FILENO));
    pqdc::BrickStoreSummary s;
    std::string what;
    if (procedural) {
        const std::unique_ptr<pqdc::ScalarField> field = pqdc::make_procedural(positional[1]);
        if (const int code = write_store(output, show_progress, [&](const pqdc::BrickStoreProgress& hook) {
                s = pqdc::write_brick_store(*field, sampling, output, bricks, hook);
            }))
            return code;
        what = "the procedural field '" + positional[1] + "' at resolution " + std::to_string(sampling.resolution);
    } else {
        const pqdc::LoadedGrid in = pqdc::read_scalar_grid(positional[1], grid, pqdc::VolumeLoading::delayed);
        if (const int code = write_store(output, show_progress, [&](const pqdc::BrickStoreProgress& hook) {
                s = pqdc::write_brick_store(*in.grid, output, bricks, hook);
            }))
            return code;
        what = "grid '" + in.grid->getName() + "' of '" + positional[1] + "'";
    }
    if (!quiet)
        std::cerr << "pqdc-bricks: wrote " << what << " as " << s.bricks << " bricks (" << s.leaves << " leaves) to '"
                  << output << "'\n";
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    try {
        pqdc_app::set_interrupt_program("pqdc-bricks");
        pqdc_app::set_interrupt_message("\npqdc-bricks: interrupted; no store written\n");
        pqdc_app::install_signal_handlers();  // also what report_write_signals_as_errors sets
        return run(argc, argv);
    } catch (...) {
        return pqdc_cli::report_current_exception("pqdc-bricks");
    }
}
