// Internal: large arrays on transparent huge pages. On a kernel that grants
// them on request only (THP "madvise", Debian's default) every first touch of
// a 4 KiB page is a fault, which on the VMs measured here cost about 11 us:
// more than the work done on the page. The lowest layer, so that the file
// readers use it as the meshers and the decimation do.
#pragma once

#include <cstddef>

namespace pqdc::detail {

/// Asks the kernel to back the whole 2 MiB pages inside [data, data +
/// bytes) with transparent huge pages (Linux; elsewhere nothing).
void advise_huge_pages(const void* data, std::size_t bytes);

/// What reserve_large advises: smaller arrays fault too few pages to matter.
constexpr std::size_t kHugePageAdviceBytes = std::size_t(4) << 20;

/// buffer.reserve(n) for a std::vector or std::string; capacity it adds of
/// 4 MiB or more is advised onto huge pages before anything touches it. A
/// large array filled once then takes one page fault per 2 MiB instead of
/// 512: with a kernel that grants huge pages on request only, the faults
/// were half of stage "faces" on a 4.7 M-voxel sphere (bench_extract).
/// Call it before resize or assign.
template <class Buffer>
void reserve_large(Buffer& buffer, std::size_t n) {
    if (n <= buffer.capacity()) return;
    buffer.reserve(n);
    const std::size_t fresh = (n - buffer.size()) * sizeof(*buffer.data());
    if (fresh >= kHugePageAdviceBytes) advise_huge_pages(buffer.data() + buffer.size(), fresh);
}

}  // namespace pqdc::detail
