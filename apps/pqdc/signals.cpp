#include "signals.hpp"

#include "supervision.hpp"
#include "../cli_util.hpp"

#include "pqdc/file_io.hpp"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <csignal>
#include <cstring>

namespace pqdc_app {
namespace {

constexpr int phase_computing = 0, phase_writing = 1, phase_exiting = 2;
std::atomic<int> g_phase{phase_computing};
std::atomic<int> g_signal{0};
std::atomic<bool> g_exit_during_writes{false};
std::atomic<bool> g_wrote_something{false};
std::atomic<int> g_message_fd{STDERR_FILENO};
std::atomic<const char*> g_nothing{kInterruptedNothingWritten};
std::atomic<const char*> g_program{"pqdc"};
// The last file written whole, for the handler (which may not allocate);
// set before g_wrote_something, read only after it.
char g_last_written[4096];

void put(int fd, const char* text) { (void)!::write(fd, text, std::strlen(text)); }

/// Whether this signal ends the process now: always while computing; while
/// writing only when asked (exit_at_once_during_writes).
bool take_exit() {
    int expected = phase_computing;
    if (g_phase.compare_exchange_strong(expected, phase_exiting)) return true;
    if (expected != phase_writing || !g_exit_during_writes.load()) return false;
    return g_phase.compare_exchange_strong(expected, phase_exiting);
}

extern "C" void on_signal(int sig) {
    g_signal.store(sig);
    if (take_exit()) {
        // The writers' named temporaries (a distributed run's shared file;
        // file systems without O_TMPFILE): _exit runs no destructor.
        pqdc::remove_temporary_files();
        const int fd = g_message_fd.load();
        if (g_wrote_something.load()) {
            // As report_job_errors says it for a signal during a write.
            put(fd, "\n");
            put(fd, g_program.load());
            put(fd, ": interrupted after '");
            put(fd, g_last_written);
            put(fd, "' was written completely; nothing after it was written\n");
        } else {
            put(fd, g_nothing.load());
        }
        ::_exit(128 + sig);
    }
}

}  // namespace

void install_signal_handlers() {
    // SIGHUP too: a closed terminal or a dropped ssh session during a long
    // run (pqdc-bricks split left its bricks so far behind).
    handle_signals(on_signal, {SIGINT, SIGTERM, SIGHUP});
    pqdc_cli::report_write_signals_as_errors();
}

int pending_signal() { return g_signal.load(); }

void set_interrupt_message_fd(int fd) { g_message_fd.store(fd); }

void set_interrupt_message(const char* text) { g_nothing.store(text); }

void set_interrupt_program(const char* program) { g_program.store(program); }

void exit_at_once_during_writes() { g_exit_during_writes.store(true); }

void write_deferring_signals(const std::string& path, const std::function<void()>& write) {
    int expected = phase_computing;
    if (!g_phase.compare_exchange_strong(expected, phase_writing)) {
        for (;;) ::pause();  // another thread's signal handler is exiting the process
    }
    struct Leave {
        ~Leave() { g_phase.store(phase_computing); }
    } leave;
    write();
    const std::size_t n = std::min(path.size(), sizeof g_last_written - 1);
    std::memcpy(g_last_written, path.data(), n);
    g_last_written[n] = '\0';
    g_wrote_something.store(true);
    if (const int sig = g_signal.load()) throw Interrupted{sig, path};
}

}  // namespace pqdc_app
