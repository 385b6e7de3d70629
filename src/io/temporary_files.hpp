// Internal: the list of named temporary files this process holds, for
// pqdc::remove_temporary_files() (include/pqdc/file_io.hpp), which a signal
// handler calls before it ends the process. Most writers never appear on it:
// their bytes go to a file without a name (O_TMPFILE) that the kernel frees
// with the process. It holds the temporaries that need a name: the shared
// file the ranks of a distributed run write their parts into (rank 0 creates
// it, the others open it by its name), and any temporary on a file system
// without O_TMPFILE. A rank killed outright (SIGKILL, the OOM killer) cannot
// clean up, but mpirun then ends the other ranks with SIGTERM, and any of
// them can remove the file by name.
//
// The list is a fixed table of slots that the handler reads without locks or
// allocation. Each slot has a generation count, raised when it is released,
// so the handler never unlinks a name whose slot was reused while it read
// it. Paths longer than a slot, or more temporaries than slots, are not
// listed: best effort, as the killed-process case is.
#pragma once

#include <string>

namespace pqdc {
namespace detail {

/// Keeps one path on the list from list() to release() or destruction.
class TemporaryFileListing {
public:
    TemporaryFileListing() = default;
    ~TemporaryFileListing() { release(); }
    TemporaryFileListing(const TemporaryFileListing&) = delete;
    TemporaryFileListing& operator=(const TemporaryFileListing&) = delete;

    /// Lists `path` (an existing file this process will rename or remove),
    /// after releasing the one listed before, if any.
    void list(const std::string& path);
    /// Takes the path off the list (after it was renamed or removed).
    void release();

private:
    int slot_ = -1;
};

/// How many paths are listed now (for tests).
int listed_temporary_files();

}  // namespace detail
}  // namespace pqdc
