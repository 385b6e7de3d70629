// The interior rule (pqdc::choose_interior): grid class, then background,
// then the active region's boundary. A density or CT grid of unknown class
// (background -1000 HU, isovalue 300) must come out with outward faces.
#include "lattice/interior.hpp"
#include "lattice/leaf_values.hpp"

#include <openvdb/tools/Morphology.h>

#include <cmath>
#include <sstream>

namespace pqdc {
namespace {

std::string number(double v) {
    std::ostringstream s;
    s << v;
    return s.str();
}

/// Values of the active voxels that have an inactive face neighbour (the
/// boundary of the active region): how many lie above and below `iso`.
template <class GridT>
void boundary_votes(const GridT& grid, double iso, std::uint64_t& above, std::uint64_t& below) {
    openvdb::MaskTree inner(grid.tree(), false, openvdb::TopologyCopy());
    openvdb::tools::erodeActiveValues(inner, 1, openvdb::tools::NN_FACE, openvdb::tools::IGNORE_TILES);
    openvdb::tree::ValueAccessor<const openvdb::MaskTree> acc(inner);
    for (auto leaf = grid.tree().cbeginLeaf(); leaf; ++leaf) {
        const auto* inner_leaf = acc.probeConstLeaf(leaf->origin());
        detail::with_leaf_values(*leaf, [&](const auto& values) {
            for (auto it = values.cbeginValueOn(); it; ++it) {
                if (inner_leaf && inner_leaf->isValueOn(it.pos())) continue;
                const double v = double(*it);
                above += v > iso;
                below += v < iso;
            }
        });
    }
}

template <class GridT>
bool vote_from_boundary(const GridT& grid, double iso, InteriorChoice& c) {
    std::uint64_t above = 0, below = 0;
    boundary_votes(grid, iso, above, below);
    if (above == below) return false;
    const bool outside_above = above > below;
    c.side = outside_above ? Interior::below_isovalue : Interior::above_isovalue;
    // A NaN background is on neither side of the isovalue either.
    const bool nan_background = std::isnan(double(grid.background()));
    c.reason = std::string("unknown grid class; the background ") +
               (nan_background ? "is NaN" : "equals the isovalue") + ", and " +
               std::to_string(outside_above ? above : below) + " of the " + std::to_string(above + below) +
               " values on the active region's boundary are " + (outside_above ? "above" : "below") +
               " it, so that side is outside";
    return true;
}

}  // namespace

InteriorChoice choose_interior(const openvdb::GridBase& grid, const ExtractOptions& options) {
    InteriorChoice c;
    if (options.interior != Interior::automatic) {
        c.side = options.interior;
        c.reason = "set by the interior option";
        return c;
    }
    if (grid.getGridClass() == openvdb::GRID_LEVEL_SET) {
        c.side = Interior::below_isovalue;
        c.reason = "grid class level set: inside negative";
        return c;
    }
    if (grid.getGridClass() == openvdb::GRID_FOG_VOLUME) {
        c.side = Interior::above_isovalue;
        c.reason = "grid class fog volume: inside denser";
        return c;
    }
    const auto* f = dynamic_cast<const openvdb::FloatGrid*>(&grid);
    const auto* d = dynamic_cast<const openvdb::DoubleGrid*>(&grid);
    const double iso = options.isovalue;
    const double bg = f ? double(f->background()) : d ? d->background() : NAN;
    if (bg > iso || bg < iso) {
        c.side = bg > iso ? Interior::below_isovalue : Interior::above_isovalue;
        c.reason = "unknown grid class; the background " + number(bg) + " is " + (bg > iso ? "above" : "below") +
                   " the isovalue " + number(iso) + ", so that side is outside";
        return c;
    }
    if (f && vote_from_boundary(*f, iso, c)) return c;
    if (d && vote_from_boundary(*d, iso, c)) return c;
    c.side = Interior::below_isovalue;
    c.reason = "unknown grid class; neither the background nor the active region's boundary decides, so "
               "inside is below, the signed-distance convention";
    return c;
}

namespace detail {

Signing signing_for(const InteriorChoice& choice, const ExtractOptions& options) {
    Signing s;
    s.isovalue = options.isovalue;
    s.sign = choice.side == Interior::above_isovalue ? -1.0 : 1.0;
    return s;
}

}  // namespace detail
}  // namespace pqdc
