// What one rank of a distributed adaptive run (pqdc::extract_adaptive_
// distributed) sends to rank 0: the finest-level cells of its run of bricks
// and stage "hermite"'s counters, as one byte string.
//
// Layout, in the ranks' byte order and word size (the magic number catches a
// mismatch): u64 magic, 4 x u64 counters (crossings, degenerate, clamped,
// fallback), u64 cells, then per array the cells' codes (u64), flags (u8),
// quadrics (CellQuadrics) and vertices (3 doubles). Cells in any order:
// rank 0 puts the whole level in code order.
#pragma once

#include "adaptive/finest_level.hpp"
#include "adaptive/octree.hpp"

#include <string>

namespace pqdc::adaptive_detail {

/// Encodes `cells` (a finest level: no child arrays) and `counters`, and
/// empties `cells` (they now belong to rank 0).
std::string encode_finest_part(Level& cells, const FinestCounters& counters);

/// Appends a part's cells to `cells` and adds its counters to `counters`.
/// Throws std::logic_error on a malformed part.
void decode_finest_part(const std::string& part, Level& cells, FinestCounters& counters);

}  // namespace pqdc::adaptive_detail
