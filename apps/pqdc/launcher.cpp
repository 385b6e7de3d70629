// pqdc: the supervisor. It starts pqdc-job (apps/pqdc/job_main.cpp), which
// parses the options, reads, meshes and writes, and only watches it: the
// corrupt-file guarantee (sandbox.hpp) needs a process that outlives a
// worker whose OpenVDB reader crashed, to say which file did it.
//
// It links neither pqdc nor OpenVDB. Loading OpenVDB costs a process about
// 35 ms (its 69 k relocations), which the worker pays once; a supervisor
// built like the worker paid it a second time, before the worker even
// started (about 8% of a whole run on a 2.5 M-voxel level set).
//
// Exit codes: the worker's (0 ok, 1 runtime error, 2 usage error, 128 +
// signal when interrupted); 1 when the worker could not be started, crashed
// in the reader (an error naming the file) or ended abnormally.
#include "supervision.hpp"

#include <dirent.h>
#include <fcntl.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <climits>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <set>
#include <string>
#include <vector>

#ifndef PQDC_JOB_FROM_BIN
#error "PQDC_JOB_FROM_BIN: the worker's path relative to pqdc's directory (apps/CMakeLists.txt)"
#endif

namespace {

using namespace pqdc_app;

std::atomic<pid_t> g_worker{0};

/// Ctrl-C reaches both processes (one process group); a signal sent to pqdc
/// alone is passed on, and the worker's handler reports it.
extern "C" void forward_signal(int sig) {
    const pid_t worker = g_worker.load();
    if (worker > 0) ::kill(worker, sig);
}

int fail(const std::string& message) {
    std::fprintf(stderr, "pqdc: %s\n", message.c_str());
    return 1;
}

/// pqdc-job's path: PQDC_JOB_FROM_BIN from this executable's directory, the
/// same in the build tree and in an installed prefix.
bool job_path(std::string& path) {
    char self[PATH_MAX];
    const ssize_t n = ::readlink("/proc/self/exe", self, sizeof self - 1);
    if (n <= 0) return false;
    self[n] = '\0';
    std::string dir(self);
    dir.erase(dir.find_last_of('/'));
    path = dir + "/" + PQDC_JOB_FROM_BIN;
    return true;
}

/// The glibc malloc tunables the worker starts with (glibc reads them only
/// when a program starts, hence here), each unless the user's own
/// GLIBC_TUNABLES names it; other tunables are kept. A run spends much of
/// its time on first-touch page faults of fresh memory: the grid's leaves,
/// the per-leaf results of stage "cells", the mesh's arrays (README, "How
/// the time is kept down"). Neither changes a byte of output.
/// - hugetlb=1: the heap and large blocks on transparent huge pages, one
///   fault per 2 MiB instead of per 4 KiB. A 12.7 M-voxel sphere's whole run
///   went 1.45x faster on a 2-core VM.
/// - top_pad=64 MiB: the pad at least the size of a thread arena's heap
///   (HEAP_MAX_SIZE, 64 MiB on 64-bit), so each heap is made writable whole
///   when it is created instead of page by page as it grows, and huge pages
///   can back it too: the worker threads' own allocations (the leaves as
///   they are decoded, stage "cells"' records and vertices) faulted per
///   4 KiB before. The sphere: 33-44 k page faults -> 9-11 k, whole run
///   0.79x the time. The price: glibc then keeps a thread heap's free top
///   (at most 64 MiB a thread, and no more than that thread's share of what
///   stage "cells" held) rather than returning it; peak RSS rose by 0-24 MiB
///   on the bench volumes, within the run-to-run spread at 8 and 16 threads.
std::vector<std::string> worker_environment() {
    static const char* const kTunables[][2] = {{"glibc.malloc.hugetlb", "1"}, {"glibc.malloc.top_pad", "67108864"}};
    static const std::string kVariable = "GLIBC_TUNABLES=";
    auto add_missing = [](std::string& entry) {
        for (const auto& [name, value] : kTunables)
            if (entry.find(name) == std::string::npos)
                entry += std::string(entry.size() > kVariable.size() ? ":" : "") + name + "=" + value;
    };
    std::vector<std::string> env;
    bool tunables = false;
    for (char** e = environ; *e; ++e) {
        std::string entry = *e;
        if (entry.rfind(kVariable, 0) == 0) {
            tunables = true;
            add_missing(entry);
        }
        env.push_back(std::move(entry));
    }
    if (!tunables) {
        env.push_back(kVariable);
        add_missing(env.back());
    }
    return env;
}

std::string describe_wait_status(int status) {
    if (WIFSIGNALED(status)) {
        const int sig = WTERMSIG(status);
        const char* name = ::strsignal(sig);
        return "signal " + std::to_string(sig) + (name ? std::string(", ") + name : std::string());
    }
    if (WIFEXITED(status)) return "exit code " + std::to_string(WEXITSTATUS(status));
    return "unknown status";
}

/// Removes the named temporaries ("NAME.tmp-<pid>-<random>") a dead worker
/// left next to its outputs. Only where the file system lacks O_TMPFILE
/// does a worker write named ones (src/io/atomic_file.hpp).
void remove_worker_temporaries(const std::vector<std::string>& outputs, pid_t worker) {
    const std::string marker = ".tmp-" + std::to_string(worker) + "-";
    std::set<std::string> dirs;
    for (const std::string& path : outputs) {
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

/// Signals a process raises itself by faulting or aborting; every other
/// signal that ends the worker was sent to it.
bool is_crash_signal(int sig) {
    return sig == SIGSEGV || sig == SIGBUS || sig == SIGFPE || sig == SIGILL || sig == SIGABRT || sig == SIGSYS ||
           sig == SIGTRAP;
}

/// What the worker said before it ended.
struct Watched {
    bool in_reader = false;
    std::string out_of_memory;  ///< the reader's message for a blown memory budget
    std::string file;           ///< the file being read, as messages name it
    std::vector<std::string> outputs;
};

Watched watch(int fd) {
    Watched w;
    Message kind{};
    std::vector<std::string> texts;
    while (receive_message(fd, kind, texts)) {
        if (kind == Message::leave_reader) {
            w.in_reader = false;
        } else if (kind == Message::enter_reader && texts.size() == 2) {
            w.in_reader = true;
            w.out_of_memory = texts[0];
            w.file = texts[1];
        } else if (kind == Message::outputs) {
            w.outputs = texts;
        }
    }
    return w;
}

/// The exit code for the worker's end, with a message where the worker
/// could not give one.
/// `by_bricks`: the command line asked for an out-of-core run already.
int outcome(const Watched& w, int status, pid_t worker, const std::string& job, bool by_bricks) {
    if (WIFEXITED(status) && WEXITSTATUS(status) == kExitNoExec)
        return fail("cannot start pqdc's worker program '" + job +
                    "' (exec failed); is the installation complete? It belongs next to pqdc at " + PQDC_JOB_FROM_BIN);
    // Inside the reader the worker ends only by a signal, by its own codes
    // (interrupted, out of memory, terminated) or by a sanitizer's halt
    // (exit code 1 after its report): all but an interrupt mean the reader died.
    const bool interrupted =
        WIFEXITED(status) && (WEXITSTATUS(status) == 128 + SIGINT || WEXITSTATUS(status) == 128 + SIGTERM);
    const bool reader_died = w.in_reader && !interrupted;
    if (WIFEXITED(status) && !reader_died) return WEXITSTATUS(status);
    remove_worker_temporaries(w.outputs, worker);
    if (w.in_reader && WIFEXITED(status) && WEXITSTATUS(status) == kExitOutOfMemory) return fail(w.out_of_memory);
    if (WIFSIGNALED(status) && (WTERMSIG(status) == SIGINT || WTERMSIG(status) == SIGTERM)) {
        // Interrupted before the worker's own handler was in place (its
        // first few milliseconds), or in the reader: it could not say so.
        if (!w.in_reader) std::fputs(kInterruptedNothingWritten, stderr);
        return 128 + WTERMSIG(status);
    }
    if (WIFSIGNALED(status) && !is_crash_signal(WTERMSIG(status))) {
        // SIGKILL, SIGXCPU, SIGHUP...: sent from outside, not a fault of the
        // input or of pqdc; the exit code is the shell's for a killed program.
        fail("pqdc's meshing process was stopped from outside (" + describe_wait_status(status) +
             "); nothing was written. SIGKILL usually comes from the out-of-memory killer (dmesg shows it; " +
             std::string(by_bricks ? "lower --memory-limit, which also bounds the bricks in flight, or --brick-runs"
                                   : "lower --memory-limit or add --out-of-core") +
             ") or a batch system's time or memory limit");
        return 128 + WTERMSIG(status);
    }
    if (w.in_reader)
        return fail(w.file + " is corrupt: OpenVDB's reader crashed on it (" + describe_wait_status(status) +
                    "); re-export the file or check that the copy is complete");
    return fail("internal error: the meshing process ended abnormally (" + describe_wait_status(status) +
                "); nothing was written. Please report this with the input and options");
}

}  // namespace

int main(int argc, char** argv) {
    std::string job;
    if (!job_path(job)) return fail("cannot find pqdc's worker program: /proc/self/exe is unreadable; is /proc mounted?");
    int fds[2];
    if (::pipe2(fds, O_CLOEXEC) != 0)
        return fail(std::string("cannot start pqdc's worker program: pipe: ") + std::strerror(errno));
    // Built before the fork: between fork and exec only async-signal-safe
    // calls are allowed. argv[0] stays pqdc's, for the worker's messages.
    std::vector<std::string> args{argv[0], kJobArgument, std::to_string(fds[1]), std::to_string(::getpid())};
    args.insert(args.end(), argv + 1, argv + argc);
    std::vector<char*> cargs;
    for (auto& a : args) cargs.push_back(a.data());
    cargs.push_back(nullptr);
    std::vector<std::string> env = worker_environment();
    std::vector<char*> cenv;
    for (auto& e : env) cenv.push_back(e.data());
    cenv.push_back(nullptr);
    const pid_t pid = ::fork();
    if (pid < 0) return fail(std::string("cannot start pqdc's worker program: fork: ") + std::strerror(errno));
    if (pid == 0) {
        ::prctl(PR_SET_PDEATHSIG, SIGKILL);  // die with an interrupted or killed pqdc
        ::fcntl(fds[1], F_SETFD, 0);          // the write end survives exec, the read end does not
        ::execve(job.c_str(), cargs.data(), cenv.data());
        ::_exit(kExitNoExec);
    }
    ::close(fds[1]);
    g_worker.store(pid);
    handle_signals(forward_signal, {SIGINT, SIGTERM});
    const Watched w = watch(fds[0]);
    ::close(fds[0]);
    int status = 0;
    while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
    }
    g_worker.store(0);
    const bool by_bricks = std::any_of(argv + 1, argv + argc, [](const char* a) {
        const std::string arg = a;
        for (const char* option : {"--out-of-core", "--brick-size", "--brick-runs"})
            if (arg.rfind(option, 0) == 0) return true;
        return false;
    });
    return outcome(w, status, pid, job, by_bricks);
}
