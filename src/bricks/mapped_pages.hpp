// Handing memory-mapped volume pages back to the kernel between bricks.
//
// A grid read with delayed loading (and every brick-store file) keeps its
// leaf buffers in a memory-mapped .vdb file; a leaf is read from that
// mapping when a brick copies it. Every page touched stays in the
// process's resident set until the mapping goes, which is when the last
// leaf referring to the file goes: for the whole run. Meshing a 1.1 G-voxel
// dense store (3.1 GB of files) so held 3.1 GiB of file pages besides the
// 1.9 GiB the meshing needed. OpenVDB gives no handle on its mappings, so
// this finds them in /proc/self/maps (files named *.vdb, the only files
// OpenVDB maps) and drops their pages with madvise(MADV_DONTNEED). The
// mappings are read-only, so a later read faults the same bytes back in
// from the page cache: output cannot change, only what counts as resident.
#pragma once

#include <cstdint>

namespace pqdc::detail {

/// Drops the resident pages of every mapped .vdb file of this process;
/// returns the bytes of the mappings advised. Linux only (elsewhere a no-op
/// returning 0). Call it where no other thread reads those leaves.
std::uint64_t release_mapped_volume_pages();

}  // namespace pqdc::detail
