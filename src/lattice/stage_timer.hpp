// Per-stage wall times into ExtractStats::stages, for both drivers.
#pragma once

#include "pqdc/stats.hpp"

#include <chrono>

namespace pqdc::detail {

class StageTimer {
public:
    explicit StageTimer(ExtractStats& stats) : stats_(stats), start_(Clock::now()), stage_(start_) {}
    /// Records the stage that just ended, named as ExtractStats::stages documents.
    void done(const char* name) {
        const auto now = Clock::now();
        stats_.stages.push_back({name, std::chrono::duration<double>(now - stage_).count()});
        stage_ = now;
    }
    void finish() { stats_.seconds_total = std::chrono::duration<double>(Clock::now() - start_).count(); }

private:
    using Clock = std::chrono::steady_clock;
    ExtractStats& stats_;
    Clock::time_point start_, stage_;
};

}  // namespace pqdc::detail
