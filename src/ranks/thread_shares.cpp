#include "ranks/thread_shares.hpp"

#include <condition_variable>
#include <deque>
#include <exception>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace pqdc::detail {
namespace {

/// Messages a share may have sent to rank 0 and rank 0 not yet taken.
constexpr std::size_t kUnreadMessages = 4;

/// Thrown in a share that waits for another one that has failed; never
/// leaves run_in_shares (the first failure does).
struct ShareAbandoned {};

class Mailboxes {
public:
    explicit Mailboxes(int shares)
        : gathered_(std::size_t(shares)), broadcast_(std::size_t(shares)), to_root_(std::size_t(shares)) {}

    using Queue = std::deque<std::string>;
    void push(Queue& q, std::string s, std::size_t capacity = ~std::size_t(0)) {
        std::unique_lock<std::mutex> lock(m_);
        changed_.wait(lock, [&] { return failed_ || q.size() < capacity; });
        if (failed_) throw ShareAbandoned{};
        q.push_back(std::move(s));
        changed_.notify_all();
    }
    std::string pop(Queue& q) {
        std::unique_lock<std::mutex> lock(m_);
        changed_.wait(lock, [&] { return failed_ || !q.empty(); });
        if (failed_) throw ShareAbandoned{};
        std::string s = std::move(q.front());
        q.pop_front();
        changed_.notify_all();
        return s;
    }
    void fail(std::exception_ptr e) {
        std::lock_guard<std::mutex> lock(m_);
        if (!first_failure_) first_failure_ = std::move(e);
        failed_ = true;
        changed_.notify_all();
    }
    bool failed() {
        std::lock_guard<std::mutex> lock(m_);
        return failed_;
    }
    std::exception_ptr first_failure() const { return first_failure_; }

    std::vector<Queue> gathered_, broadcast_, to_root_;

private:
    std::mutex m_;
    std::condition_variable changed_;
    bool failed_ = false;
    std::exception_ptr first_failure_;
};

class Share : public RankGroup {
public:
    Share(Mailboxes& boxes, int rank, int size) : boxes_(boxes), rank_(rank), size_(size) {}
    int rank() const override { return rank_; }
    int size() const override { return size_; }
    std::vector<std::string> gather_at_root(std::string part) override {
        if (rank_ != 0) {
            boxes_.push(boxes_.gathered_[std::size_t(rank_)], std::move(part));
            return {};
        }
        std::vector<std::string> parts{std::move(part)};
        for (int r = 1; r < size_; ++r) parts.push_back(boxes_.pop(boxes_.gathered_[std::size_t(r)]));
        return parts;
    }
    std::string broadcast_from_root(std::string value) override {
        if (rank_ != 0) return boxes_.pop(boxes_.broadcast_[std::size_t(rank_)]);
        for (int r = 1; r < size_; ++r) boxes_.push(boxes_.broadcast_[std::size_t(r)], value);
        return value;
    }
    void send_to_root(std::string message) override {
        boxes_.push(boxes_.to_root_[std::size_t(rank_)], std::move(message), kUnreadMessages);
    }
    std::string receive_from(int from) override { return boxes_.pop(boxes_.to_root_[std::size_t(from)]); }

private:
    Mailboxes& boxes_;
    const int rank_, size_;
};

}  // namespace

void run_in_shares(int shares, const std::function<void(RankGroup& share, const std::function<bool()>& wanted)>& job) {
    Mailboxes boxes(shares);
    const std::function<bool()> wanted = [&boxes] { return !boxes.failed(); };
    auto run = [&](int r) {
        Share share(boxes, r, shares);
        try {
            job(share, wanted);
        } catch (const ShareAbandoned&) {
            boxes.fail(nullptr);
        } catch (...) {
            boxes.fail(std::current_exception());
        }
    };
    std::vector<std::thread> threads;
    try {
        for (int r = 1; r < shares; ++r) threads.emplace_back(run, r);
    } catch (...) {  // no thread: the started shares must not wait for it
        boxes.fail(std::current_exception());
    }
    if (threads.size() + 1 == std::size_t(shares)) run(0);
    for (std::thread& t : threads) t.join();
    if (std::exception_ptr e = boxes.first_failure()) std::rethrow_exception(e);
}

}  // namespace pqdc::detail
