// Writing a whole file the way every pqdc writer does: the bytes go to a
// file without a name in the target's directory, which is synced and linked
// into place only when complete, so a failure, an interrupt or a SIGKILL
// leaves the old file or the new one, never a part of either and never a
// temporary (src/io/atomic_file.hpp has the details and the fallbacks).
#pragma once

#include <string>
#include <string_view>

namespace pqdc {

/// Writes `bytes` to `path` atomically; "-" is standard output. Throws
/// io_error naming the path and the reason.
void write_file(const std::string& path, std::string_view bytes);

/// Removes the named temporary files pqdc's writers in this process hold at
/// this moment, for a signal handler that is about to end the process
/// (async-signal-safe: no locks, no allocation). Most writers have none: their
/// bytes go to a file without a name, which the kernel frees with the process.
/// Those that do are the shared file of a distributed run
/// (MeshStreamWriter::finish with a rank group: every rank that opened it can
/// remove it, so when one rank is killed the others, ended by mpirun, leave
/// nothing) and temporaries on file systems without O_TMPFILE. A writer whose
/// temporary was removed fails if it goes on. Best effort: up to 32 files at
/// once, paths shorter than 4096 bytes.
void remove_temporary_files() noexcept;

}  // namespace pqdc
