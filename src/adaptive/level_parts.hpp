// What one rank of a distributed adaptive run (pqdc::extract_adaptive_
// distributed) sends to rank 0: the octree's lower levels of its run of
// bricks (adaptive/brick_levels.hpp) and the counters of stage "hermite"
// and of their merges, as one byte string.
//
// Layout, in the ranks' byte order and word size (the magic number catches a
// mismatch): u64 magic, 6 x u64 finest counters (crossings, degenerate,
// clamped, fallback, cells, non-finite), 6 x u64 merge counters (merges, then refusals:
// error, topology, containment, balance, pinned), u64 levels, then per
// level u64 nodes and the arrays: codes (u64), flags (u8), child masks
// (u8, none at level 0), quadrics (u64 count, then CellQuadrics) and
// vertices (3 doubles). Nodes in any order: rank 0 sorts the levels and
// links them (sort_and_link).
#pragma once

#include "adaptive/finest_level.hpp"
#include "adaptive/octree.hpp"
#include "adaptive/simplify.hpp"

#include <string>
#include <vector>

namespace pqdc::adaptive_detail {

/// Encodes `levels` and the counters, and empties `levels` (they now
/// belong to rank 0).
std::string encode_levels_part(std::vector<Level>& levels, const FinestCounters& finest, const MergeCounters& merges);

/// Appends a part's nodes to `levels` (which has as many levels) and adds
/// its counters. Throws std::logic_error on a malformed part.
void decode_levels_part(const std::string& part, std::vector<Level>& levels, FinestCounters& finest,
                        MergeCounters& merges);

}  // namespace pqdc::adaptive_detail
