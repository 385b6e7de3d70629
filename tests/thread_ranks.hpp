// A pqdc::RankGroup whose ranks are threads of the test process, so the
// distributed driver's logic (brick shares, the exchange, rank 0's
// assembly) is tested without MPI. pqdc-mpi's transport is tested by
// tests/mpi/run.sh.
#pragma once

#include "pqdc/distributed.hpp"

#include <condition_variable>
#include <exception>
#include <functional>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace pqdc_test {

class ThreadRanks {
public:
    explicit ThreadRanks(int ranks) : size_(ranks), parts_(std::size_t(ranks)) {}

    /// Runs job(group) for every rank on its own thread and returns each
    /// rank's result; rethrows the first exception a rank threw.
    template <class Result>
    std::vector<Result> run(const std::function<Result(pqdc::RankGroup&)>& job) {
        const int n = size_;
        std::vector<Result> results(parts_.size());
        std::vector<std::exception_ptr> errors(parts_.size());
        std::vector<std::thread> threads;
        for (int r = 0; r < n; ++r)
            threads.emplace_back([&, r] {
                Rank rank(*this, r);
                try {
                    results[std::size_t(r)] = job(rank);
                } catch (...) {
                    errors[std::size_t(r)] = std::current_exception();
                    std::lock_guard<std::mutex> lock(m_);
                    failed_ = true;
                    ready_.notify_all();
                }
            });
        for (std::thread& t : threads) t.join();
        for (const std::exception_ptr& e : errors)
            if (e) std::rethrow_exception(e);
        return results;
    }

private:
    class Rank : public pqdc::RankGroup {
    public:
        Rank(ThreadRanks& all, int rank) : all_(all), rank_(rank) {}
        int rank() const override { return rank_; }
        int size() const override { return all_.size_; }
        std::vector<std::string> gather_at_root(std::string part) override {
            std::unique_lock<std::mutex> lock(all_.m_);
            all_.parts_[std::size_t(rank_)] = std::move(part);
            ++all_.arrived_;
            all_.ready_.notify_all();
            if (rank_ != 0) return {};
            all_.ready_.wait(lock, [&] { return all_.failed_ || all_.arrived_ == size(); });
            if (all_.failed_) throw std::runtime_error("another rank failed");
            return std::move(all_.parts_);
        }

    private:
        ThreadRanks& all_;
        const int rank_;
    };

    const int size_;
    std::mutex m_;
    std::condition_variable ready_;
    std::vector<std::string> parts_;
    int arrived_ = 0;
    bool failed_ = false;
};

}  // namespace pqdc_test
