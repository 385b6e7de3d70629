// The test suite of bench_quality: level sets with a known exact surface
// and, where the shape has them, sampled points on its true sharp edges.
#pragma once

#include "pqdc/measure.hpp"
#include "pqdc/procedural.hpp"

#include <openvdb/openvdb.h>

#include <memory>
#include <string>
#include <vector>

namespace quality {

struct Case {
    std::string name;
    openvdb::FloatGrid::Ptr grid;  ///< the clean level set (world-unit distances)
    double voxel = 1;              ///< voxel size, world units
    /// The exact surface: a procedural field (its zero set and gradient) or
    /// the mesh the level set was made from. Exactly one is set.
    std::shared_ptr<const pqdc::ScalarField> field;
    std::shared_ptr<const pqdc::MeshDistance> reference;
    /// Points on the true sharp edges, about a quarter voxel apart; empty for
    /// smooth shapes.
    std::vector<openvdb::Vec3d> feature_points;
};

/// pqdc::make_sphere's default sphere, sampled with sample_field at
/// `resolution` cells across its bounds.
Case sphere_case(int resolution);

/// pqdc::make_rotated_box's default box; features: its 12 edges.
Case box_case(int resolution);

/// A CAD-like part: a box with a cylindrical through-hole and a half sphere
/// fused onto its top face, rotated like the box case. The field is
/// min(max(box, -cylinder), sphere) of exact distance fields: its zero set,
/// gradients and creases are exact; its values are exact distances except
/// in the wedges off convex edges and inside concave ones, where they are
/// below the distance (as with any min/max CSG). Features: the 12 box edges,
/// the two rims of the hole and the circle where the sphere meets the top.
Case csg_case(int resolution);

/// A closed mesh (OFF, OBJ or PLY) converted as pqdc-mesh-to-volume does:
/// pqdc::mesh_to_level_set (exact distances) at `resolution` voxels across
/// its longest side, half width 3. Features (when feature_angle_degrees > 0): the mesh
/// edges whose two faces' normals differ by more than that angle.
Case mesh_case(const std::string& name, const std::string& path, int resolution, double feature_angle_degrees);

}  // namespace quality
