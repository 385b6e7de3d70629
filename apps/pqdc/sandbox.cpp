#include "sandbox.hpp"

#include "job.hpp"
#include "signals.hpp"

#include "pqdc/exceptions.hpp"

#include "../cli_util.hpp"

#include <dirent.h>
#include <fcntl.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <iostream>
#include <limits>
#include <set>
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

constexpr const char* kJobArgument = "--internal-job";
constexpr int kExitOutOfMemory = 5, kExitTerminated = 6, kExitNoExec = 127;
constexpr char kEnter = 'R', kLeave = 'D';

void write_all(int fd, const void* data, std::size_t n) {
    const char* p = static_cast<const char*>(data);
    while (n > 0) {
        const ssize_t w = ::write(fd, p, n);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) return;  // the supervisor is gone; PDEATHSIG ends us
        p += w, n -= std::size_t(w);
    }
}

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

std::string describe_wait_status(int status) {
    if (WIFSIGNALED(status)) {
        const int sig = WTERMSIG(status);
        const char* name = ::strsignal(sig);
        return std::string("signal ") + std::to_string(sig) + (name ? std::string(", ") + name : std::string());
    }
    if (WIFEXITED(status)) return "exit code " + std::to_string(WEXITSTATUS(status));
    return "unknown status";
}

std::atomic<pid_t> g_child{0};

extern "C" void forward_signal(int sig) {
    const pid_t child = g_child.load();
    if (child > 0) ::kill(child, sig);
}

/// Removes the temporaries ("NAME.tmp-<pid>-<random>") a dead child left in
/// the directories of the run's outputs.
void remove_child_temporaries(const CliOptions& o, pid_t child) {
    const std::string marker = ".tmp-" + std::to_string(child) + "-";
    std::set<std::string> dirs;
    for (const std::string& path : {o.output, o.stats_path}) {
        if (path.empty() || path == "-") continue;
        const std::size_t slash = path.find_last_of('/');
        dirs.insert(slash == std::string::npos ? "." : (slash == 0 ? "/" : path.substr(0, slash)));
    }
    for (const std::string& dir : dirs) {
        DIR* d = ::opendir(dir.c_str());
        if (!d) continue;
        std::vector<std::string> doomed;
        while (const dirent* e = ::readdir(d))
            if (std::strstr(e->d_name, marker.c_str())) doomed.push_back(dir + "/" + e->d_name);
        ::closedir(d);
        for (const auto& f : doomed) ::unlink(f.c_str());
    }
}

std::string input_name(const CliOptions& o) { return o.input == "-" ? "standard input" : "'" + o.input + "'"; }

}  // namespace

void SupervisorLink::entering_reader(const std::string& out_of_memory) {
    if (fd_ < 0) return;
    const std::uint32_t n = std::uint32_t(out_of_memory.size());
    std::string msg(1, kEnter);
    msg.append(reinterpret_cast<const char*>(&n), 4);
    msg += out_of_memory;
    write_all(fd_, msg.data(), msg.size());
}

void SupervisorLink::leaving_reader() {
    if (fd_ >= 0) write_all(fd_, &kLeave, 1);
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
    link_.entering_reader(oom_);
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

int supervise(int argc, char** argv, const CliOptions& o) {
    int fds[2];
    if (::pipe2(fds, O_CLOEXEC) != 0)
        throw pqdc::resource_error(std::string("cannot start pqdc's worker process: pipe: ") + std::strerror(errno));
    std::cout.flush();
    std::cerr.flush();
    // Everything the child needs is built before the fork: between fork and
    // exec only async-signal-safe calls are allowed.
    std::vector<std::string> args{argv[0], kJobArgument, std::to_string(fds[1]), std::to_string(::getpid())};
    args.insert(args.end(), argv + 1, argv + argc);
    std::vector<char*> cargs;
    for (auto& a : args) cargs.push_back(a.data());
    cargs.push_back(nullptr);
    const pid_t pid = ::fork();
    if (pid < 0) {
        const int err = errno;
        ::close(fds[0]);
        ::close(fds[1]);
        throw pqdc::resource_error(std::string("cannot start pqdc's worker process: fork: ") + std::strerror(err));
    }
    if (pid == 0) {
        ::prctl(PR_SET_PDEATHSIG, SIGKILL);  // die with an interrupted or killed pqdc
        ::fcntl(fds[1], F_SETFD, 0);          // the write end survives exec, the read end does not
        ::execv("/proc/self/exe", cargs.data());
        ::_exit(kExitNoExec);
    }
    ::close(fds[1]);
    // Ctrl-C reaches both processes; a signal sent to pqdc alone is passed on.
    g_child.store(pid);
    struct sigaction sa {};
    sa.sa_handler = forward_signal;
    sigemptyset(&sa.sa_mask);
    sa.sa_flags = SA_RESTART;
    sigaction(SIGINT, &sa, nullptr);
    sigaction(SIGTERM, &sa, nullptr);
    std::signal(SIGXFSZ, SIG_IGN);

    bool in_reader = false;
    std::string out_of_memory;
    for (;;) {
        char kind = 0;
        const ssize_t n = ::read(fds[0], &kind, 1);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) break;
        if (kind == kLeave) {
            in_reader = false;
        } else if (kind == kEnter) {
            std::uint32_t len = 0;
            std::size_t got = 0;
            while (got < 4) {
                const ssize_t r = ::read(fds[0], reinterpret_cast<char*>(&len) + got, 4 - got);
                if (r < 0 && errno == EINTR) continue;
                if (r <= 0) break;
                got += std::size_t(r);
            }
            out_of_memory.assign(std::min<std::uint32_t>(len, 1u << 16), '\0');
            got = 0;
            while (got < out_of_memory.size()) {
                const ssize_t r = ::read(fds[0], &out_of_memory[got], out_of_memory.size() - got);
                if (r < 0 && errno == EINTR) continue;
                if (r <= 0) break;
                got += std::size_t(r);
            }
            in_reader = true;
        }
    }
    ::close(fds[0]);
    int status = 0;
    while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
    }
    g_child.store(0);
    if (WIFEXITED(status) && WEXITSTATUS(status) == kExitNoExec)
        throw pqdc::resource_error("cannot start pqdc's worker process: exec of /proc/self/exe failed; is /proc mounted?");
    const bool normal = WIFEXITED(status) && !(in_reader && (WEXITSTATUS(status) == kExitOutOfMemory ||
                                                              WEXITSTATUS(status) == kExitTerminated));
    if (normal) return WEXITSTATUS(status);
    remove_child_temporaries(o, pid);
    if (in_reader && WIFEXITED(status) && WEXITSTATUS(status) == kExitOutOfMemory)
        throw pqdc::resource_error(out_of_memory);
    if (in_reader && WIFSIGNALED(status) && (WTERMSIG(status) == SIGINT || WTERMSIG(status) == SIGTERM))
        return interrupted_exit(WTERMSIG(status));
    if (in_reader)
        throw pqdc::input_error(input_name(o) + " is corrupt: OpenVDB's reader crashed on it (" +
                                describe_wait_status(status) +
                                "); re-export the file or check that the copy is complete");
    throw std::runtime_error("internal error: the meshing process ended abnormally (" + describe_wait_status(status) +
                             "); nothing was written. Please report this with the input and options");
}

}  // namespace pqdc_app
