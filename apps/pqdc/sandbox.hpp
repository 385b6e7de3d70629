// The corrupt-file guarantee. OpenVDB's reader trusts the sizes and masks in
// a file: a flipped bit can make it overflow a heap buffer
// (io::bloscFromStream reads a chunk of the size stored in the file into a
// buffer of the expected size and only then compares the two) or copy a
// metadata string of gigabytes. So a run does its whole job (read, mesh,
// write) in a worker process, pqdc-job, and pqdc only supervises
// (launcher.cpp): the worker reads under an address-space limit and tells
// the supervisor when it enters and leaves the reader (supervision.hpp), and
// the supervisor turns a crash or a blown limit inside the reader into an
// error naming the file, and removes any named temporary file the worker
// left. The grid is parsed once, in the worker; nothing is copied back.
//
// The worker is a program of its own (fork, then exec), never a bare fork:
// loading libopenvdb starts log4cplus's thread pool, so a program linked
// with it is multithreaded from its first line, and a forked copy that
// allocates can deadlock on a lock one of those threads held at the fork.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

namespace pqdc_app {

/// The child's end of the link to the supervisor (none when pqdc runs
/// without one, e.g. for procedural fields).
class SupervisorLink {
public:
    explicit SupervisorLink(int fd = -1) : fd_(fd) {}
    /// Entering OpenVDB's reader for the file messages call `display_name`;
    /// `out_of_memory` is what the supervisor prints if the reader blows its
    /// memory budget.
    void entering_reader(const std::string& display_name, const std::string& out_of_memory);
    void leaving_reader();
    /// The files the run may write (-o and --stats, patterns included).
    void writing(const std::vector<std::string>& paths);

private:
    int fd_;
};

/// RAII for one read: announces it, silences stderr (glibc's "malloc():
/// corrupted ..." lines would only repeat what the parent reports), limits
/// the address space to the budget, and makes a bad_alloc escaping from a
/// noexcept corner of OpenVDB exit with a code the parent understands.
class ReaderSandbox {
public:
    ReaderSandbox(SupervisorLink& link, const std::string& path, const std::string& display_name,
                  std::size_t memory_limit_bytes);
    ~ReaderSandbox();
    /// The message for a reader that ran out of its budget.
    const std::string& out_of_memory_message() const { return oom_; }

private:
    SupervisorLink& link_;
    std::string oom_;
    int saved_stderr_ = -1;
};

/// True when argv asks for the supervised worker (supervision.hpp);
/// job_child_main runs it.
bool is_job_child(int argc, char** argv);
int job_child_main(int argc, char** argv);

}  // namespace pqdc_app
