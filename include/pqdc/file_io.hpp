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

}  // namespace pqdc
