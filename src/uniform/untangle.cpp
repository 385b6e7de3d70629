#include "uniform/untangle.hpp"

#include "lattice/untangle.hpp"
#include "uniform/quad_star_check.hpp"

namespace pqdc::detail {

void untangle_lattice_mesh(Mesh& mesh, std::vector<VertexCell> vertex_cell, const LatticeTransform& xf,
                           const ExtractOptions& options, const Progress& progress, ExtractStats& stats) {
    const std::vector<openvdb::Vec3d> safe = safe_positions(vertex_cell, xf);
    const std::vector<std::uint8_t> patches = cell_patches(vertex_cell);
    std::vector<VertexCell>().swap(vertex_cell);
    const LatticeVertices lattice{&safe, &patches, &xf};
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
    untangle_mesh(mesh, safe, xf, untangling, stats);
}

}  // namespace pqdc::detail
