// Memory limit and progress/cancellation, shared by both extractors.
#pragma once

#include "pqdc/exceptions.hpp"
#include "pqdc/extract.hpp"
#include "memory/huge_pages.hpp"  // reserve_large, for the stages' large arrays

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstddef>
#include <functional>
#include <string>
#include <vector>

namespace pqdc::detail {

/// 80% of physical memory.
std::size_t default_memory_limit();

/// options.memory_limit_bytes, or default_memory_limit() when it is 0.
std::size_t memory_limit(const ExtractOptions& options);

/// A byte count for messages, about three significant digits in the largest unit
/// that keeps it >= 1 ("12.3 MiB", "4.05 KiB", "300 bytes"): whole MiB made
/// a 4 KiB need "about 0 MiB" and a 1.4 MiB one equal to a 1 MiB limit.
std::string byte_size_text(double bytes);

/// Throws resource_error when `needed` bytes for `what` exceed the options' limit.
void check_memory(double needed, const ExtractOptions& options, const char* what);

/// Hands memory that the heap keeps after frees back to the system, so
/// that the next large arrays do not add to it (glibc; elsewhere nothing).
void return_freed_memory();

/// options.progress behind a clamp and the cancellation rule.
class Progress {
public:
    explicit Progress(const ExtractOptions& o) : callback_(o.progress) {}
    /// Reports the finished fraction; throws cancelled_error when the caller asked to stop.
    void report(double fraction) const {
        if (callback_ && !callback_(std::min(1.0, std::max(0.0, fraction))))
            throw cancelled_error("extraction cancelled by the caller");
    }
    bool enabled() const { return bool(callback_); }

private:
    const std::function<bool(double)>& callback_;
};

/// Runs body(i) for i in [0, n) in parallel, in chunks, reporting progress
/// from the calling thread between chunks (also the cancellation point):
/// the callback is never called from a worker thread.
template <class Body>
void parallel_chunks(std::size_t n, const Progress& progress, double from, double to, const Body& body) {
    const std::size_t chunk = progress.enabled() ? std::max<std::size_t>(256, n / 64) : std::max<std::size_t>(n, 1);
    for (std::size_t start = 0; start < n; start += chunk) {
        const std::size_t end = std::min(n, start + chunk);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(start, end), [&](const tbb::blocked_range<std::size_t>& r) {
            for (std::size_t i = r.begin(); i != r.end(); ++i) body(i);
        });
        progress.report(from + (to - from) * double(end) / double(n));
    }
}

/// A stage's share [from, to] of the whole job's progress, so that a stage
/// (and the steps inside it) reports its own fractions in [0, 1].
class ProgressSpan {
public:
    ProgressSpan(const Progress& progress, double from, double to) : progress_(progress), from_(from), to_(to) {}
    /// Reports the stage's finished fraction f in [0, 1]; the cancellation point.
    void report(double f) const { progress_.report(from_ + (to_ - from_) * f); }
    /// The sub-span [a, b] of this one (fractions of it).
    ProgressSpan part(double a, double b) const {
        return ProgressSpan(progress_, from_ + (to_ - from_) * a, from_ + (to_ - from_) * b);
    }
    bool enabled() const { return progress_.enabled(); }

private:
    const Progress& progress_;
    double from_, to_;
};

/// tbb::parallel_for over [0, n) in blocked ranges of `grain`, cut into
/// chunks of `chunk` items when progress is on: after each chunk the span
/// reports from the calling thread (the cancellation point), so a chunk's
/// duration bounds the time to react to Ctrl-C. body(range) may keep
/// per-range state (accessors, scratch); items must not depend on each
/// other, so the chunks leave the result unchanged.
template <class Body>
void parallel_ranges(std::size_t n, std::size_t grain, std::size_t chunk, const ProgressSpan& span, const Body& body) {
    const std::size_t step = span.enabled() ? std::max<std::size_t>(chunk, 1) : std::max<std::size_t>(n, 1);
    for (std::size_t start = 0; start < n; start += step) {
        const std::size_t end = std::min(n, start + step);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(start, end, grain), body);
        span.report(double(end) / double(n));
    }
}

}  // namespace pqdc::detail
