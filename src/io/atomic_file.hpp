// Internal: the buffered, atomic file writer every pqdc writer uses. Bytes go
// to a file without a name in the target's directory (O_TMPFILE), which
// commit() fsyncs and links in place: straight to the target when there is
// none, else to "<path>.tmp-<pid>-<random>" renamed over it. A process that
// dies before commit(), even by SIGKILL (the OOM killer, a batch system's
// time limit), leaves nothing behind: the kernel frees a file without a
// name with its last descriptor. Where O_TMPFILE is not available (file
// systems without it), the bytes go to the named temporary from the start,
// and destruction without commit (an exception anywhere) removes it; only
// a killed process then leaves it behind. Either way the target is the old
// file or the complete new one. Failures throw io_error naming the path and
// strerror.
//
// A writer made with the Named tag always uses the named temporary: other
// processes open it by temp_path() (the ranks of a distributed run writing
// their parts of one file).
//
// A named temporary stays on the process's list of temporaries
// (io/temporary_files.hpp) until it is renamed or removed, so that a signal
// handler can remove it (pqdc::remove_temporary_files) before the process
// ends.
//
// The path "-" is standard output: bytes go straight to file descriptor 1
// (nothing can be made atomic there) and commit() only flushes. So does an
// existing target that is not a regular file (a FIFO, /dev/null, a
// terminal): a rename would replace the device node itself, which as root
// turned /dev/null into a plain file.
//
// A scratch writer (the Scratch tag) holds one section of a file that is
// assembled later (MeshStreamWriter: the vertices, then the faces, whose
// counts the header needs first). It is created next to the target (in the
// temporary directory for "-") and unlinked at once, so nothing is left
// behind however the process ends (O_TMPFILE where available); copy_into()
// appends its bytes to the real writer. It is never committed.
#pragma once

