// The byte strings ranks send to rank 0 in a distributed run (scale/
// cell_parts.cpp for the uniform cells stage, adaptive/level_parts.cpp for
// the adaptive finest level): trivially copyable values appended in the
// ranks' own byte order and word size, read back in the same order. A part
// that does not parse is an internal error (every rank runs the same
// program on the same input), reported as std::logic_error.
#pragma once

#include <cstddef>
#include <cstring>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

namespace pqdc::detail {

class PartWriter {
public:
    explicit PartWriter(std::string& out) : out_(out) {}
    template <class T>
    void put(const T& v) {
        static_assert(std::is_trivially_copyable_v<T>);
        put_bytes(&v, sizeof v);
    }
    void put_bytes(const void* p, std::size_t n) {
        if (n) out_.append(static_cast<const char*>(p), n);
    }
    /// The elements of `values`, without their count (the reader must know it).
    template <class T>
    void put_array(const std::vector<T>& values) {
        static_assert(std::is_trivially_copyable_v<T>);
        put_bytes(values.data(), values.size() * sizeof(T));
    }

private:
    std::string& out_;
};

class PartReader {
public:
    /// `what`: the part's name in error messages ("the cells stage").
    PartReader(const std::string& in, const char* what) : in_(in), what_(what) {}
    template <class T>
    T get() {
        static_assert(std::is_trivially_copyable_v<T>);
        T v;
        get_bytes(&v, sizeof v);
        return v;
    }
    void get_bytes(void* p, std::size_t n) {
        if (n > in_.size() - at_) malformed("it ends early");
        if (n) std::memcpy(p, in_.data() + at_, n);
        at_ += n;
    }
    /// Appends `n` values to `out`; malformed when fewer are left.
    template <class T>
    void append_array(std::size_t n, std::vector<T>& out) {
        static_assert(std::is_trivially_copyable_v<T>);
        if (n > left() / sizeof(T)) malformed("it ends early");
        const std::size_t at = out.size();
        out.resize(at + n);
        get_bytes(out.data() + at, n * sizeof(T));
    }
    /// Bytes not read yet.
    std::size_t left() const { return in_.size() - at_; }
    bool done() const { return at_ == in_.size(); }
    [[noreturn]] void malformed(const char* why) const {
        throw std::logic_error(std::string("internal error: a rank's part of ") + what_ + " is malformed: " + why);
    }

private:
    const std::string& in_;
    const char* what_;
    std::size_t at_ = 0;
};

}  // namespace pqdc::detail
