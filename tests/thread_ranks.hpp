// A pqdc::RankGroup whose ranks are threads of the test process, so the
// distributed driver's logic (brick shares, the exchange, rank 0's
// assembly) is tested without MPI. pqdc-mpi's transport is tested by
// tests/mpi/run.sh.
#pragma once

#include "pqdc/distributed.hpp"

#include <condition_variable>
#include <deque>
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
    explicit ThreadRanks(int ranks)
        : size_(ranks), gathered_(std::size_t(ranks)), broadcast_(std::size_t(ranks)), to_root_(std::size_t(ranks)) {}

    /// Runs job(group) for every rank on its own thread and returns each
    /// rank's result; rethrows the first exception a rank threw.
    template <class Result>
    std::vector<Result> run(const std::function<Result(pqdc::RankGroup&)>& job) {
        const int n = size_;
        std::vector<Result> results(static_cast<std::size_t>(n));
        std::vector<std::exception_ptr> errors(static_cast<std::size_t>(n));
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
            if (rank_ != 0) {
                all_.push(all_.gathered_[std::size_t(rank_)], std::move(part));
                return {};
            }
            std::vector<std::string> parts{std::move(part)};
            for (int r = 1; r < size(); ++r) parts.push_back(all_.pop(all_.gathered_[std::size_t(r)]));
            return parts;
        }
        std::string broadcast_from_root(std::string value) override {
            if (rank_ != 0) return all_.pop(all_.broadcast_[std::size_t(rank_)]);
            for (int r = 1; r < size(); ++r) all_.push(all_.broadcast_[std::size_t(r)], value);
            return value;
        }
        void send_to_root(std::string message) override {
            if (rank_ == 0) throw std::logic_error("rank 0 sent itself a message");
            all_.push(all_.to_root_[std::size_t(rank_)], std::move(message));
        }
        std::string receive_from(int from) override {
            if (rank_ != 0 || from <= 0 || from >= size()) throw std::logic_error("receive_from on the wrong rank");
            return all_.pop(all_.to_root_[std::size_t(from)]);
        }

    private:
        ThreadRanks& all_;
        const int rank_;
    };

    using Queue = std::deque<std::string>;
    void push(Queue& q, std::string s) {
        std::lock_guard<std::mutex> lock(m_);
        q.push_back(std::move(s));
        ready_.notify_all();
    }
    std::string pop(Queue& q) {
        std::unique_lock<std::mutex> lock(m_);
        ready_.wait(lock, [&] { return failed_ || !q.empty(); });
        if (q.empty()) throw std::runtime_error("another rank failed");
        std::string s = std::move(q.front());
        q.pop_front();
        return s;
    }

    const int size_;
    std::mutex m_;
    std::condition_variable ready_;
    /// Per rank: what it sent to gather_at_root, what rank 0 broadcast to
    /// it, what it sent with send_to_root.
    std::vector<Queue> gathered_, broadcast_, to_root_;
    bool failed_ = false;
};

}  // namespace pqdc_test
