// Which side of the isovalue is inside: one rule for both extractors.
#pragma once

#include "pqdc/extract.hpp"

#include <openvdb/openvdb.h>

namespace pqdc::detail {

/// Maps raw grid values to signed values, inside negative. Every later stage
/// sees only signed values, so the interior convention is decided here once.
struct Signing {
    double isovalue = 0.0;
    double sign = 1.0;  ///< +1: inside below isovalue; -1: inside above
    double operator()(double raw) const { return sign * (raw - isovalue); }
};

/// The signing of a grid under the options: Interior::automatic means inside
/// above the isovalue for fog volumes, below for level sets and unknown classes.
Signing grid_signing(openvdb::GridClass grid_class, const ExtractOptions& options);

}  // namespace pqdc::detail
