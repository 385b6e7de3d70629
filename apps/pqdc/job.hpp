// The read-mesh-write job of one pqdc run.
#pragma once

#include "options.hpp"
#include "sandbox.hpp"

#include "pqdc/distributed.hpp"

#include <functional>

namespace pqdc_app {

/// Runs the whole job for the options given (procedural field or .vdb
/// grids), printing through the progress line; returns the exit code.
/// `ranks`: a pqdc-mpi run's group (uniform mode, brick by brick, rank 0
/// prints and writes); null for pqdc. Throws the library's errors,
/// pqdc_cli::UsageError and Interrupted.
int run_job(const CliOptions& options, SupervisorLink& link, pqdc::RankGroup* ranks);

/// job() with every exception mapped to its message (after "program: ")
/// and exit code: 1 runtime, 2 usage, 128 + signal when interrupted.
int report_job_errors(const char* program, const std::function<int()>& job);

/// Parses argv, runs the job and maps every exception to its message and
/// exit code: what main() does, in the supervised child or in-process.
int run_main(int argc, char** argv, SupervisorLink& link);

}  // namespace pqdc_app
