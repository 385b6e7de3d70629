// The read-mesh-write job of one pqdc run.
#pragma once

#include "options.hpp"
#include "sandbox.hpp"

namespace pqdc_app {

/// Runs the whole job for the options given (procedural field or .vdb
/// grids), printing through the progress line; returns the exit code.
/// Throws the library's errors, pqdc_cli::UsageError and Interrupted.
int run_job(const CliOptions& options, SupervisorLink& link);

/// Parses argv, runs the job and maps every exception to its message and
/// exit code: what main() does, in the supervised child or in-process.
int run_main(int argc, char** argv, SupervisorLink& link);

}  // namespace pqdc_app
