// A std::vector that does not zero what it grows by (internal).
//
// The self-intersection check allocates arrays of hundreds of megabytes
// (grid entries, radix buffers, triangle indices) that a parallel loop
// fills completely. std::vector<T>(n) would first zero them in the calling
// thread, so every fresh page is faulted in serially; here the first touch
// is the parallel fill. Use it only for arrays written in full before read.
#pragma once

#include <memory>
#include <new>
#include <utility>
#include <vector>

namespace pqdc::detail {

template <class T>
struct DefaultInitAllocator : std::allocator<T> {
    template <class U>
    struct rebind {
        using other = DefaultInitAllocator<U>;
    };
    DefaultInitAllocator() = default;
    template <class U>
    DefaultInitAllocator(const DefaultInitAllocator<U>&) noexcept {}
    /// Default-initialization: nothing written for trivial types.
    template <class U>
    void construct(U* p) noexcept(noexcept(::new (static_cast<void*>(p)) U)) {
        ::new (static_cast<void*>(p)) U;
    }
    template <class U, class... Args>
    void construct(U* p, Args&&... args) {
        std::allocator_traits<std::allocator<T>>::construct(static_cast<std::allocator<T>&>(*this), p,
                                                           std::forward<Args>(args)...);
    }
};

template <class T>
using UninitializedVector = std::vector<T, DefaultInitAllocator<T>>;

}  // namespace pqdc::detail
