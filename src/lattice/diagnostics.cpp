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

/// How many mesh vertices lie in a lattice cell with an inactive corner (the
/// edge of the active region); -1 for grids other than float and double.
template <class GridT>
std::int64_t vertices_at_active_edge(const openvdb::GridBase& g, const Mesh& mesh) {
    const auto* grid = dynamic_cast<const GridT*>(&g);
    if (!grid) return -1;
    auto acc = grid->getConstAccessor();
    std::int64_t n = 0;
    for (const openvdb::Vec3d& p : mesh.points) {
        const openvdb::Vec3d i = grid->transform().worldToIndex(p);
        const openvdb::Coord c = openvdb::Coord::floor(i);
        bool all_on = true;
        for (int k = 0; k < 8 && all_on; ++k) all_on = acc.isValueOn(c.offsetBy(k & 1, (k >> 1) & 1, (k >> 2) & 1));
        n += !all_on;
    }
    return n;
}

std::string number(double v) {
    std::ostringstream s;
    s << v;
    return s.str();
}

/// "63.6% of the vertices (1712 of 2690)".
std::string percent(std::uint64_t part, std::uint64_t whole) {
    std::ostringstream s;
    s.precision(3);
    s << 100.0 * double(part) / double(whole) << "% of the vertices (" << part << " of " << whole << ")";
    return s.str();
}

}  // namespace

void report_input(const openvdb::GridBase& grid, const InteriorChoice& choice, const ExtractOptions& options,
                  const Mesh& mesh, ExtractStats& stats) {
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
          << "', so the surface runs along the edge of the active voxels and comes out terraced: "
          << percent(stats.clamped_vertices, placed) << " were clamped to their cells; "
          << "mesh at a level between the background and the inside values";
        if (std::isfinite(far) && far != background)
            s << ", e.g. isovalue " << 0.5 * (background + far) << " (halfway to the "
              << (above ? "largest" : "smallest") << " active value " << far << ")";
        stats.warnings.push_back(s.str());
        return;
    }
    // Clamps alone are ordinary on fine detail (armadillo: 7%, the Figure 3
    // field: 40%); what terraces is a surface pressed against the active
    // region's edge, where the values end.
    if (double(stats.clamped_vertices) <= kClampedWarningFraction * double(placed)) return;
    std::int64_t edge = vertices_at_active_edge<openvdb::FloatGrid>(grid, mesh);
    if (edge < 0) edge = vertices_at_active_edge<openvdb::DoubleGrid>(grid, mesh);
    if (edge < 0 || 2 * std::uint64_t(edge) < mesh.points.size()) return;
    stats.warnings.push_back(
        "the surface runs along the edge of the active region of grid '" + grid.getName() + "': " +
        percent(std::uint64_t(edge), mesh.points.size()) + " lie in cells with an inactive corner and " +
        percent(stats.clamped_vertices, placed) +
        " were clamped to their cells, so it comes out terraced; mesh at a level well inside the "
        "active values (away from the background " + number(background) + "), or activate more of the grid around "
        "the surface");
}

}  // namespace pqdc::detail
