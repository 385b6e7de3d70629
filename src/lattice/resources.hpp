// Memory limit and progress/cancellation, shared by both extractors.
#pragma once

#include "pqdc/exceptions.hpp"
#include "pqdc/extract.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstddef>
#include <functional>

namespace pqdc::detail {

/// 80% of physical memory.
std::size_t default_memory_limit();

/// options.memory_limit_bytes, or default_memory_limit() when it is 0.
std::size_t memory_limit(const ExtractOptions& options);

/// Throws resource_error when `needed` bytes for `what` exceed the options' limit.
void check_memory(double needed, const ExtractOptions& options, const char* what);

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

}  // namespace pqdc::detail
