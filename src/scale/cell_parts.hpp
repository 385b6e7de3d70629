// What one rank of a distributed run sends to rank 0 (scale/
// distributed_values.hpp): the cells stage's results for its run of
// candidate leaves, and its counters, as one byte string.
//
// Layout, in the byte order and word size of the ranks (a distributed run
// needs them to agree; the magic number catches a mismatch):
//   u64 magic, u64 first leaf, u64 end leaf, 6 x u64 counters,
//   per leaf: u8 present; if present: u32 faces, u32 incidences,
//     u64 points, the points (3 doubles each), the leaf's value mask
//     (8 x u64) and its active cell records (i32, in offset order; the
//     receiver sets the leaf's index, which the records do not hold).
#pragma once

#include "uniform/cells.hpp"

#include <openvdb/openvdb.h>

#include <cstddef>
#include <string>
#include <vector>

namespace pqdc::detail {

/// Encodes leaves [begin, end) of `results` with `counters`, and clears
/// those leaves of `results` (they now belong to rank 0).
std::string encode_cell_part(LeafResults& results, std::size_t begin, std::size_t end, const CellCounters& counters);

/// Decodes a part into `results` (whose leaves it names must be empty),
/// with `origins` the candidate leaf origins (the records' leaves), and
/// returns its counters. Throws std::logic_error on a malformed part.
CellCounters decode_cell_part(const std::string& part, const std::vector<openvdb::Coord>& origins,
                              LeafResults& results);

}  // namespace pqdc::detail
