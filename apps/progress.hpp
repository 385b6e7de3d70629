// The progress line of the apps (pqdc, pqdc-mpi's rank 0, pqdc-decimate, pqdc-bricks) on a
// terminal: one line, redrawn by a ticker thread every
// 100 ms from the first 0.2 s of the run, through reading (the reader's
// offset in the file, from /proc/self/fdinfo, against its size), meshing (the
// library's progress callback) and writing (bytes written against the
// file's expected size). Off a terminal it prints nothing (unless forced).
// Log lines go through log() so they never interleave with the line.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>

namespace pqdc_app {

class Progress {
public:
    /// enabled: draw the line at all. The line goes to a duplicate of
    /// stderr, so it keeps showing while stderr itself is silenced. Lines
    /// start with "program: ".
    explicit Progress(bool enabled, std::string program = "pqdc");
    ~Progress();
    Progress(const Progress&) = delete;
    Progress& operator=(const Progress&) = delete;

    /// Starts a stage: "reading 'a.vdb'" with the fraction taken from the
    /// reader's offset in `path` against total_bytes.
    void reading(const std::string& what, const std::string& path, std::uint64_t total_bytes);
    /// Starts a stage whose fraction the caller sets with set().
    void stage(const std::string& what);
    void set(double fraction) { fraction_.store(fraction, std::memory_order_relaxed); }
    /// Prints "program: LINE" on stderr (unless quiet), clearing the progress line first.
    void log(const std::string& line, bool quiet);
    /// Clears the line and stops drawing.
    void finish();

private:
    void run();
    void draw_locked(bool final_clear);

    bool enabled_;
    std::string program_;
    int fd_ = -1;
    std::mutex mutex_;
    std::condition_variable wake_;
    bool stop_ = false, shown_ = false;
    std::string what_;
    bool from_io_ = false;
    std::string io_path_;
    std::uint64_t io_total_ = 1;
    std::atomic<double> fraction_{0.0};
    std::thread thread_;
};

}  // namespace pqdc_app
