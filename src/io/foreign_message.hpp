// Another library's exception text, made fit for one line of a pqdc error.
// OpenVDB quotes what it read: a corrupt brick file gave a map-type "name"
// of 2.9 GB of NUL bytes, and pqdc printed all of it (and under MPI the
// abort raced the forwarding of that message, so it was often lost).
#pragma once

#include <cstddef>
#include <string>

namespace pqdc::detail {

/// `text` with control and NUL bytes as spaces, runs of spaces as one, and
/// at most `limit` characters (then "...").
inline std::string foreign_message(const char* text, std::size_t limit = 200) {
    std::string out;
    const char* p = text;
    for (; *p && out.size() < limit; ++p) {
        const unsigned char c = static_cast<unsigned char>(*p);
        const char shown = c < 32 || c == 127 ? ' ' : char(c);
        if (shown == ' ' && (out.empty() || out.back() == ' ')) continue;
        out += shown;
    }
    while (!out.empty() && out.back() == ' ') out.pop_back();
    if (*p) out += "...";  // stopped at the limit with text left
    return out;
}

}  // namespace pqdc::detail
