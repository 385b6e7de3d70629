#include "sandbox.hpp"

#include "job.hpp"
#include "signals.hpp"
#include "supervision.hpp"

#include <fcntl.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <iostream>
#include <limits>
#include <vector>

#if defined(__SANITIZE_ADDRESS__)
#define PQDC_CLI_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define PQDC_CLI_ASAN 1
#endif
#endif

namespace pqdc_app {
namespace {

std::size_t physical_memory_bytes() {
    const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGE_SIZE);
    if (pages <= 0 || page <= 0) return std::numeric_limits<std::size_t>::max();
    return std::size_t(pages) * std::size_t(page);
}

// Below a few MiB, blosc and OpenVDB's first allocations fail in code that
// does not expect it; a --memory-limit that small is enforced by the
// extractor's estimate instead, with a clear message.
constexpr std::size_t kReaderMinimumBytes = std::size_t(64) << 20;

std::string mib(std::size_t bytes) { return std::to_string((bytes + (1u << 20) - 1) >> 20) + " MiB"; }

/// How much the reader may allocate. OpenVDB data does not expand much when
/// read: masks are stored raw, so an 8^3 leaf (>= ~130 bytes on disk) or an
/// internal node (>= 1 KiB of masks) takes at most ~40x its file size in
/// memory; 256x the file size plus 1 GiB is a generous ceiling that still
/// stops a corrupt 100 KiB file from allocating 10 GiB.
std::size_t read_budget(const std::string& path, std::size_t memory_limit_bytes, bool& from_file_size) {
    std::size_t bytes = memory_limit_bytes ? memory_limit_bytes : std::size_t(double(physical_memory_bytes()) * 0.8);
    bytes = std::max(bytes, kReaderMinimumBytes);
    from_file_size = false;
    struct stat st {};
    if (::stat(path.c_str(), &st) == 0 && st.st_size > 0) {
        const double ceiling = 256.0 * double(st.st_size) + double(std::size_t(1) << 30);
        if (ceiling < double(bytes)) {
            bytes = std::size_t(ceiling);
            from_file_size = true;
        }
    }
    return bytes;
}

void set_address_space_limit(std::size_t extra_bytes) {
#ifndef PQDC_CLI_ASAN  // ASan reserves terabytes of shadow address space; no limit there
    long pages = 0;
    if (std::FILE* f = std::fopen("/proc/self/statm", "r")) {
        if (std::fscanf(f, "%ld", &pages) != 1) pages = 0;
        std::fclose(f);
    }
    const double wanted = double(pages) * double(::sysconf(_SC_PAGE_SIZE)) + double(extra_bytes);
    if (wanted < double(std::numeric_limits<rlim_t>::max()) * 0.5) {
        struct rlimit rl {};
        ::getrlimit(RLIMIT_AS, &rl);
        if (rl.rlim_cur == RLIM_INFINITY || rlim_t(wanted) < rl.rlim_cur) {
            rl.rlim_cur = rlim_t(wanted);
            ::setrlimit(RLIMIT_AS, &rl);
        }
    }
#else
    (void)extra_bytes;
#endif
}

void lift_address_space_limit() {
#ifndef PQDC_CLI_ASAN
    struct rlimit rl {};
    ::getrlimit(RLIMIT_AS, &rl);
    rl.rlim_cur = rl.rlim_max;
    ::setrlimit(RLIMIT_AS, &rl);
#endif
}

[[noreturn]] void terminate_in_reader() {
    int code = kExitTerminated;
    if (const std::exception_ptr e = std::current_exception()) {
        try {
            std::rethrow_exception(e);
        } catch (const std::bad_alloc&) {
            code = kExitOutOfMemory;
        } catch (...) {
        }
    }
    ::_exit(code);
}

}  // namespace

void SupervisorLink::entering_reader(const std::string& display_name, const std::string& out_of_memory) {
    if (fd_ >= 0) send_message(fd_, Message::enter_reader, {out_of_memory, display_name});
}

void SupervisorLink::leaving_reader() {
    if (fd_ >= 0) send_message(fd_, Message::leave_reader);
}

void SupervisorLink::writing(const std::vector<std::string>& paths) {
    if (fd_ >= 0) send_message(fd_, Message::outputs, paths);
}

ReaderSandbox::ReaderSandbox(SupervisorLink& link, const std::string& path, const std::string& display_name,
                             std::size_t memory_limit_bytes)
    : link_(link) {
    bool from_file_size = false;
    const std::size_t budget = read_budget(path, memory_limit_bytes, from_file_size);
    oom_ = "reading " + display_name + " needs more than " + mib(budget) +
           (from_file_size
                ? "; a valid OpenVDB file of this size never needs that much, so the file is corrupt (a size "
                  "field holds garbage): re-export it or check that the copy is complete"
                : "; give a higher --memory-limit if the machine has the memory, or check the file: it may be "
                  "corrupt");
    link_.entering_reader(display_name, oom_);
    std::cerr.flush();
#ifndef PQDC_CLI_ASAN
    saved_stderr_ = ::fcntl(STDERR_FILENO, F_DUPFD_CLOEXEC, 3);
    if (const int null = ::open("/dev/null", O_WRONLY | O_CLOEXEC); null >= 0 && saved_stderr_ >= 0) {
        set_interrupt_message_fd(saved_stderr_);
        ::dup2(null, STDERR_FILENO);
        ::close(null);
    }
#endif
    std::set_terminate(terminate_in_reader);
    set_address_space_limit(budget);
}

ReaderSandbox::~ReaderSandbox() {
    lift_address_space_limit();
    std::set_terminate(nullptr);
    if (saved_stderr_ >= 0) {
        ::dup2(saved_stderr_, STDERR_FILENO);
        set_interrupt_message_fd(STDERR_FILENO);
        ::close(saved_stderr_);
    }
    link_.leaving_reader();
}

bool is_job_child(int argc, char** argv) { return argc > 2 && std::strcmp(argv[1], kJobArgument) == 0; }

int job_child_main(int argc, char** argv) {
    // pqdc --internal-job FD PARENT ARGS...
    if (argc < 4) return 2;
    const int fd = std::atoi(argv[2]);
    if (::getppid() != pid_t(std::atol(argv[3]))) ::_exit(3);  // the supervisor died before PDEATHSIG took hold
    install_signal_handlers();
    std::vector<char*> args{argv[0]};
    args.insert(args.end(), argv + 4, argv + argc);
    args.push_back(nullptr);
    SupervisorLink link(fd);
    return run_main(int(args.size()) - 1, args.data(), link);
}

}  // namespace pqdc_app
