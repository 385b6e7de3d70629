// Shares of one streamed run meshed at once by threads of one process
// (issue 14): the distributed pipeline's ranks, in process. A streamed
// run's per-brick work (the brick's copy, the local mesh, the scratch
// records, the first check's set-up) is largely serial, so one process
// meshing one brick at a time uses little of a second core; two shares of
// the bricks, each one brick at a time, use both, and the output stays the
// same bytes because it is the distributed run's (tested for any number of
// ranks).
#pragma once

#include "pqdc/distributed.hpp"

#include <functional>

namespace pqdc::detail {

/// Runs job(share, wanted) on `shares` threads at once, each with its rank
/// of an in-process RankGroup (rank 0 on the calling thread). `wanted()`
/// turns false once a share has failed, so that the others can stop at
/// their next cancellation point. A share's messages to rank 0 wait while
/// it holds a few unread ones, so a share ahead of rank 0 does not queue
/// its whole mesh. After every share has ended, rethrows the first failure.
void run_in_shares(int shares, const std::function<void(RankGroup& share, const std::function<bool()>& wanted)>& job);

}  // namespace pqdc::detail
