#include "io/temporary_files.hpp"

#include "pqdc/file_io.hpp"

#include <atomic>
#include <cstring>

#include <unistd.h>

namespace pqdc {
namespace detail {
namespace {

constexpr int kSlots = 32;
constexpr std::size_t kPathBytes = 4096;  // PATH_MAX on Linux, with its terminating zero

struct Slot {
    std::atomic<bool> claimed{false};  ///< owned by a listing
    std::atomic<bool> ready{false};    ///< path is complete
    std::atomic<unsigned> generation{0};
    char path[kPathBytes];
};

Slot g_slots[kSlots];

// Atomics without locks are what make the table safe in a signal handler.
static_assert(std::atomic<bool>::is_always_lock_free && std::atomic<unsigned>::is_always_lock_free,
              "the temporary file list needs lock-free atomics");

}  // namespace

void TemporaryFileListing::list(const std::string& path) {
    release();
    if (path.empty() || path.size() >= kPathBytes) return;
    for (int i = 0; i < kSlots; ++i) {
        bool expected = false;
        if (!g_slots[i].claimed.compare_exchange_strong(expected, true)) continue;
        std::memcpy(g_slots[i].path, path.c_str(), path.size() + 1);
        g_slots[i].ready.store(true, std::memory_order_release);
        slot_ = i;
        return;
    }
}

void TemporaryFileListing::release() {
    if (slot_ < 0) return;
    Slot& s = g_slots[slot_];
    s.ready.store(false, std::memory_order_release);
    s.generation.fetch_add(1, std::memory_order_acq_rel);
    s.claimed.store(false, std::memory_order_release);
    slot_ = -1;
}

int listed_temporary_files() {
    int n = 0;
    for (const Slot& s : g_slots) n += s.ready.load(std::memory_order_acquire) ? 1 : 0;
    return n;
}

}  // namespace detail

void remove_temporary_files() noexcept {
    for (detail::Slot& s : detail::g_slots) {
        const unsigned before = s.generation.load(std::memory_order_acquire);
        if (!s.ready.load(std::memory_order_acquire)) continue;
        char path[detail::kPathBytes];
        std::memcpy(path, s.path, sizeof path);
        path[sizeof path - 1] = '\0';
        std::atomic_thread_fence(std::memory_order_acquire);
        // Released (and perhaps reused) meanwhile: the copy may be torn.
        if (s.generation.load(std::memory_order_acquire) != before || !s.ready.load(std::memory_order_acquire))
            continue;
        (void)::unlink(path);
    }
}

}  // namespace pqdc
