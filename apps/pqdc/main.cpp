// pqdc: mesh an OpenVDB grid or a procedural field by dual contouring with
// probabilistic plane quadrics. Parses options, then runs the job: .vdb
// input in a supervised child process (sandbox.hpp says why), procedural
// fields in-process.
// Exit codes: 0 ok, 1 runtime error (input, output, resources), 2 usage
// error, 128 + signal number when interrupted (130 SIGINT, 143 SIGTERM).
#include "job.hpp"
#include "options.hpp"
#include "sandbox.hpp"
#include "signals.hpp"

#include "../cli_util.hpp"

int main(int argc, char** argv) {
    using namespace pqdc_app;
    if (is_job_child(argc, argv)) return job_child_main(argc, argv);
    CliOptions o;
    try {
        if (!parse_command_line(argc, argv, o)) return 0;
    } catch (...) {
        return pqdc_cli::report_current_exception("pqdc");
    }
    SupervisorLink none;
    if (o.procedural.empty()) {
        try {
            return supervise(argc, argv, o);
        } catch (...) {
            return pqdc_cli::report_current_exception("pqdc");
        }
    }
    install_signal_handlers();
    return run_main(argc, argv, none);
}
