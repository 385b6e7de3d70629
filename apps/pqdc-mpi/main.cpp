// pqdc-mpi: pqdc with the stage that reads the voxel values shared among
// the ranks of an MPI job: the cells stage in uniform mode
// (pqdc::extract_distributed), the finest octree level in adaptive mode
// (pqdc::extract_adaptive_distributed). Same options and the same output
// bytes as pqdc:
//   mpirun -np 4 pqdc-mpi volume.vdb -o surface.ply [pqdc options]
// Every rank reads the file's topology (delayed loading) and the values of
// its own bricks. In uniform mode each rank also meshes its bricks and
// writes its part of the file at its offset (pqdc::extract_distributed with
// a MeshStreamWriter, then MeshStreamWriter::finish(group)), with vertex
// normals and the component filter too; with --adaptive or --decimate
// rank 0 assembles, repairs and writes the whole mesh. A rank that fails prints
// its error and aborts the whole job (MPI_Abort), before rank 0 has opened
// its output or, while the ranks write their parts, after rank 0 has
// removed the temporary file: no file is left. A rank killed outright
// leaves the shared temporary to the others, which remove it when mpirun
// signals them (pqdc::remove_temporary_files). Exit codes as pqdc's.
//
// Not run under pqdc's reader sandbox (a supervising parent process): MPI
// ranks must not fork. A corrupt .vdb can therefore crash a rank; mpirun
// then ends the job, still with no output.
#include "../cli_util.hpp"
#include "../pqdc/job.hpp"
#include "../pqdc/options.hpp"
#include "../pqdc/sandbox.hpp"
#include "../pqdc/signals.hpp"
#include "mpi_rank_group.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <iostream>
#include <string>

namespace {

/// What pqdc's options mean under MPI: always brick by brick; refused
/// what cannot be distributed yet.
void check_distributable(pqdc_app::CliOptions& o) {
    if (o.input == "-")
        throw pqdc_cli::UsageError{"pqdc-mpi reads its input on every rank: give a .vdb file or brick store, not "
                                   "- (standard input)"};
    o.out_of_core = true;
}

}  // namespace

int main(int argc, char** argv) {
    int provided = 0;
    MPI_Init_thread(&argc, &argv, MPI_THREAD_FUNNELED, &provided);
    MPI_Comm_set_errhandler(MPI_COMM_WORLD, MPI_ERRORS_RETURN);
    pqdc_mpi::MpiRankGroup group(MPI_COMM_WORLD);
    const bool root = group.rank() == 0;
    // Only rank 0 speaks for the job (help, usage errors, the summary); a
    // failing rank still prints its own error below.
    if (!root)
        if (const int null = ::open("/dev/null", O_WRONLY | O_CLOEXEC); null >= 0) {
            ::dup2(null, STDOUT_FILENO);
            ::close(null);
        }
    pqdc_app::CliOptions o;
    int code = 0;
    try {
        if (!pqdc_app::parse_command_line(argc, argv, o, pqdc_app::Program::pqdc_mpi)) {
            MPI_Finalize();
            return 0;
        }
        check_distributable(o);
    } catch (...) {
        // The same on every rank: rank 0 reports it, everyone exits.
        if (root) code = pqdc_cli::report_current_exception("pqdc-mpi");
        else code = 2;
        MPI_Finalize();
        return code;
    }
    pqdc_app::install_signal_handlers();
    // mpirun ends the other ranks with a signal when one fails (MPI_Abort,
    // below): their "interrupted" would read as if the user had stopped it.
    // Rank 0 speaks for the job (it writes the files and knows which are
    // whole); the others stop without a word.
    pqdc_app::set_interrupt_message(
        root ? "\npqdc-mpi: stopped by a signal (Ctrl-C, or mpirun ending the job after a rank failed: see its "
               "error above); no output written\n"
             : "");
    pqdc_app::set_interrupt_program("pqdc-mpi");
    // A rank killed outright (SIGKILL, the OOM killer) cannot remove the
    // shared temporary file; mpirun then sends the others SIGTERM, and their
    // collective write could never finish: they remove it and exit.
    if (group.size() > 1) pqdc_app::exit_at_once_during_writes();
    const std::string program =
        group.size() == 1 ? std::string("pqdc-mpi")
                          : "pqdc-mpi (rank " + std::to_string(group.rank()) + " of " + std::to_string(group.size()) + ")";
    pqdc_app::SupervisorLink none;
    code = pqdc_app::report_job_errors(program.c_str(), [&] { return pqdc_app::run_job(o, none, &group); });
    // The other ranks may wait for this one in a collective: end them all.
    if (code != 0 && group.size() > 1) MPI_Abort(MPI_COMM_WORLD, code);
    MPI_Finalize();
    return code;
}
