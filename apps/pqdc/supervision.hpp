// What pqdc (the supervisor, apps/pqdc/launcher.cpp) and pqdc-job (the
// worker that reads, meshes and writes, apps/pqdc/job_main.cpp) say to each
// other. The worker is started as
//   pqdc-job --internal-job FD SUPERVISOR_PID ARGS...
// and writes messages to the pipe FD: a kind byte, then for kinds with text
// a count and that many strings (a 32-bit length and the bytes each).
// Header-only and free of pqdc and OpenVDB: the supervisor links neither,
// so it starts in a millisecond and a corrupt file cannot reach it.
#pragma once

#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <initializer_list>
#include <cstdint>
#include <string>
#include <vector>

namespace pqdc_app {

inline constexpr const char* kJobArgument = "--internal-job";

/// What the worker's signal handler prints when nothing was written yet, and
/// what the supervisor prints for a worker a signal ended before its handler
/// was in place.
inline constexpr const char* kInterruptedNothingWritten = "\npqdc: interrupted; no output written\n";

/// The worker's exit codes that only mean something inside the reader.
inline constexpr int kExitOutOfMemory = 5, kExitTerminated = 6;
/// The forked supervisor child could not exec the worker.
inline constexpr int kExitNoExec = 127;

enum class Message : char {
    /// Entering OpenVDB's reader. Strings: what to print if it runs out of
    /// memory, what to print if it crashes (both name the file).
    enter_reader = 'R',
    leave_reader = 'D',
    /// The files the run may write (-o, --stats): where a named temporary of
    /// a dead worker would be. Strings: their paths.
    outputs = 'O',
};

/// Installs `handler` for `signals`, restarting interrupted system calls.
inline void handle_signals(void (*handler)(int), std::initializer_list<int> signals) {
    struct sigaction sa {};
    sa.sa_handler = handler;
    sigemptyset(&sa.sa_mask);
    sa.sa_flags = SA_RESTART;
    for (int sig : signals) sigaction(sig, &sa, nullptr);
}

/// Sends one message; a write error means the supervisor is gone (the
/// worker dies with it: PR_SET_PDEATHSIG), so it is ignored.
inline void send_message(int fd, Message kind, const std::vector<std::string>& texts = {}) {
    std::string bytes(1, char(kind));
    if (kind != Message::leave_reader) {
        auto put32 = [&bytes](std::uint32_t n) { bytes.append(reinterpret_cast<const char*>(&n), 4); };
        put32(std::uint32_t(texts.size()));
        for (const std::string& t : texts) {
            put32(std::uint32_t(t.size()));
            bytes += t;
        }
    }
    const char* p = bytes.data();
    std::size_t n = bytes.size();
    while (n > 0) {
        const ssize_t w = ::write(fd, p, n);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) return;
        p += w, n -= std::size_t(w);
    }
}

/// Reads exactly n bytes; false at the end of the pipe.
inline bool read_exactly(int fd, void* data, std::size_t n) {
    char* p = static_cast<char*>(data);
    while (n > 0) {
        const ssize_t r = ::read(fd, p, n);
        if (r < 0 && errno == EINTR) continue;
        if (r <= 0) return false;
        p += r, n -= std::size_t(r);
    }
    return true;
}

/// Receives one message into kind and texts; false at the end of the pipe
/// (the worker ended) or on a malformed one. Strings are capped at 64 KiB.
inline bool receive_message(int fd, Message& kind, std::vector<std::string>& texts) {
    char k = 0;
    if (!read_exactly(fd, &k, 1)) return false;
    kind = Message(k);
    texts.clear();
    if (kind == Message::leave_reader) return true;
    if (kind != Message::enter_reader && kind != Message::outputs) return false;
    std::uint32_t count = 0;
    if (!read_exactly(fd, &count, 4) || count > 16) return false;
    for (std::uint32_t i = 0; i < count; ++i) {
        std::uint32_t len = 0;
        if (!read_exactly(fd, &len, 4) || len > (1u << 16)) return false;
        std::string t(len, '\0');
        if (!read_exactly(fd, t.data(), len)) return false;
        texts.push_back(std::move(t));
    }
    return true;
}

}  // namespace pqdc_app
