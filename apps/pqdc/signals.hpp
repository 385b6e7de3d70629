// Interrupts. Sampling a procedural field and reading a file have no
// cancellation points, so waiting for the library to notice a flag can take
// many seconds. Outside of writes nothing on disk needs cleaning up, so the
// handler exits at once, after removing any named temporary file (see
// pqdc::remove_temporary_files). During a write it only records the signal;
// the write finishes (or fails and removes its temporary) and the signal is
// acted on right after. The phase switch is a compare-exchange so the handler and
// the main thread can never both win.
#pragma once

#include <functional>
#include <string>

namespace pqdc_app {

/// A signal arrived while a file was being written; that file is complete.
struct Interrupted {
    int signal;
    std::string written;
};

void install_signal_handlers();

/// Where the handler prints "interrupted" (stderr; the saved stderr while
/// the reader sandbox silences it).
void set_interrupt_message_fd(int fd);

/// What the handler prints when nothing was written yet (default
/// "pqdc: interrupted; no output written"); `text` must live as long as
/// the process, a string literal.
void set_interrupt_message(const char* text);

/// The program the handler names once a file was written (default
/// "pqdc"); a string literal.
void set_interrupt_program(const char* program);

/// Signals end the process during writes too, at once, after removing the
/// temporary files being written (pqdc::remove_temporary_files). For the
/// ranks of a distributed run: once mpirun signals them (a rank failed or
/// was killed, or Ctrl-C), the collective write cannot finish, and mpirun
/// follows with SIGKILL after a moment.
void exit_at_once_during_writes();

/// The signal received so far, 0 if none.
int pending_signal();

/// Runs `write` (which creates one file atomically, or a brick store that
/// removes its files when it fails) with signals deferred;
/// throws Interrupted when one arrived meanwhile.
void write_deferring_signals(const std::string& path, const std::function<void()>& write);

inline int interrupted_exit(int sig) { return 128 + (sig ? sig : 2); }

}  // namespace pqdc_app
