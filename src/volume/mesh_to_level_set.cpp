// Closed meshes to level sets with exact distances (include/pqdc/mesh_to_volume.hpp).
//
// Stages: check the mesh and options; classify its edges (is the pseudo-normal
// sign valid?); OpenVDB's meshToLevelSet for the band and the flood-fill sign;
// every active value replaced by the exact signed distance, leaf-parallel.
#include "pqdc/mesh_to_volume.hpp"

#include "pqdc/exceptions.hpp"
#include "pqdc/measure.hpp"

#include "../measure/mesh_internal.hpp"

#include <openvdb/tools/MeshToVolume.h>
#include <openvdb/tree/LeafManager.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

namespace pqdc {

namespace {

/// OpenVDB's transforms refuse scales it takes for zero (ArithmeticError "Non-zero scale values required"):
/// a scale map whose determinant is within 3e-15 of zero, so a cubic voxel of edge 1.4422e-5 or less
/// (1e-8 here let 1e-8..1.44e-5 through to that raw message; a 1 mm part in metres at 128 voxels).
constexpr double kSmallestVoxelSize = 1.5e-5;

void validate(const MeshToLevelSetOptions& o) {
    if (!(std::isfinite(o.voxel_size) && o.voxel_size > 0))
        throw option_error("MeshToLevelSetOptions::voxel_size is " + std::to_string(o.voxel_size) +
                           "; give the voxel edge length in world units (> 0)");
    if (o.voxel_size < kSmallestVoxelSize) {
        std::ostringstream s;
        s << "MeshToLevelSetOptions::voxel_size is " << o.voxel_size << "; OpenVDB's transforms need at least "
          << kSmallestVoxelSize << " world units: scale the mesh up (its units are free) and the voxel size with it";
        throw option_error(s.str());
    }
    if (!(o.half_width_voxels >= 1 && o.half_width_voxels <= 1000))
        throw option_error("MeshToLevelSetOptions::half_width_voxels is " + std::to_string(o.half_width_voxels) +
                           "; it must be in [1, 1000] voxels");
}

void check_mesh(const Mesh& mesh) {
    if (mesh.face_count() == 0)
        throw input_error("mesh has no faces (" + std::to_string(mesh.points.size()) +
                          " points); a level set needs a closed surface");
    detail::check_indices(mesh);
    auto check_point = [&](unsigned v) {
        const openvdb::Vec3d& p = mesh.points[v];
        if (!(std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2])))
            throw input_error("mesh point " + std::to_string(v) +
                              " has a NaN or infinite coordinate; fix it or drop the faces using it");
    };
    for (const auto& t : mesh.triangles)
        for (int k = 0; k < 3; ++k) check_point(t[k]);
    for (const auto& q : mesh.quads)
        for (int k = 0; k < 4; ++k) check_point(q[k]);
}

/// Counts the boundary and inconsistent edges of the polygons as given (quads
/// are not split: their diagonal is interior).
void classify_edges(const Mesh& mesh, MeshToLevelSetStats& stats) {
    struct Use {
        std::uint64_t key;  // smaller vertex << 32 | larger vertex
        bool forward;       // the face walks it from smaller to larger
        bool operator<(const Use& o) const { return key != o.key ? key < o.key : forward < o.forward; }
    };
    std::vector<Use> uses;
    uses.reserve(3 * mesh.triangles.size() + 4 * mesh.quads.size());
    auto add = [&](unsigned a, unsigned b) {
        uses.push_back({std::uint64_t(std::min(a, b)) << 32 | std::max(a, b), a < b});
    };
    for (const auto& t : mesh.triangles)
        for (int k = 0; k < 3; ++k) add(t[k], t[(k + 1) % 3]);
    for (const auto& q : mesh.quads)
        for (int k = 0; k < 4; ++k) add(q[k], q[(k + 1) % 4]);
    std::sort(uses.begin(), uses.end());
    for (std::size_t i = 0; i < uses.size();) {
        std::size_t j = i;
        while (j < uses.size() && uses[j].key == uses[i].key) ++j;
        if (j - i == 1)
            ++stats.boundary_edges;
        else if (j - i != 2 || uses[i].forward == uses[i + 1].forward)
            ++stats.inconsistent_edges;
        i = j;
    }
}

/// +1 when the faces wind counter-clockwise seen from outside (positive
/// enclosed volume), -1 when the mesh is inside out.
double orientation(const Mesh& mesh) {
    // Relative to a point of the mesh: far from the origin the products of
    // absolute coordinates cancel catastrophically.
    const openvdb::Vec3d o = mesh.points.empty() ? openvdb::Vec3d(0.0) : mesh.points[0];
    double six_volume = 0;
    for (std::size_t t = 0; t < detail::split_triangle_count(mesh); ++t) {
        const auto c = detail::split_triangle(mesh, t);
        six_volume += (mesh.points[c[0]] - o).dot((mesh.points[c[1]] - o).cross(mesh.points[c[2]] - o));
    }
    return six_volume < 0 ? -1.0 : 1.0;
}

