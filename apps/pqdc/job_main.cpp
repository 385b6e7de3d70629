// pqdc-job: the worker behind pqdc (launcher.cpp). Parses the options and
// runs the job: read a .vdb file or sample a procedural field, mesh it by
// dual contouring with probabilistic plane quadrics, write the mesh.
// Started by pqdc with the supervision arguments (supervision.hpp); started
// directly, it runs the same job without a supervisor (a reader crash on a
// corrupt file is then a crash).
// Exit codes: 0 ok, 1 runtime error (input, output, resources), 2 usage
// error, 128 + signal number when interrupted (130 SIGINT, 143 SIGTERM).
#include "job.hpp"
#include "sandbox.hpp"
#include "signals.hpp"

int main(int argc, char** argv) {
    using namespace pqdc_app;
    if (is_job_child(argc, argv)) return job_child_main(argc, argv);
    install_signal_handlers();
    SupervisorLink none;
    return run_main(argc, argv, none);
}
