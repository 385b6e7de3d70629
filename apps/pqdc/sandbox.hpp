// The corrupt-file guarantee. OpenVDB's reader trusts the sizes and masks in
// a file: a flipped bit can make it overflow a heap buffer
// (io::bloscFromStream reads a chunk of the size stored in the file into a
// buffer of the expected size and only then compares the two) or copy a
// metadata string of gigabytes. So a .vdb run does its whole job (read,
// mesh, write) in a child process, and the parent only supervises: the child
// reads under an address-space limit, tells the parent when it enters and
// leaves the reader, and the parent turns a crash or a blown limit inside
// the reader into an error naming the file, and removes any temporary file
// the child left. The grid is parsed once, in the child; nothing is copied
// back.
//
// The child is this executable started afresh (fork, then exec of
// /proc/self/exe with a hidden first argument), never a bare fork: loading
// libopenvdb starts log4cplus's thread pool, so pqdc is multithreaded from
// its first line, and a forked copy that allocates can deadlock on a lock one
// of those threads held at the fork.
#pragma once

#include "options.hpp"

#include <cstddef>
#include <string>

namespace pqdc_app {

/// The child's end of the link to the supervisor (none when pqdc runs
/// without one, e.g. for procedural fields).
class SupervisorLink {
public:
    explicit SupervisorLink(int fd = -1) : fd_(fd) {}
    /// Entering OpenVDB's reader for `path`; `out_of_memory` is what the
    /// parent prints if the reader blows its memory budget.
    void entering_reader(const std::string& out_of_memory);
    void leaving_reader();

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

/// True when argv asks for the supervised child; job_child_main runs it.
bool is_job_child(int argc, char** argv);
int job_child_main(int argc, char** argv);

/// Runs the job in a supervised child and returns the exit code to use.
int supervise(int argc, char** argv, const CliOptions& options);

}  // namespace pqdc_app