/// Replaces every active value by the exact distance. Each voxel's value
/// depends on its coordinate only, so the grid is the same for any thread
/// count; the counts are summed per leaf in leaf order.
void exact_values(openvdb::FloatGrid& grid, const Mesh& mesh, double sign_flip, MeshToLevelSetStats& stats) {
    const MeshDistance distance(mesh);
    grid.tree().voxelizeActiveTiles();
    openvdb::tree::LeafManager<openvdb::FloatTree> leaves(grid.tree());
    std::vector<std::uint64_t> changed(leaves.leafCount(), 0);
    const bool pseudo_normal_sign = stats.exact_signs;
    leaves.foreach([&](openvdb::FloatTree::LeafNodeType& leaf, std::size_t index) {
        for (auto it = leaf.beginValueOn(); it; ++it) {
            const openvdb::Vec3d p = grid.indexToWorld(it.getCoord());
            const float before = *it;
            float value;
            if (pseudo_normal_sign) {
                value = float(sign_flip * distance.signed_distance(p));
                changed[index] += (value < 0) != (before < 0);
            } else {
                value = std::copysign(float(distance(p)), before);
            }
            it.setValue(value);
        }
    });
    for (std::uint64_t c : changed) stats.signs_changed += c;
}

/// Index coordinates beyond which float loses an eighth of a voxel (2^16: float's spacing is then 2^-7).
constexpr double kFarVoxels = 65536;

/// A multiple of the voxel size per axis near the centre of the mesh's
/// bounding box when that lies beyond kFarVoxels, else zero (the grid's
/// index space then stays the origin's, as always).
openvdb::Vec3d lattice_shift(const Mesh& mesh, double voxel_size) {
    openvdb::Vec3d lo(std::numeric_limits<double>::infinity()), hi(-std::numeric_limits<double>::infinity());
    for (const openvdb::Vec3d& p : mesh.points) {
        lo = openvdb::Vec3d(std::min(lo[0], p[0]), std::min(lo[1], p[1]), std::min(lo[2], p[2]));
        hi = openvdb::Vec3d(std::max(hi[0], p[0]), std::max(hi[1], p[1]), std::max(hi[2], p[2]));
    }
    const openvdb::Vec3d centre_index = (lo + hi) * (0.5 / voxel_size);
    if (!(std::max({std::abs(centre_index[0]), std::abs(centre_index[1]), std::abs(centre_index[2])}) > kFarVoxels))
        return openvdb::Vec3d(0.0);
    return openvdb::Vec3d(std::round(centre_index[0]), std::round(centre_index[1]), std::round(centre_index[2])) *
           voxel_size;
}

}  // namespace

openvdb::FloatGrid::Ptr mesh_to_level_set(const Mesh& mesh, const MeshToLevelSetOptions& options,
                                          MeshToLevelSetStats* stats_out) {
    validate(options);
    check_mesh(mesh);
    MeshToLevelSetStats stats;
    classify_edges(mesh, stats);
    stats.exact_signs = options.distances == LevelSetDistances::exact && stats.boundary_edges == 0 &&
                        stats.inconsistent_edges == 0;

    // OpenVDB takes the points as floats: far from the origin (UTM-sized
    // coordinates) their index coordinates lose whole voxels and the band
    // and signs come out wrong. There the mesh is converted relative to a
    // lattice point near its centre, which the grid's transform then adds.
    const openvdb::Vec3d shift = lattice_shift(mesh, options.voxel_size);
    const auto local = openvdb::math::Transform::createLinearTransform(options.voxel_size);
    std::vector<openvdb::Vec3s> points(mesh.points.size());
    for (std::size_t i = 0; i < points.size(); ++i) points[i] = openvdb::Vec3s(mesh.points[i] - shift);
    openvdb::FloatGrid::Ptr grid = openvdb::tools::meshToLevelSet<openvdb::FloatGrid>(
        *local, points, mesh.triangles, mesh.quads, float(options.half_width_voxels));
    if (!grid || grid->activeVoxelCount() == 0)
        throw input_error("the mesh gave an empty level set; is the voxel size (" + std::to_string(options.voxel_size) +
                          ") far larger than the mesh?");
    if (shift != openvdb::Vec3d(0.0)) {
        auto shifted = openvdb::math::Transform::createLinearTransform(options.voxel_size);
        shifted->postTranslate(shift);
        grid->setTransform(shifted);
    }
    grid->setGridClass(openvdb::GRID_LEVEL_SET);
    if (options.distances == LevelSetDistances::exact)
        exact_values(*grid, mesh, stats.exact_signs ? orientation(mesh) : 1.0, stats);
    stats.active_voxels = grid->activeVoxelCount();
    if (stats_out) *stats_out = stats;
    return grid;
}

}  // namespace pqdc
