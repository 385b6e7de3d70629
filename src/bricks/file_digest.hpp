// The checksum a brick store's index records for each of its files (store
// format 3): a bit flipped inside a brick file keeps its size, parses, and
// meshed silently into another surface (or crashed OpenVDB's reader, which
// the ranks of pqdc-mpi run outside any sandbox). The digest is checked
// before OpenVDB parses the file.
#pragma once

#include <string>

namespace pqdc::detail {

/// XXH3 (64 bits, seed 0) of the bytes of file `path`, as 16 lowercase hex
/// digits. Read in chunks, so memory stays small for any file size. Throws
/// std::system_error (the errno of the failing open or read).
std::string file_digest(const std::string& path);

/// Whether `text` has the form file_digest() returns.
bool is_file_digest(const std::string& text);

}  // namespace pqdc::detail
