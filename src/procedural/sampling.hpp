// Internal: sample_field with a hook on the number of leaf blocks it will
// allocate, so that a run can refuse a field too large for its memory
// limit while the lattice is still being classified, before any leaf exists
// (a 2048^3 sphere used to take 6 s and 860 MB before the first check).
#pragma once

#include "pqdc/procedural.hpp"

#include <cstdint>
#include <functional>

namespace pqdc::detail {

/// Called with the running count of active 8^3 blocks while the lattice is
/// classified (from worker threads, concurrently; it may throw to stop the
/// sampling), and once with the final count before the leaves are allocated.
using BlockCountCheck = std::function<void(std::uint64_t blocks)>;

/// sample_field(field, sampling, nodes) with `check` (see above).
openvdb::FloatGrid::Ptr sample_field_checked(const ScalarField& field, const ProceduralSampling& sampling,
                                             const openvdb::CoordBBox& nodes, const BlockCountCheck& check);

}  // namespace pqdc::detail