#include "io/temporary_files.hpp"
#include "pqdc/exceptions.hpp"

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace pqdc {
namespace detail {

class AtomicFileWriter {
public:
    explicit AtomicFileWriter(const std::string& path) : AtomicFileWriter(path, false) {}

    struct Named {};
    /// A writer whose temporary has a name from the start (see the top of the file).
    AtomicFileWriter(const std::string& path, Named) : AtomicFileWriter(path, true) {}

private:
    AtomicFileWriter(const std::string& path, bool named) : path_(path) {
        buffer_.reserve(kBufferBytes);
        if (path == "-") {
            fd_ = STDOUT_FILENO;
            to_stdout_ = direct_ = true;
            return;
        }
        struct stat st {};
        if (::stat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode) && !S_ISDIR(st.st_mode)) {
            fd_ = ::open(path.c_str(), O_WRONLY | O_CLOEXEC);
            if (fd_ < 0)
                throw io_error("cannot write '" + path_ + "': " + std::strerror(errno) +
                               " (it exists and is not a regular file: a device or a pipe)");
            direct_ = true;
            return;
        }
        if (named || !open_anonymous(O_WRONLY)) open_temp();
    }

public:
    struct Scratch {};
    /// A scratch section for the target `path` (see the top of the file).
    AtomicFileWriter(const std::string& path, Scratch) : path_(path), scratch_(true) {
        buffer_.reserve(kBufferBytes);
        struct stat st {};
        const bool in_place = path == "-" || (::stat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode));
        if (in_place) {  // no directory of its own to use; messages then name the temporary directory
            const char* dir = std::getenv("TMPDIR");
            path_ = std::string(dir && *dir ? dir : "/tmp") + "/pqdc-section";
        }
        if (open_anonymous(O_RDWR)) return;
        open_temp();
        ::unlink(temp_path_.c_str());
        temp_path_.clear();
    }

    /// A scratch section's bytes, in order, in chunks of at most 4 MiB:
    /// f(data, size) for each.
    template <class F>
    void read_back(const F& f) {
        flush_buffer();
        if (const int err = read_chunks(fd_, offset_, f)) fail("reading back a section", err);
    }

    /// A scratch section's bytes appended to `out`, in order.
    void copy_into(AtomicFileWriter& out) {
        read_back([&](const char* data, std::size_t n) { out.append(data, n); });
    }

    /// A scratch section's bytes written to `fd` from `offset` on (pwrite:
    /// the parts of a file several writers fill at once). `target`: what a
    /// failure's message calls the file written.
    void copy_to(int fd, std::uint64_t offset, const std::string& target) {
        read_back([&](const char* data, std::size_t n) {
            write_all_at(fd, data, n, offset, target);
            offset += n;
        });
    }

    /// Writes n bytes to `fd` at `offset`; io_error naming `target`.
    static void write_all_at(int fd, const char* data, std::size_t n, std::uint64_t offset, const std::string& target) {
        while (n > 0) {
            const ssize_t w = ::pwrite(fd, data, n, off_t(offset));
            if (w < 0 && errno == EINTR) continue;
            if (w <= 0)
                throw io_error("cannot write '" + target + "': " + std::strerror(w < 0 ? errno : EIO) +
                               " (while writing this rank's part; check that the directory has free space)");
            data += w;
            n -= std::size_t(w);
            offset += std::uint64_t(w);
        }
    }

    /// The temporary file's name while the target is written to one (always
    /// for a Named writer; empty for a temporary without a name and for
    /// standard output, a device or a pipe, which are written in place).
    const std::string& temp_path() const { return temp_path_; }

    /// A scratch section flushed: its descriptor, for mapping it.
    int flushed_descriptor() {
        flush_buffer();
        return fd_;
    }

    /// What messages call the target: the path, or "standard output".
    std::string display_name() const { return to_stdout_ ? "standard output" : path_; }
    /// Calls progress(fraction of expected_bytes written) after each flush.
    void set_progress(std::function<void(double)> progress, std::uint64_t expected_bytes) {
        progress_ = std::move(progress);
        expected_ = expected_bytes ? expected_bytes : 1;
    }

    AtomicFileWriter(const AtomicFileWriter&) = delete;
    AtomicFileWriter& operator=(const AtomicFileWriter&) = delete;

    ~AtomicFileWriter() {
        if (!committed_) discard();
    }

    /// Room for at least n more bytes at the end of the buffer; flushes first
    /// if needed. Callers append with advance().
    char* reserve(std::size_t n) {
        if (buffer_.size() + n > buffer_.capacity()) flush_buffer();
        if (n > buffer_.capacity()) buffer_.reserve(n);
        used_before_reserve_ = buffer_.size();
        buffer_.resize(buffer_.size() + n);
        return buffer_.data() + used_before_reserve_;
    }
    /// Keeps the first n bytes of the last reserve().
    void advance(std::size_t n) { buffer_.resize(used_before_reserve_ + n); }

    void append(const void* data, std::size_t n) {
        // An empty vector's data() may be null, and memcpy(dst, nullptr, 0) is undefined.
        if (n == 0) return;
        if (n >= kBufferBytes) {
            flush_buffer();
            write_all(static_cast<const char*>(data), n);
            return;
        }
        char* dst = reserve(n);
        std::memcpy(dst, data, n);
    }
    void append(std::string_view s) { append(s.data(), s.size()); }

    /// The file offset the next append() writes at.
    std::uint64_t position() const { return offset_ + buffer_.size(); }
    /// Moves the write position to `offset` (for formats that patch their
    /// headers, OpenVDB's seekable files): the buffer is written first.
    /// Not for standard output.
    void seek(std::uint64_t offset) {
        flush_buffer();
        if (to_stdout_ || ::lseek(fd_, off_t(offset), SEEK_SET) < 0) fail("seeking", to_stdout_ ? ESPIPE : errno);
        offset_ = offset;
    }

    void commit() {
        if (scratch_) throw std::logic_error("AtomicFileWriter: a scratch section is never committed");
        flush_buffer();
        if (direct_) {
            const int fd = fd_;
            fd_ = -1;
            committed_ = true;
            if (!to_stdout_ && ::close(fd) != 0) fail("closing", errno);
            return;
        }
        if (::fsync(fd_) != 0) fail("flushing to disk", errno);
        const bool in_place = anonymous_ && link_anonymous();  // a new target, linked straight in
        const int fd = fd_;
        fd_ = -1;
        // Once in place the file is complete (fsync'ed): a close error changes nothing.
        if (::close(fd) != 0 && !in_place) fail("closing", errno);
        if (!in_place && ::rename(temp_path_.c_str(), path_.c_str()) != 0)
            fail("renaming the temporary file into place", errno);
        listing_.release();
        committed_ = true;
        sync_parent_directory();
    }

private:
    static constexpr std::size_t kBufferBytes = std::size_t(4) << 20;

    /// f(data, size) for the first `bytes` of `fd`, in order, in chunks of at
    /// most 4 MiB; errno of a failed read (EIO for a short file), else 0.
    template <class F>
    static int read_chunks(int fd, std::uint64_t bytes, const F& f) {
        std::vector<char> chunk(std::size_t(std::min<std::uint64_t>(kBufferBytes, bytes)));
        for (std::uint64_t at = 0; at < bytes;) {
            const std::size_t want = std::size_t(std::min<std::uint64_t>(chunk.size(), bytes - at));
            const ssize_t got = ::pread(fd, chunk.data(), want, off_t(at));
            if (got < 0 && errno == EINTR) continue;
            if (got <= 0) return got < 0 ? errno : EIO;
            f(static_cast<const char*>(chunk.data()), std::size_t(got));
            at += std::uint64_t(got);
        }
        return 0;
    }

    [[noreturn]] void fail(const char* stage, int err) {
        discard();
        if (to_stdout_)
            throw io_error(std::string("cannot write to standard output: ") + std::strerror(err) + " (while " +
                           stage + "; the reading end of the pipe may have closed)");
        if (scratch_)  // a user sees the free space the output needs, not the scratch files'
            throw io_error("cannot write the scratch files next to '" + path_ + "': " + std::strerror(err) +
                           " (while " + stage +
                           "; a run brick by brick keeps the mesh there until the output is written, about 40 "
                           "bytes a vertex and 12-16 a face besides the output itself: free that much space, "
                           "or write the output to another disk)");
        throw io_error("cannot write '" + path_ + "': " + std::strerror(err) + " (while " + stage +
                       "; check that the directory exists, is writable and has free space)");
    }

    void discard() {
        if (direct_) {
            if (!to_stdout_ && fd_ >= 0) ::close(fd_);
            fd_ = -1;
            return;
        }
        if (fd_ >= 0) {
            ::close(fd_);
            fd_ = -1;
        }
        if (!temp_path_.empty()) {
            ::unlink(temp_path_.c_str());
            temp_path_.clear();
            listing_.release();
        }
    }

    std::string directory() const {
        const std::size_t slash = path_.find_last_of('/');
        return slash == std::string::npos ? "." : (slash == 0 ? "/" : path_.substr(0, slash));
    }

    /// A file without a name in the target's directory; false where the
    /// kernel or the file system has no O_TMPFILE (or refuses it for another
    /// reason, which open_temp() then reports).
    bool open_anonymous(int access) {
#ifdef O_TMPFILE
        const int fd = ::open(directory().c_str(), O_TMPFILE | access | O_CLOEXEC, scratch_ ? 0600 : 0666);
        if (fd < 0) return false;
        fd_ = fd;
        anonymous_ = true;
        if (!scratch_) keep_existing_mode();
        return true;
#else
        (void)access;
        return false;
#endif
    }

    /// Names the finished file without a name: the target's name when there
    /// is no target yet (true: committed), else a named temporary to rename
    /// over it (false, temp_path_ set). The link is made through the
    /// descriptor (AT_EMPTY_PATH, which needs CAP_DAC_READ_SEARCH) or
    /// /proc/self/fd; where neither works, the bytes are copied into a
    /// named temporary.
    bool link_anonymous() {
        auto link_to = [&](const std::string& name) {
            if (::linkat(fd_, "", AT_FDCWD, name.c_str(), AT_EMPTY_PATH) == 0) return 0;
            if (errno == EEXIST) return EEXIST;
            const std::string proc = "/proc/self/fd/" + std::to_string(fd_);
            if (::linkat(AT_FDCWD, proc.c_str(), AT_FDCWD, name.c_str(), AT_SYMLINK_FOLLOW) == 0) return 0;
            return errno == 0 ? EIO : errno;
        };
        const int direct = link_to(path_);
        if (direct == 0) return true;
        if (direct == EEXIST) {
            for (int attempt = 0; attempt < 16; ++attempt) {
                std::string candidate = temp_name();
                const int err = link_to(candidate);
                if (err == 0) {
                    temp_path_ = std::move(candidate);
                    listing_.list(temp_path_);
                    return false;
                }
                if (err != EEXIST) break;
            }
        }
        copy_to_named_temp();
        return false;
    }

    /// link_anonymous()'s last resort: the bytes copied into a named
    /// temporary, which becomes fd_.
    void copy_to_named_temp() {
        const int from = fd_;
        const std::uint64_t bytes = offset_;
        fd_ = -1;
        anonymous_ = false;
        offset_ = 0;
        struct Closer {
            int fd;
            ~Closer() { ::close(fd); }
        } closer{from};  // also when open_temp() or a write throws
        open_temp();
        const int err = read_chunks(from, bytes, [&](const char* data, std::size_t n) { write_all(data, n); });
        if (err) fail("copying the finished file to a named temporary", err);
        if (::fsync(fd_) != 0) fail("flushing to disk", errno);
    }

    /// "<path>.tmp-<pid>-<random>": a splitmix64 of the clock, the address
    /// and a counter, unique enough across threads and processes; O_EXCL
    /// (or link's EEXIST) settles any collision.
    std::string temp_name() const {
        static std::atomic<std::uint64_t> counter{0};
        const auto now = static_cast<std::uint64_t>(std::chrono::steady_clock::now().time_since_epoch().count());
        std::uint64_t x = now ^ (reinterpret_cast<std::uintptr_t>(this) << 16) ^
                          (counter.fetch_add(1) * 0x9E3779B97F4A7C15ull);
        x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
        x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
        x ^= x >> 31;
        char suffix[64];
        std::snprintf(suffix, sizeof suffix, ".tmp-%ld-%012llx", static_cast<long>(::getpid()),
                      static_cast<unsigned long long>(x & 0xFFFFFFFFFFFFull));
        return path_ + suffix;
    }

    void open_temp() {
        int err = 0;
        for (int attempt = 0; attempt < 16; ++attempt) {
            std::string candidate = temp_name();
            const int fd = ::open(candidate.c_str(), (scratch_ ? O_RDWR : O_WRONLY) | O_CREAT | O_EXCL | O_CLOEXEC,
                                  scratch_ ? 0600 : 0666);
            if (fd >= 0) {
                fd_ = fd;
                temp_path_ = std::move(candidate);
                if (!scratch_) {  // a scratch section's name is removed at once
                    listing_.list(temp_path_);
                    keep_existing_mode();
                }
                return;
            }
            err = errno;
            if (err != EEXIST) break;
        }
        throw io_error("cannot write '" + path_ + "': " + std::strerror(err) +
                       " (while creating a temporary file in its directory; check that the directory "
                       "exists and is writable)");
    }

    // Replacing a file should not silently change who may read it.
    void keep_existing_mode() {
        struct stat st {};
        if (::stat(path_.c_str(), &st) == 0 && S_ISREG(st.st_mode)) {
            (void)::fchmod(fd_, st.st_mode & 07777);
        }
    }

    void write_all(const char* data, std::size_t n) {
        while (n > 0) {
            const ssize_t w = ::write(fd_, data, n);
            if (w < 0) {
                if (errno == EINTR) continue;
                fail("writing", errno);
            }
            if (w == 0) fail("writing", EIO);
            data += w;
            n -= static_cast<std::size_t>(w);
            written_ += static_cast<std::uint64_t>(w);
            offset_ += static_cast<std::uint64_t>(w);
        }
    }

    void flush_buffer() {
        if (buffer_.empty()) return;
        const std::uint64_t at = offset_;
        write_all(buffer_.data(), buffer_.size());
        // Start writing the chunk to disk now, so that commit()'s fsync
        // waits only for the last ones instead of the whole file (a hint:
        // failures show up at the fsync).
        if (!direct_ && !scratch_) (void)::sync_file_range(fd_, off_t(at), off_t(buffer_.size()), SYNC_FILE_RANGE_WRITE);
        buffer_.clear();
        if (progress_) progress_(std::min(1.0, double(written_) / double(expected_)));
    }

    // Makes the rename itself durable. Best effort: the data is already
    // complete and in place, and some file systems refuse fsync on directories.
    void sync_parent_directory() const {
        const int dfd = ::open(directory().c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
        if (dfd >= 0) {
            (void)::fsync(dfd);
            ::close(dfd);
        }
    }

    std::string path_;
    std::string temp_path_;
    TemporaryFileListing listing_;  ///< temp_path_ while it names a file
    int fd_ = -1;
    bool committed_ = false;
    bool to_stdout_ = false;
    bool direct_ = false;  ///< standard output or a non-regular target: written in place, not renamed
    bool scratch_ = false;
    bool anonymous_ = false;  ///< fd_ has no name (O_TMPFILE) until commit() links it
    std::uint64_t written_ = 0, expected_ = 1;
    std::uint64_t offset_ = 0;  // of the file descriptor
    std::function<void(double)> progress_;
    std::vector<char> buffer_;
    std::size_t used_before_reserve_ = 0;
};

}  // namespace detail
}  // namespace pqdc
