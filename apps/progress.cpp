#include "progress.hpp"

#include <dirent.h>
#include <fcntl.h>
#include <stdlib.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <utility>

namespace pqdc_app {
namespace {

/// How far into `path` this process's reader is: the largest file offset
/// among its descriptors open on that file (/proc/self/fdinfo "pos:"), 0
/// when none is open. OpenVDB reads through 8 KiB buffers and seeks back
/// and forth, so bytes read (rchar) run ahead of the position ~10x.
std::uint64_t read_position(const std::string& path) {
    std::uint64_t best = 0;
    DIR* d = ::opendir("/proc/self/fd");
    if (!d) return 0;
    while (const dirent* e = ::readdir(d)) {
        if (e->d_name[0] == '.') continue;
        char link[4096];
        const std::string fd_path = std::string("/proc/self/fd/") + e->d_name;
        const ssize_t n = ::readlink(fd_path.c_str(), link, sizeof link - 1);
        if (n <= 0 || std::string(link, std::size_t(n)) != path) continue;
        if (std::FILE* f = std::fopen((std::string("/proc/self/fdinfo/") + e->d_name).c_str(), "r")) {
            unsigned long long pos = 0;
            if (std::fscanf(f, "pos: %llu", &pos) == 1) best = std::max<std::uint64_t>(best, pos);
            std::fclose(f);
        }
    }
    ::closedir(d);
    return best;
}

}  // namespace

Progress::Progress(bool enabled, std::string program) : enabled_(enabled), program_(std::move(program)) {
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

void Progress::reading(const std::string& what, const std::string& path, std::uint64_t total_bytes) {
    std::lock_guard<std::mutex> lock(mutex_);
    what_ = what;
    from_io_ = true;
    char* real = ::realpath(path.c_str(), nullptr);
    io_path_ = real ? real : path;
    std::free(real);
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
    if (!quiet) std::cerr << program_ << ": " << line << std::endl;
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
    if (from_io_) f = double(read_position(io_path_)) / double(io_total_);
    f = std::clamp(f, 0.0, 1.0);
    char line[512];
    const int n = std::snprintf(line, sizeof line, "\r%.40s: %.200s %3d%%\033[K", program_.c_str(), what_.c_str(),
                                int(f * 100.0));
    if (n > 0) (void)!::write(fd_, line, std::size_t(std::min(n, int(sizeof line) - 1)));
    shown_ = true;
}

}  // namespace pqdc_app
