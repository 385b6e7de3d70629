#include "lattice/resources.hpp"

#include <unistd.h>
#ifdef __GLIBC__
#include <malloc.h>
#endif

#include <cstdint>
#include <cstdio>
#include <limits>
#include <sstream>

namespace pqdc::detail {

std::size_t default_memory_limit() {
    const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
    if (pages <= 0 || page <= 0) return std::numeric_limits<std::size_t>::max();
    return std::size_t(double(pages) * double(page) * 0.8);
}

std::size_t memory_limit(const ExtractOptions& options) {
    return options.memory_limit_bytes ? options.memory_limit_bytes : default_memory_limit();
}

std::string byte_size_text(double bytes) {
    static const char* const units[] = {"bytes", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"};
    int unit = 0;
    while (bytes >= 1024.0 && unit < 6) {
        bytes /= 1024.0;
        ++unit;
    }
    char text[48];
    // %.3g alone would print 1000-1023 as 1e+03.
    std::snprintf(text, sizeof text, bytes >= 100 ? "%.0f %s" : "%.3g %s", bytes, units[unit]);
    return text;
}

void check_memory(double needed, const ExtractOptions& options, const char* what) {
    const std::size_t limit = memory_limit(options);
    if (needed > double(limit)) {
        std::ostringstream s;
        s << "the " << what << " would need about " << byte_size_text(needed) << ", more than the "
          << byte_size_text(double(limit))
          << " allowed; mesh a smaller region (options.region: a box or a mask) or a coarser grid, or raise the memory limit";
        throw resource_error(s.str());
    }
}

void return_freed_memory() {
#ifdef __GLIBC__
    malloc_trim(0);
#endif
}

}  // namespace pqdc::detail
