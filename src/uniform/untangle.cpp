#include "uniform/untangle.hpp"

#include "lattice/untangle.hpp"
#include "uniform/quad_star_check.hpp"

namespace pqdc::detail {

void untangle_lattice_mesh(Mesh& mesh, VertexCells vertex_cells, const LatticeTransform& xf,
                           const ExtractOptions& options, const Progress& progress, ExtractStats& stats) {
    // The cells stay (8 bytes a vertex) rather than a safe position per
    // vertex (24): the check reads the cells, the repair the safe positions
    // of the vertices it moves.
    const std::vector<std::uint8_t> patches = cell_patches(vertex_cells);
    const LatticeVertices lattice{nullptr, &patches, &xf, &vertex_cells};
    QuadStarCheck quad_stars(mesh, lattice);
    UntangleSettings untangling;
    untangling.stored = options.stored_precision;
    untangling.progress = [&progress](double f) {
        progress.report(0.5 + 0.45 * f);  // the exact check is about half of a clean run's time
        return true;
    };
    untangling.whole_mesh_check = [&quad_stars](const Mesh&, const std::vector<openvdb::Vec3d>& points,
                                                const SelfIntersectionOptions& o) { return quad_stars.whole(points, o); };
    untangling.moved_check = [&quad_stars](const std::vector<openvdb::Vec3d>& points,
                                           const std::vector<std::uint32_t>& moved, SelfIntersections& found) {
        return quad_stars.near(points, moved, found);
    };
    const SafePosition safe = [&](std::uint32_t v) { return safe_position(vertex_cells, v, xf); };
    untangle_mesh(mesh, safe, xf, untangling, stats);
}

}  // namespace pqdc::detail
