// The bench_quality suite (quality_cases.hpp).
#include "quality_cases.hpp"

#include "pqdc/exceptions.hpp"
#include "pqdc/mesh_io.hpp"

#include "pqdc/mesh_to_volume.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <map>
#include <stdexcept>
#include <utility>

namespace quality {

namespace {

using openvdb::Vec3d;

constexpr double kFeatureSpacingVoxels = 0.25;

/// Rotation about a unit axis (Rodrigues), as make_rotated_box rotates.
struct Rotation {
    Vec3d k;
    double c, s;
    Rotation(const Vec3d& axis, double degrees)
        : k(axis.unitSafe()), c(std::cos(degrees * M_PI / 180.0)), s(std::sin(degrees * M_PI / 180.0)) {}
    Vec3d apply(const Vec3d& v) const { return v * c + k.cross(v) * s + k * (k.dot(v) * (1 - c)); }
    Vec3d inverse(const Vec3d& v) const { return v * c - k.cross(v) * s + k * (k.dot(v) * (1 - c)); }
};

void add_segment(std::vector<Vec3d>& out, const Vec3d& a, const Vec3d& b, double voxel) {
    const int n = std::max(1, int(std::ceil((b - a).length() / (kFeatureSpacingVoxels * voxel))));
    for (int i = 0; i <= n; ++i) out.push_back(a + (b - a) * (double(i) / n));
}

/// The 12 edges of the box (center, half extents, rotation), in world space.
void add_box_edges(std::vector<Vec3d>& out, const Vec3d& center, const Vec3d& half, const Rotation& r, double voxel) {
    auto corner = [&](int i) {
        return center + r.apply(Vec3d(i & 1 ? half[0] : -half[0], i & 2 ? half[1] : -half[1], i & 4 ? half[2] : -half[2]));
    };
    for (int i = 0; i < 8; ++i)
        for (int bit : {1, 2, 4})
            if (!(i & bit)) add_segment(out, corner(i), corner(i | bit), voxel);
}

/// Keeps the points on the field's surface (to rounding): a check that the
/// feature curves were built right, and it drops parts of box edges that
/// CSG removed.
std::vector<Vec3d> on_surface(const pqdc::ScalarField& field, const std::vector<Vec3d>& points, double voxel) {
    std::vector<Vec3d> kept;
    for (const Vec3d& p : points)
        if (std::abs(field.value(p)) <= 1e-9 * voxel) kept.push_back(p);
    return kept;
}

Case procedural_case(const std::string& name, std::shared_ptr<const pqdc::ScalarField> field, int resolution) {
    Case c;
    c.name = name;
    pqdc::ProceduralSampling sampling;
    sampling.resolution = resolution;
    c.grid = pqdc::sample_field(*field, sampling);
    c.voxel = c.grid->voxelSize()[0];
    c.field = std::move(field);
    return c;
}

class CsgPart final : public pqdc::ScalarField {
public:
    static constexpr double kHoleRadius = 0.2, kDomeRadius = 0.3;
    CsgPart() : rotation_(Vec3d(1, 2, 3), 30.0) {
        box_params_.center = Vec3d(0.0);
        box_params_.half_extents = Vec3d(0.7, 0.5, 0.3);
        box_params_.axis = Vec3d(1, 2, 3);
        box_params_.angle_degrees = 30.0;
        box_ = pqdc::make_rotated_box(box_params_);
        pqdc::SphereParams dome;
        dome.center = rotation_.apply(dome_center_local());
        dome.radius = kDomeRadius;
        dome_ = pqdc::make_sphere(dome);
    }
    static Vec3d hole_center_local() { return Vec3d(0.3, 0.0, 0.0); }  // axis along local z
    static Vec3d dome_center_local() { return Vec3d(-0.35, 0.0, 0.3); }  // on the top face
    const pqdc::BoxParams& box_params() const { return box_params_; }
    const Rotation& rotation() const { return rotation_; }

