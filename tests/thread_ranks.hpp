// A pqdc::RankGroup whose ranks are threads of the test process, so the
// distributed driver's logic (brick shares, the exchanges, rank 0's
// assembly) is tested without MPI: the library's own in-process ranks
// (ranks/thread_shares.hpp, which streamed runs use for concurrent runs of
// bricks). pqdc-mpi's transport is tested by tests/mpi/run.sh.
#pragma once

#include "pqdc/distributed.hpp"
#include "ranks/thread_shares.hpp"

#include <functional>
#include <vector>

namespace pqdc_test {

class ThreadRanks {
public:
    explicit ThreadRanks(int ranks) : size_(ranks) {}

    /// Runs job(group) for every rank on its own thread and returns each
    /// rank's result; rethrows the first exception a rank threw.
    template <class Result>
    std::vector<Result> run(const std::function<Result(pqdc::RankGroup&)>& job) {
        std::vector<Result> results(static_cast<std::size_t>(size_));
        pqdc::detail::run_in_shares(size_, [&](pqdc::RankGroup& group, const std::function<bool()>&) {
            results[static_cast<std::size_t>(group.rank())] = job(group);
        });
        return results;
    }

private:
    const int size_;
};

}  // namespace pqdc_test
