#include "bricks/mapped_pages.hpp"

#ifdef __linux__
#include <sys/mman.h>

#include <cstdio>
#include <cstring>
#endif

namespace pqdc::detail {

std::uint64_t release_mapped_volume_pages() {
    std::uint64_t advised = 0;
#ifdef __linux__
    std::FILE* maps = std::fopen("/proc/self/maps", "r");
    if (!maps) return 0;  // no procfs: nothing is released, nothing breaks
    char line[4352];
    while (std::fgets(line, sizeof line, maps)) {
        unsigned long lo = 0, hi = 0;
        char perms[8] = {};
        int path_at = 0;
        if (std::sscanf(line, "%lx-%lx %7s %*s %*s %*s %n", &lo, &hi, perms, &path_at) < 3 || path_at == 0) continue;
        // Read-only data mappings of .vdb files only: never code, never writable memory.
        if (perms[0] != 'r' || perms[1] != '-' || perms[2] != '-') continue;
        char* path = line + path_at;
        path[std::strcspn(path, "\n")] = '\0';
        const std::size_t n = std::strlen(path);
        if (n < 4 || std::strcmp(path + n - 4, ".vdb") != 0) continue;
        if (madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_DONTNEED) == 0) advised += hi - lo;
    }
    std::fclose(maps);
#endif
    return advised;
}

}  // namespace pqdc::detail