    double value(const Vec3d& p) const override {
        return std::min(std::max(box_->value(p), -hole(p)), dome_->value(p));
    }
    Vec3d gradient(const Vec3d& p) const override {
        const double b = box_->value(p), h = -hole(p), d = dome_->value(p);
        if (d < std::max(b, h)) return dome_->gradient(p);
        if (b >= h) return box_->gradient(p);
        Vec3d q = rotation_.inverse(p) - hole_center_local();
        q[2] = 0.0;
        const double l = q.length();
        return l > 0.0 ? rotation_.apply(-q / l) : Vec3d(0.0);
    }
    double lipschitz_bound() const override { return 1.0; }
    openvdb::BBoxd bounds() const override {
        openvdb::BBoxd b = box_->bounds();
        b.expand(dome_->bounds());
        return b;
    }

private:
    double hole(const Vec3d& p) const {  // exact distance to the infinite cylinder, negative inside
        Vec3d q = rotation_.inverse(p) - hole_center_local();
        return std::sqrt(q[0] * q[0] + q[1] * q[1]) - kHoleRadius;
    }
    Rotation rotation_;
    pqdc::BoxParams box_params_;
    std::unique_ptr<pqdc::ScalarField> box_, dome_;
};

void add_circle(std::vector<Vec3d>& out, const Vec3d& center_local, double radius, const Rotation& r, double voxel) {
    const int n = int(std::ceil(2 * M_PI * radius / (kFeatureSpacingVoxels * voxel)));
    for (int i = 0; i < n; ++i) {
        const double a = 2 * M_PI * i / n;
        out.push_back(r.apply(center_local + Vec3d(radius * std::cos(a), radius * std::sin(a), 0.0)));
    }
}

}  // namespace

Case sphere_case(int resolution) {
    return procedural_case("sphere", pqdc::make_procedural("sphere"), resolution);
}

Case box_case(int resolution) {
    const pqdc::BoxParams params;
    std::shared_ptr<const pqdc::ScalarField> field = pqdc::make_rotated_box(params);
    Case c = procedural_case("box", field, resolution);
    std::vector<Vec3d> edges;
    add_box_edges(edges, params.center, params.half_extents, Rotation(params.axis, params.angle_degrees), c.voxel);
    c.feature_points = on_surface(*field, edges, c.voxel);
    if (c.feature_points.size() != edges.size())
        throw std::logic_error("box_case: the box edges do not lie on make_rotated_box's surface");
    return c;
}

Case csg_case(int resolution) {
    auto part = std::make_shared<const CsgPart>();
    Case c = procedural_case("csg", part, resolution);
    std::vector<Vec3d> curves;
    const pqdc::BoxParams& b = part->box_params();
    add_box_edges(curves, b.center, b.half_extents, part->rotation(), c.voxel);
    const double top = b.half_extents[2];
    for (const double z : {-top, top})
        add_circle(curves, CsgPart::hole_center_local() + Vec3d(0, 0, z), CsgPart::kHoleRadius, part->rotation(),
                   c.voxel);
    add_circle(curves, CsgPart::dome_center_local(), CsgPart::kDomeRadius, part->rotation(), c.voxel);
    c.feature_points = on_surface(*part, curves, c.voxel);
    if (c.feature_points.size() != curves.size())
        throw std::logic_error("csg_case: feature curves off the part's surface");
    return c;
}

Case mesh_case(const std::string& name, const std::string& path, int resolution, double feature_angle_degrees) {
    const pqdc::Mesh mesh = pqdc::read_mesh(path);
    openvdb::BBoxd bounds;
    for (const Vec3d& p : mesh.points) bounds.expand(p);
    const Vec3d extent = bounds.extents();
    Case c;
    c.name = name;
    c.voxel = std::max({extent[0], extent[1], extent[2]}) / resolution;
    pqdc::MeshToLevelSetOptions convert;
    convert.voxel_size = c.voxel;
    c.grid = pqdc::mesh_to_level_set(mesh, convert);
    c.reference = std::make_shared<const pqdc::MeshDistance>(mesh);
    if (feature_angle_degrees <= 0) return c;

    // Sharp edges: pairs of triangles (n-gons arrive fan-triangulated, quads
    // split 0-2 as the measures do) sharing an edge at a large normal angle.
    std::vector<std::array<unsigned, 3>> tris;
    for (const auto& t : mesh.triangles) tris.push_back({t[0], t[1], t[2]});
    for (const auto& q : mesh.quads) {
        tris.push_back({q[0], q[1], q[2]});
        tris.push_back({q[0], q[2], q[3]});
    }
    std::map<std::pair<unsigned, unsigned>, std::vector<Vec3d>> edge_normals;
    for (const auto& t : tris) {
        const Vec3d n = (mesh.points[t[1]] - mesh.points[t[0]]).cross(mesh.points[t[2]] - mesh.points[t[0]]).unitSafe();
        for (int k = 0; k < 3; ++k)
            edge_normals[{std::min(t[k], t[(k + 1) % 3]), std::max(t[k], t[(k + 1) % 3])}].push_back(n);
    }
    const double cos_limit = std::cos(feature_angle_degrees * M_PI / 180.0);
    for (const auto& [edge, normals] : edge_normals)
        if (normals.size() == 2 && normals[0].dot(normals[1]) < cos_limit)
            add_segment(c.feature_points, mesh.points[edge.first], mesh.points[edge.second], c.voxel);
    return c;
}

}  // namespace quality
