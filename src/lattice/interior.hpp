// Which side of the isovalue is inside: one rule for both extractors.
#pragma once

#include <functional>

#include "pqdc/extract.hpp"
#include "pqdc/mesh.hpp"

#include <openvdb/openvdb.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

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

/// Share of clamped vertices above which the surface is checked for hugging
/// the active region's edge (the fog volume of issue 12 clamps 64%).
constexpr double kClampedWarningFraction = 0.05;

/// Where report_input() may read the values to explain an empty mesh: the
/// grid (in memory, or delay-loaded: then they are not read), or only files
/// the grid does not hold (a brick store's shell, a streamed run).
enum class ValuesIn { grid, files };

/// After an extraction of `grid` into `mesh` (world space): stats.interior
/// and interior_reason from the choice, and stats.warnings when the mesh is
/// empty (why: the value range against the isovalue, the region, or
/// min_component_voxels), when the isovalue equals the background, or when
/// more than kClampedWarningFraction of the vertices were clamped and at
/// least half of them lie in cells with an inactive corner: either way the
/// surface hugs the active region's edge.
void report_input(const openvdb::GridBase& grid, const InteriorChoice& choice, const ExtractOptions& options,
                  const Mesh& mesh, ExtractStats& stats);

/// report_input() for a mesh that was written piece by piece: `points` of
/// them, of which at_active_edge() (called only when may_warn_of_active_edge)
/// counts those in cells with an inactive corner.
void report_input(const openvdb::GridBase& grid, const InteriorChoice& choice, const ExtractOptions& options,
                  std::uint64_t points, const std::function<std::int64_t()>& at_active_edge, ExtractStats& stats,
                  ValuesIn values = ValuesIn::grid);

/// report_input()'s warning of an empty mesh for a procedural field (no
/// grid): min_component_voxels removed it all, or the field has no surface.
void report_empty_field(const Mesh& mesh, const ExtractOptions& options, ExtractStats& stats);

/// Whether report_input() will count the vertices at the active region's edge.
bool may_warn_of_active_edge(const ExtractStats& stats);

/// Whether report_input() reads the grid's values: when the isovalue
/// equals the grid's background (its warning names the farthest value).
bool isovalue_is_background(const openvdb::GridBase& grid, const ExtractOptions& options);

/// may_warn_of_active_edge() at the end of a run whose stage "cells" left
/// `stats` (active and clamped cells counted) may be true: later stages
/// only remove vertices, never clamp one.
bool may_warn_of_active_edge_after_cells(const ExtractStats& stats);

/// The vertices of `mesh` (world space) in cells of `grid` with an inactive
/// corner; -1 when `grid` is not a float or double grid.
std::int64_t vertices_at_active_edge(const openvdb::GridBase& grid, const Mesh& mesh);

/// The same count with `xf` the grid's transform and the active states from
/// a lookup that make_lookup() makes for each thread (a callable
/// bool(const Coord&), index space; an accessor caches leaves per thread):
/// for a mask kept after the grid went, and for volumes read through a
/// BrickSource. A sum of counts, so the same for any thread count.
template <class MakeLookup>
std::int64_t vertices_at_active_edge(const openvdb::math::Transform& xf, const Mesh& mesh,
                                     const MakeLookup& make_lookup) {
    return tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, mesh.points.size(), 4096), std::int64_t(0),
        [&](const tbb::blocked_range<std::size_t>& r, std::int64_t n) {
            const auto is_on = make_lookup();
            for (std::size_t v = r.begin(); v != r.end(); ++v) {
                const openvdb::Coord c = openvdb::Coord::floor(xf.worldToIndex(mesh.points[v]));
                bool all_on = true;
                for (int k = 0; k < 8 && all_on; ++k) all_on = is_on(c.offsetBy(k & 1, (k >> 1) & 1, (k >> 2) & 1));
                n += !all_on;
            }
            return n;
        },
        std::plus<>());
}

}  // namespace pqdc::detail
