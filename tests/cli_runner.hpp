// Test helpers: run the real pqdc binary with controlled limits and signals,
// and scratch directories to check that nothing is left behind.
#pragma once

#include "test_files.hpp"

#include <fcntl.h>
#include <grp.h>
#include <poll.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <map>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace pqdc_test {

struct RunSpec {
    std::vector<std::string> args;  ///< after the program name
    std::string cwd;                ///< working directory of the child; empty = inherit
    double signal_after_seconds = -1;  ///< send `signal` this long after the start (< 0: never)
    int signal = SIGINT;
    double kill_after_seconds = 300;  ///< SIGKILL and report timed_out: a hang guard, not a speed target
    long file_size_limit_bytes = -1;  ///< RLIMIT_FSIZE for the child (< 0: unchanged)
    /// Drop to uid/gid 65534 (only when running as root, whom permissions do
    /// not bind). The program then runs from a copy in a world-enterable
    /// temporary directory (reachable_copy), so that the test works wherever
    /// the checkout lives, a directory only root can enter included; cwd must
    /// then be a ScratchLocation::world_reachable directory.
    bool as_nobody = false;
};

/// A copy of `program` and the build tree's shared libraries (libpqdc*) in
/// a world-enterable temporary directory, made once per program; the copy
/// finds the libraries through LD_LIBRARY_PATH, which run_program sets.
/// Returns {program copy, library directory}.
inline std::pair<std::string, std::string> reachable_copy(const std::string& program) {
    namespace fs = std::filesystem;
    static std::map<std::string, std::pair<std::string, std::string>> made;
    const auto known = made.find(program);
    if (known != made.end()) return known->second;
    const fs::path root = fs::temp_directory_path() /
                          ("pqdc-reachable-" + std::to_string(::getuid()) + "-" + std::to_string(::getpid()));
    const fs::path bin = root / "bin", lib = root / "lib";
    fs::create_directories(bin);
    fs::create_directories(lib);
    for (const fs::path& d : {root, bin, lib})
        fs::permissions(d, fs::perms::owner_all | fs::perms::group_read | fs::perms::group_exec |
                               fs::perms::others_read | fs::perms::others_exec);
    for (const auto& e : fs::directory_iterator(fs::path(PQDC_BINARY_DIR) / "src")) {
        const std::string name = e.path().filename().string();
        if (name.rfind("libpqdc", 0) == 0 && name.find(".so") != std::string::npos)
            fs::copy_file(e.path(), lib / name, fs::copy_options::overwrite_existing);  // follows symlinks
    }
    const auto world = fs::perms::owner_all | fs::perms::group_read | fs::perms::group_exec |
                       fs::perms::others_read | fs::perms::others_exec;
    const fs::path copy = bin / fs::path(program).filename();
    fs::copy_file(program, copy, fs::copy_options::overwrite_existing);
    fs::permissions(copy, world);
    // pqdc runs its worker from a path relative to its own (apps/CMakeLists.txt):
    // the build tree's layout below `root`, from libexec up.
    const fs::path build = fs::path(PQDC_BINARY_DIR), libexec = build / "libexec";
    if (fs::exists(libexec))
        for (const auto& e : fs::recursive_directory_iterator(libexec)) {
            const fs::path to = root / fs::relative(e.path(), build);
            if (e.is_directory()) fs::create_directories(to);
            else fs::copy_file(e.path(), to, fs::copy_options::overwrite_existing);
            fs::permissions(to, world);
        }
    return made[program] = {copy.string(), lib.string()};
}

struct RunResult {
    int exit_code = -1;  ///< -1 when killed by a signal
    int term_signal = 0;
    bool timed_out = false;
    std::string out, err;
};

