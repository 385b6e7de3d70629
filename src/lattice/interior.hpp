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

/// The signing of a resolved interior choice.
Signing signing_for(const InteriorChoice& choice, const ExtractOptions& options);

}  // namespace pqdc::detail

namespace pqdc::detail {

/// Share of clamped vertices above which the caller is warned: ordinary
/// level sets clamp well under 1% (see the README's measurements).
constexpr double kClampedWarningFraction = 0.05;

/// After an extraction of `grid`: stats.interior and interior_reason from
/// the choice, and stats.warnings when the isovalue equals the background
/// (the surface hugs the active region's edge) or more than
/// kClampedWarningFraction of the vertices were clamped.
void report_input(const openvdb::GridBase& grid, const InteriorChoice& choice, const ExtractOptions& options,
                  ExtractStats& stats);

}  // namespace pqdc::detail
