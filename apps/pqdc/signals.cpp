#include "signals.hpp"

#include "supervision.hpp"
#include "../cli_util.hpp"

#include <unistd.h>

#include <atomic>
#include <csignal>
#include <cstring>

namespace pqdc_app {
namespace {

constexpr int phase_computing = 0, phase_writing = 1, phase_exiting = 2;
std::atomic<int> g_phase{phase_computing};
std::atomic<int> g_signal{0};
std::atomic<bool> g_wrote_something{false};
std::atomic<int> g_message_fd{STDERR_FILENO};
std::atomic<const char*> g_nothing{kInterruptedNothingWritten};

extern "C" void on_signal(int sig) {
    g_signal.store(sig);
    int expected = phase_computing;
    if (g_phase.compare_exchange_strong(expected, phase_exiting)) {
        const char* nothing = g_nothing.load();
        static const char partial[] =
            "\npqdc: interrupted; files reported as written are complete, nothing else was written\n";
        const int fd = g_message_fd.load();
        if (g_wrote_something.load())
            (void)!::write(fd, partial, sizeof partial - 1);
        else
            (void)!::write(fd, nothing, std::strlen(nothing));
        ::_exit(128 + sig);
    }
}

}  // namespace

void install_signal_handlers() {
    handle_signals(on_signal, {SIGINT, SIGTERM});
    pqdc_cli::report_write_signals_as_errors();
}

int pending_signal() { return g_signal.load(); }

void set_interrupt_message_fd(int fd) { g_message_fd.store(fd); }

void set_interrupt_message(const char* text) { g_nothing.store(text); }

void write_deferring_signals(const std::string& path, const std::function<void()>& write) {
    int expected = phase_computing;
    if (!g_phase.compare_exchange_strong(expected, phase_writing)) {
        for (;;) ::pause();  // another thread's signal handler is exiting the process
    }
    struct Leave {
        ~Leave() { g_phase.store(phase_computing); }
    } leave;
    write();
    g_wrote_something.store(true);
    if (const int sig = g_signal.load()) throw Interrupted{sig, path};
}

}  // namespace pqdc_app