inline RunResult run_program(const std::string& program_path, const RunSpec& spec) {
    const bool drop = spec.as_nobody && ::geteuid() == 0;
    std::string program = program_path;
    std::vector<std::string> env_s;
    for (char** e = environ; *e; ++e) env_s.emplace_back(*e);
    if (drop) {
        const auto [copy, lib] = reachable_copy(program_path);
        program = copy;
        env_s.erase(std::remove_if(env_s.begin(), env_s.end(),
                                   [](const std::string& v) { return v.rfind("LD_LIBRARY_PATH=", 0) == 0; }),
                    env_s.end());
        env_s.push_back("LD_LIBRARY_PATH=" + lib);
    }
    std::vector<char*> envp;
    for (auto& v : env_s) envp.push_back(v.data());
    envp.push_back(nullptr);
    std::vector<std::string> argv_s{program};
    argv_s.insert(argv_s.end(), spec.args.begin(), spec.args.end());
    std::vector<char*> argv;
    for (auto& a : argv_s) argv.push_back(a.data());
    argv.push_back(nullptr);

    int out_pipe[2], err_pipe[2];
    if (::pipe2(out_pipe, O_CLOEXEC) != 0 || ::pipe2(err_pipe, O_CLOEXEC) != 0) throw std::runtime_error("pipe");
    const pid_t pid = ::fork();
    if (pid < 0) throw std::runtime_error("fork");
    if (pid == 0) {
        // Only async-signal-safe calls from here to exec: the test runner has threads.
        ::dup2(out_pipe[1], 1);
        ::dup2(err_pipe[1], 2);
        if (!spec.cwd.empty() && ::chdir(spec.cwd.c_str()) != 0) ::_exit(126);
        struct sigaction sa {};
        sa.sa_handler = SIG_DFL;
        ::sigaction(SIGINT, &sa, nullptr);
        ::sigaction(SIGTERM, &sa, nullptr);
        ::sigaction(SIGXFSZ, &sa, nullptr);
        ::sigaction(SIGPIPE, &sa, nullptr);
        sigset_t none;
        sigemptyset(&none);
        ::sigprocmask(SIG_SETMASK, &none, nullptr);
        if (spec.file_size_limit_bytes >= 0) {
            struct rlimit rl {};
            rl.rlim_cur = rl.rlim_max = rlim_t(spec.file_size_limit_bytes);
            ::setrlimit(RLIMIT_FSIZE, &rl);
        }
        if (drop && (::setgroups(0, nullptr) != 0 || ::setgid(65534) != 0 || ::setuid(65534) != 0)) ::_exit(125);
        ::execve(argv[0], argv.data(), envp.data());
        ::_exit(127);
    }
    ::close(out_pipe[1]);
    ::close(err_pipe[1]);
    RunResult r;
    const auto t0 = std::chrono::steady_clock::now();
    bool signalled = false, killed = false;
    struct pollfd fds[2] = {{out_pipe[0], POLLIN, 0}, {err_pipe[0], POLLIN, 0}};
    std::string* sinks[2] = {&r.out, &r.err};
    int open_fds = 2;
    while (open_fds > 0) {
        const int n = ::poll(fds, 2, 20);
        if (n < 0 && errno != EINTR) break;
        for (int i = 0; i < 2; ++i) {
            if (fds[i].fd < 0 || !(fds[i].revents & (POLLIN | POLLHUP | POLLERR))) continue;
            char buf[65536];
            const ssize_t got = ::read(fds[i].fd, buf, sizeof buf);
            if (got > 0) sinks[i]->append(buf, std::size_t(got));
            else if (got == 0 || errno != EINTR) {
                ::close(fds[i].fd);
                fds[i].fd = -1;
                --open_fds;
            }
        }
        const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        if (!signalled && spec.signal_after_seconds >= 0 && t >= spec.signal_after_seconds) {
            ::kill(pid, spec.signal);
            signalled = true;
        }
        if (!killed && t >= spec.kill_after_seconds) {
            ::kill(pid, SIGKILL);
            killed = true;
            r.timed_out = true;
        }
    }
    for (auto& f : fds)
        if (f.fd >= 0) ::close(f.fd);
    int status = 0;
    while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
    }
    if (WIFEXITED(status)) r.exit_code = WEXITSTATUS(status);
    if (WIFSIGNALED(status)) r.term_signal = WTERMSIG(status);
    return r;
}

enum class ScratchLocation {
    build_tree,       ///< under the build tree (kept for inspection after a failure)
    world_reachable,  ///< under the system temporary directory, enterable by every user (RunSpec::as_nobody)
};

/// A fresh, empty directory.
class ScratchDir {
public:
    explicit ScratchDir(const std::string& name, ScratchLocation where = ScratchLocation::build_tree)
        : dir_(root(where) + "/" + name) {
        std::filesystem::remove_all(dir_);
        std::filesystem::create_directories(dir_);
    }
    std::string path(const std::string& file) const { return dir_ + "/" + file; }
    const std::string& dir() const { return dir_; }
    /// Names of the directory's entries, sorted.
    std::vector<std::string> entries() const {
        std::vector<std::string> names;
        for (const auto& e : std::filesystem::directory_iterator(dir_)) names.push_back(e.path().filename().string());
        std::sort(names.begin(), names.end());
        return names;
    }

private:
    static std::string root(ScratchLocation where) {
        namespace fs = std::filesystem;
        if (where == ScratchLocation::build_tree) return std::string(PQDC_BINARY_DIR) + "/test_robust";
        const fs::path r = fs::temp_directory_path() /
                           ("pqdc-scratch-" + std::to_string(::getuid()) + "-" + std::to_string(::getpid()));
        fs::create_directories(r);
        fs::permissions(r, fs::perms::owner_all | fs::perms::group_read | fs::perms::group_exec |
                               fs::perms::others_read | fs::perms::others_exec);
        return r.string();
    }
    std::string dir_;
};

}  // namespace pqdc_test
