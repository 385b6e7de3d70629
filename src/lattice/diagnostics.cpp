// What the caller should hear about an input after meshing it: the interior
// side taken and warnings with advice (the library never prints).
#include "lattice/interior.hpp"
#include "lattice/leaf_values.hpp"

#include <openvdb/tools/Count.h>

#include <algorithm>
#include <cmath>
#include <sstream>

namespace pqdc::detail {
namespace {

/// The active value at the far end of the inside (the largest or the
/// smallest), or false for grids other than float and double.
template <class GridT>
bool far_value(const openvdb::GridBase& g, bool inside_above, double& far) {
    const auto* grid = dynamic_cast<const GridT*>(&g);
    if (!grid) return false;
    if (!delay_loaded(grid->tree())) {
        const auto mm = openvdb::tools::minMax(grid->tree());
        far = inside_above ? double(mm.max()) : double(mm.min());
        return true;
    }
    // Leaf by leaf through copies (with_leaf_values), so the grid stays unloaded.
    using ValueT = typename GridT::ValueType;
    bool any = false;
    ValueT lo{}, hi{};
    auto add = [&](ValueT v) {
        if (!any) lo = hi = v;
        lo = std::min(lo, v);
        hi = std::max(hi, v);
        any = true;
    };
    for (auto leaf = grid->tree().cbeginLeaf(); leaf; ++leaf)
        with_leaf_values(*leaf, [&](const auto& l) {
            for (auto it = l.cbeginValueOn(); it; ++it) add(*it);
        });
    auto tiles = grid->tree().cbeginValueOn();
    tiles.setMaxDepth(GridT::TreeType::ValueOnCIter::LEAF_DEPTH - 1);
    for (; tiles; ++tiles)
        if (!tiles.isVoxelValue()) add(*tiles);
    far = inside_above ? double(hi) : double(lo);
    return true;
}

template <class GridT>
bool background_of(const openvdb::GridBase& g, double& background) {
    const auto* grid = dynamic_cast<const GridT*>(&g);
    if (grid) background = double(grid->background());
    return grid != nullptr;
}

/// The background of a float or double grid into `background`; false for other value types.
bool scalar_background(const openvdb::GridBase& g, double& background) {
    return background_of<openvdb::FloatGrid>(g, background) || background_of<openvdb::DoubleGrid>(g, background);
}

/// How many mesh vertices lie in a lattice cell with an inactive corner (the
/// edge of the active region); -1 for grids other than float and double.
template <class GridT>
std::int64_t typed_vertices_at_active_edge(const openvdb::GridBase& g, const Mesh& mesh) {
    const auto* grid = dynamic_cast<const GridT*>(&g);
    if (!grid) return -1;
    // An accessor caches leaves and so loads their buffers; the tree's own
    // lookup reads only the masks.
    if (delay_loaded(grid->tree()))
        return vertices_at_active_edge(grid->transform(), mesh, [&] {
            return [&](const openvdb::Coord& c) { return grid->tree().isValueOn(c); };
        });
    using Accessor = openvdb::tree::ValueAccessor<const typename GridT::TreeType, false>;
    return vertices_at_active_edge(grid->transform(), mesh, [&] {
        return [acc = Accessor(grid->tree())](const openvdb::Coord& c) { return acc.isValueOn(c); };
    });
}

std::string number(double v) {
    std::ostringstream s;
    s << v;
    return s.str();
}

/// "63.6% of the vertices (1712 of 2690)".
std::string percent(std::uint64_t part, std::uint64_t whole, const char* of = "the vertices") {
    std::ostringstream s;
    s.precision(3);
    s << 100.0 * double(part) / double(whole) << "% of " << of << " (" << part << " of " << whole << ")";
    return s.str();
}

/// Why a grid whose values were read gave no surface: its active value
/// range against the isovalue.
template <class GridT>
std::string explain_value_range(const GridT& grid, const ExtractOptions& options, const ExtractStats& stats) {
    double lo = INFINITY, hi = -INFINITY;
    std::uint64_t active = 0;
    for (auto it = grid.cbeginValueOn(); it; ++it) {
        ++active;
        const double v = double(*it);
        if (std::isfinite(v)) lo = std::min(lo, v), hi = std::max(hi, v);
    }
    const double iso = options.isovalue;
    std::ostringstream s;
    s << "no surface in grid '" << grid.getName() << "'; ";
    if (active == 0) {
        s << "it has no active voxels or tiles (an empty grid); the output mesh is empty";
    } else if (!(lo <= hi)) {
        s << "all its active values are NaN or infinite; the output mesh is empty";
    } else if (iso < lo || iso > hi) {
        s << "its active values lie in [" << lo << ", " << hi << "] and the isovalue " << iso
          << " is outside that range; choose --isovalue inside it (the output mesh is empty)";
    } else {
        s << "its active values [" << lo << ", " << hi << "] never change sign across the isovalue " << iso
          << " between neighbouring lattice points";
        if (stats.non_finite_values) s << " that are finite (" << stats.non_finite_values << " NaN voxels)";
        if (iso == lo || iso == hi) {  // a mask or label volume at one of its values
            // With one active value (a mask whose outside is the background),
            // the level to suggest lies towards the background.
            const double other = lo < hi ? (iso == lo ? hi : lo) : double(grid.background());
            s << "; the isovalue is the " << (iso == lo ? "smallest" : "largest")
              << " value, so no point lies beyond it: for a mask or label volume choose a level between two of "
                 "its values";
            if (std::isfinite(other) && other != iso)
                s << (lo < hi ? "" : " or the background") << ", e.g. --isovalue " << 0.5 * (iso + other);
        }
        s << "; the output mesh is empty";
    }
    return s.str();
}

/// The empty mesh's explanation when min_component_voxels removed every
/// component, else empty.
std::string islands_took_all(const ExtractOptions& options, const ExtractStats& stats) {
    const ComponentFilterStats& c = stats.components;
    if (c.components == 0 || c.removed_components != c.components) return {};
    std::ostringstream s;
    s << "--min-component " << options.min_component_voxels << " removed every component (the largest was "
      << c.largest_removed_diagonal_voxels << " voxels across); the output mesh is empty: give a smaller size";
    return s.str();
}

/// Why `grid` gave no surface, in terms the user can act on.
std::string explain_no_surface(const openvdb::GridBase& grid, const ExtractOptions& options, const ExtractStats& stats,
                               ValuesIn values) {
    if (std::string islands = islands_took_all(options, stats); !islands.empty()) return islands;
    const std::string head = "no surface in grid '" + grid.getName() + "'";
    // Crossings, but none with all four of its cells: a face needs them.
    if (stats.crossing_edges > 0 && stats.boundary_crossings == stats.crossing_edges)
        return "the surface of grid '" + grid.getName() + "' crosses " + std::to_string(stats.crossing_edges) +
               " lattice edges, but none has all four cells around it in the region and the active region, "
               "which a face needs; the output mesh is empty (enlarge the --bbox/--mask region or the active "
               "region)";
    if (!options.region.empty())
        return head + " inside the region (--bbox, --mask); the output mesh is empty (check the region against "
                      "the grid's bounds with vdb_print -l)";
    // Values left in the file (out of core): reading them all to explain
    // would load the whole volume, which delayed loading avoids.
    const auto* f = dynamic_cast<const openvdb::FloatGrid*>(&grid);
    const auto* d = dynamic_cast<const openvdb::DoubleGrid*>(&grid);
    if (values == ValuesIn::files || (f && delay_loaded(f->tree())) || (d && delay_loaded(d->tree())))
        return head + " (meshed out of core; its value range was not read: vdb_print -l shows it); the output "
                      "mesh is empty";
    if (f) return explain_value_range(*f, options, stats);
    if (d) return explain_value_range(*d, options, stats);
    return head + "; the output mesh is empty";
}

}  // namespace

void report_empty_field(const Mesh& mesh, const ExtractOptions& options, ExtractStats& stats) {
    if (!mesh.empty()) return;
    const std::string islands = islands_took_all(options, stats);
    stats.warnings.push_back(islands.empty() ? "no surface found in the procedural field; the output mesh is empty"
                                             : islands);
}

std::int64_t vertices_at_active_edge(const openvdb::GridBase& grid, const Mesh& mesh) {
    const std::int64_t n = typed_vertices_at_active_edge<openvdb::FloatGrid>(grid, mesh);
    return n >= 0 ? n : typed_vertices_at_active_edge<openvdb::DoubleGrid>(grid, mesh);
}

bool may_warn_of_active_edge(const ExtractStats& stats) {
    const std::uint64_t placed = std::max(stats.vertices, stats.active_cells);
    return double(stats.clamped_vertices) > kClampedWarningFraction * double(placed);
}

bool isovalue_is_background(const openvdb::GridBase& grid, const ExtractOptions& options) {
    double background = NAN;
    return scalar_background(grid, background) && background == options.isovalue;
}

bool may_warn_of_active_edge_after_cells(const ExtractStats& stats) {
    // placed = max(vertices, active cells) >= active cells at the end.
    ExtractStats bound;
    bound.active_cells = stats.active_cells;
    bound.clamped_vertices = stats.clamped_vertices;
    return may_warn_of_active_edge(bound);
}

void report_input(const openvdb::GridBase& grid, const InteriorChoice& choice, const ExtractOptions& options,
                  const Mesh& mesh, ExtractStats& stats) {
    report_input(grid, choice, options, mesh.points.size(), [&] { return vertices_at_active_edge(grid, mesh); }, stats);
}

void report_input(const openvdb::GridBase& grid, const InteriorChoice& choice, const ExtractOptions& options,
                  std::uint64_t points, const std::function<std::int64_t()>& at_active_edge, ExtractStats& stats,
                  ValuesIn values) {
    const bool above = choice.side == Interior::above_isovalue;
    stats.interior = above ? "above" : "below";
    stats.interior_reason = choice.reason;
    if (stats.vertices == 0) {
        stats.warnings.push_back(explain_no_surface(grid, options, stats, values));
        return;
    }
    // Clamps are counted per finest cell (adaptive meshes have fewer vertices
    // than cells): say so where the counts differ.
    const std::uint64_t placed = std::max(stats.vertices, stats.active_cells);
    const char* clamped_of = stats.vertices < stats.active_cells ? "the finest cells' vertices" : "the vertices";
    const double iso = options.isovalue;
    double background = NAN, far = NAN;
    if (scalar_background(grid, background) && background == iso) {
        if (!far_value<openvdb::FloatGrid>(grid, above, far)) far_value<openvdb::DoubleGrid>(grid, above, far);
        std::ostringstream s;
        s << "the isovalue " << iso << " equals the background (inactive) value of grid '" << grid.getName()
          << "', so the surface runs along the edge of the active voxels and comes out terraced: "
          << percent(stats.clamped_vertices, placed, clamped_of) << " were clamped to their cells; "
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
    if (!may_warn_of_active_edge(stats)) return;
    const std::int64_t edge = at_active_edge();
    if (edge < 0 || 2 * std::uint64_t(edge) < points) return;
    stats.warnings.push_back(
        "the surface runs along the edge of the active region of grid '" + grid.getName() + "': " +
        percent(std::uint64_t(edge), points) + " lie in cells with an inactive corner and " +
        percent(stats.clamped_vertices, placed, clamped_of) +
        " were clamped to their cells, so it comes out terraced; mesh at a level well inside the "
        "active values (away from the background " + number(background) + "), or activate more of the grid around "
        "the surface");
}

}  // namespace pqdc::detail
