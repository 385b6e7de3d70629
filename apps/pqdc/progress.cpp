#include "progress.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <iostream>

namespace pqdc_app {
namespace {

/// Bytes this process has read through read(2) and friends so far.
std::uint64_t bytes_read_so_far() {
    std::uint64_t rchar = 0;
    if (std::FILE* f = std::fopen("/proc/self/io", "r")) {
        char key[64];
        unsigned long long value = 0;
        while (std::fscanf(f, "%63s %llu", key, &value) == 2)
            if (std::strcmp(key, "rchar:") == 0) {
                rchar = value;
                break;
            }
        std::fclose(f);
    }
    return rchar;
}

}  // namespace

Progress::Progress(bool enabled) : enabled_(enabled) {
    if (!enabled_) return;
    fd_ = ::fcntl(STDERR_FILENO, F_DUPFD_CLOEXEC, 3);
    if (fd_ < 0) {
        enabled_ = false;
        return;
    }
    thread_ = std::thread([this] { run(); });
}

Progress::~Progress() {
    finish();
    if (fd_ >= 0) ::close(fd_);
}

void Progress::reading(const std::string& what, std::uint64_t total_bytes) {
    std::lock_guard<std::mutex> lock(mutex_);
    what_ = what;
    from_io_ = true;
    io_start_ = enabled_ ? bytes_read_so_far() : 0;
    io_total_ = std::max<std::uint64_t>(total_bytes, 1);
}

void Progress::stage(const std::string& what) {
    std::lock_guard<std::mutex> lock(mutex_);
    what_ = what;
    from_io_ = false;
    fraction_.store(0.0);
}

void Progress::log(const std::string& line, bool quiet) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (shown_) {
        (void)!::write(fd_, "\r\033[K", 4);
        shown_ = false;
    }
    if (!quiet) std::cerr << "pqdc: " << line << std::endl;
}

void Progress::finish() {
    {
        std::lock_guard<std::mutex> lock(mutex_);
        if (stop_) return;
        stop_ = true;
        if (shown_) (void)!::write(fd_, "\r\033[K", 4);
        shown_ = false;
    }
    wake_.notify_all();
    if (thread_.joinable()) thread_.join();
}

void Progress::run() {
    using namespace std::chrono;
    std::unique_lock<std::mutex> lock(mutex_);
    // Quick runs end before anything is drawn.
    if (wake_.wait_for(lock, milliseconds(200), [this] { return stop_; })) return;
    while (!stop_) {
        draw_locked(false);
        wake_.wait_for(lock, milliseconds(100), [this] { return stop_; });
    }
}

void Progress::draw_locked(bool) {
    if (what_.empty()) return;
    double f = fraction_.load();
    if (from_io_) f = double(bytes_read_so_far() - io_start_) / double(io_total_);
    f = std::clamp(f, 0.0, 1.0);
    char line[512];
    const int n = std::snprintf(line, sizeof line, "\rpqdc: %.200s %3d%%\033[K", what_.c_str(), int(f * 100.0));
    if (n > 0) (void)!::write(fd_, line, std::size_t(std::min(n, int(sizeof line) - 1)));
    shown_ = true;
}

}  // namespace pqdc_app
