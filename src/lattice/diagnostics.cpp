// What the caller should hear about an input after meshing it: the interior
// side taken and warnings with advice (the library never prints).
#include "lattice/interior.hpp"

#include <openvdb/tools/Count.h>

#include <algorithm>
#include <cmath>
#include <sstream>

namespace pqdc::detail {
namespace {

/// The background and the active value at the far end of the inside, or
/// false for grids other than float and double.
template <class GridT>
bool value_range(const openvdb::GridBase& g, bool inside_above, double& background, double& far) {
    const auto* grid = dynamic_cast<const GridT*>(&g);
    if (!grid) return false;
    background = double(grid->background());
    const auto mm = openvdb::tools::minMax(grid->tree());
    far = inside_above ? double(mm.max()) : double(mm.min());
    return true;
}

std::string percent(std::uint64_t part, std::uint64_t whole) {
    std::ostringstream s;
    s.precision(3);
    s << 100.0 * double(part) / double(whole) << "% (" << part << " of " << whole << ")";
    return s.str();
}

}  // namespace

void report_input(const openvdb::GridBase& grid, const InteriorChoice& choice, const ExtractOptions& options,
                  ExtractStats& stats) {
    const bool above = choice.side == Interior::above_isovalue;
    stats.interior = above ? "above" : "below";
    stats.interior_reason = choice.reason;
    if (stats.vertices == 0) return;
    // Clamps are counted per finest cell (adaptive meshes have fewer vertices than cells).
    const std::uint64_t placed = std::max(stats.vertices, stats.active_cells);
    const double iso = options.isovalue;
    double background = NAN, far = NAN;
    const bool scalar = value_range<openvdb::FloatGrid>(grid, above, background, far) ||
                        value_range<openvdb::DoubleGrid>(grid, above, background, far);
    if (scalar && background == iso) {
        std::ostringstream s;
        s << "the isovalue " << iso << " equals the background (inactive) value of grid '" << grid.getName()
          << "', so the surface runs along the edge of the active voxels and comes out terraced ("
          << percent(stats.clamped_vertices, placed) << " of the vertices clamped to their cells); "
          << "mesh at a level between the background and the inside values";
        if (std::isfinite(far) && far != background)
            s << ", e.g. isovalue " << 0.5 * (background + far) << " (halfway to the "
              << (above ? "largest" : "smallest") << " active value " << far << ")";
        stats.warnings.push_back(s.str());
        return;
    }
    if (double(stats.clamped_vertices) > kClampedWarningFraction * double(placed)) {
        stats.warnings.push_back(
            percent(stats.clamped_vertices, placed) +
            " of the vertices were clamped to their cells (their quadric minimum lay outside): the surface is "
            "terraced where that happens. Usual causes: an isovalue at or near the edge of the active values "
            "(choose a level well inside them), noisy data (raise sigma_n, e.g. 0.3), or sigma_n 0 on "
            "sampled data (use 0.05 or more)");
    }
}

}  // namespace pqdc::detail
