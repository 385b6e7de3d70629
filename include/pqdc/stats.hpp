// What happened during an extraction, for logs and --stats: one record for
// both modes (the adaptive one adds its octree's counters).
#pragma once

#include "pqdc/components.hpp"

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace pqdc {

/// Wall time of one named pipeline stage.
struct StageTime {
    std::string name;
    double seconds = 0;
};

struct ExtractStats {
    std::uint64_t active_cells = 0;       ///< cells in the domain with a sign change
    std::uint64_t crossing_edges = 0;     ///< sign-changing lattice edges inside the domain (Hermite samples)
    std::uint64_t degenerate_normals = 0; ///< crossings whose gradient was zero/non-finite (point-only term)
    std::uint64_t vertices = 0;
    std::uint64_t multi_vertex_cells = 0; ///< cells with more than one surface patch (uniform mode)
    std::uint64_t clamped_vertices = 0;   ///< minimizers moved back into their cell
    std::uint64_t fallback_vertices = 0;  ///< solver failures replaced by the mass point
    std::uint64_t triangles = 0;
    std::uint64_t quads = 0;
    std::uint64_t boundary_crossings = 0; ///< crossing edges owned by an active cell but lacking one of their four cells (the mesh is open there; adaptive: finest cells, 0 when the adaptive mesh came out closed)
    std::uint64_t non_finite_values = 0;  ///< active NaN voxels; cells touching them are left out (holes with boundary)
    /// Estimated noise of the volume: median residual of local quadratic fits
    /// of the field near the surface, voxels (0 for procedural fields).
    double noise_voxels = 0;
    std::uint64_t noise_samples = 0;  ///< surface points behind noise_voxels
    double sigma_n = 0;               ///< the sigma_n used (the chosen one when asked for auto)
    std::string gradient;             ///< the gradient stencil used: central, sharp, least_squares or analytic
    int denoise_radius = 0;           ///< cells of quadric filtering around each cell (0: off)
    /// Stage "untangle" (see the README's section on quality): intersecting
    /// triangle pairs plus degenerate triangles it found in the mesh it got
    /// (quads count as their two triangles), the vertices it moved towards
    /// their safe positions (all the way: untangle_snapped), and its repair
    /// rounds. The output has none of these intersections.
    std::uint64_t untangle_found = 0;
    std::uint64_t untangle_moved = 0;
    std::uint64_t untangle_snapped = 0;
    std::uint64_t untangle_rounds = 0;
    /// ExtractOptions::min_component_voxels: what the component filter
    /// found and removed (all zero when it is 0). vertices, triangles and
    /// quads above count the mesh after it.
    ComponentFilterStats components;
    /// The pipeline's stages in the order they ran, each with its wall time
    /// (uniform: candidates, noise estimate, [smooth field], cells, gather,
    /// faces, untangle; adaptive: candidates, noise estimate, [smooth
    /// field], hermite, octree, dual grid, polygons; "smooth field" only
    /// when denoising a grid).
    std::vector<StageTime> stages;
    double seconds_total = 0;
    /// The side taken as inside ("below" or "above" the isovalue; procedural
    /// fields: "below") and why (see pqdc::choose_interior).
    std::string interior;
    std::string interior_reason;
    /// Things the caller should tell the user, each a sentence with advice:
    /// the isovalue equals the background (the surface hugs the active
    /// region's edge), or more than 5% of the vertices were clamped.
    std::vector<std::string> warnings;

    /// The time of the named stage; 0 when the pipeline has no such stage.
    double seconds(std::string_view stage) const {
        for (const StageTime& s : stages)
            if (s.name == stage) return s.seconds;
        return 0;
    }
};

/// ExtractStats plus what the octree did.
struct AdaptiveStats : ExtractStats {
    /// Surface leaves per level: [L] counts leaves of edge length 2^L voxels.
    std::array<std::uint64_t, 13> leaves_per_level{};
    std::uint64_t surface_leaves = 0;      ///< leaves holding surface (one vertex each)
    std::uint64_t empty_leaves = 0;        ///< empty leaves beside surface (siblings of surface nodes, roots next to surface roots)
    std::uint64_t merges = 0;              ///< parents that became leaves
    std::uint64_t refused_error = 0;       ///< merges refused: collapse error >= max_error_voxels
    std::uint64_t refused_topology = 0;    ///< merges refused by the sign/manifold tests
    std::uint64_t refused_containment = 0; ///< merges refused: vertex outside the parent or the region
    std::uint64_t refused_balance = 0;     ///< merges refused: a neighbour is more than one level finer
    std::uint64_t refused_pinned = 0;      ///< merges refused: the parent holds a cell pinned by stage "untangle"
    std::uint64_t dual_cells = 0;          ///< dual cells with at least one surface leaf
    std::uint64_t filled_pockets = 0;      ///< empty outside leaves walled in by surface leaves, set inside (no bubble)
    std::uint64_t undefined_leaves_inside = 0;  ///< empty leaves without a field value (NaN) set inside: they touch only inside empty leaves
    std::uint64_t collapsed_vertices = 0;  ///< coincident crossings merged by edge collapses
    std::uint64_t added_vertices = 0;      ///< loops fanned around an added (projected) center vertex
    std::uint64_t separated_vertices = 0;  ///< coincident vertices no collapse could merge, moved 1e-4 apart
    std::uint64_t relaxed_vertices = 0;    ///< vertices moved by the tangential relaxation (along flat parts and creases)
    std::uint64_t angle_flips = 0;         ///< edges flipped to raise the smallest angle of flat triangle pairs
    /// Stage "bridges": edges of the first build that joined two sheets
    /// across empty space (their middle well outside the surface), and the
    /// finest cells kept from merging around their ends until none was left.
    std::uint64_t bridges_found = 0;
    std::uint64_t bridge_pinned_cells = 0;
    /// Stage "untangle" refines before it moves vertices (the untangle_*
    /// counters above; untangle_rounds counts octree rebuilds and move
    /// rounds): the finest cells kept from merging, around the corners of
    /// offending triangles.
    std::uint64_t untangle_pinned_cells = 0;
    /// Intersecting pairs + degenerate triangles that refinement and moves
    /// left (adaptive/untangle.hpp, step 3); when not 0 the output is the
    /// uniform extractor's mesh, untangle_fallback is set and a warning says so.
    std::uint64_t untangle_unresolved = 0;
    bool untangle_fallback = false;
    /// Stage "untangle" could not repair the mesh with its shape steps
    /// (tangential relaxation, angle flips) and built it again without them
    /// (before any fallback to uniform).
    bool untangle_flips_dropped = false;
};

}  // namespace pqdc
