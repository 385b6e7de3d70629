// Catch2 checks and fixtures shared by the extractor tests (uniform and
// adaptive): the watertightness contract every closed test surface must meet,
// and the rotated box's true corners.
#pragma once

#include "robust_oracle.hpp"

#include "pqdc/measure.hpp"
#include "pqdc/mesh.hpp"
#include "pqdc/procedural.hpp"

#include <catch2/catch.hpp>
#include <openvdb/openvdb.h>

#include <array>
#include <cmath>
#include <string>

namespace pqdc_test {

/// Closed, edge- and vertex-manifold, consistently and outward oriented,
/// finite, no degenerate faces, no unreferenced vertices.
inline pqdc::TopologyReport require_watertight(const pqdc::Mesh& mesh, const std::string& what) {
    INFO(what);
    REQUIRE(mesh.face_count() > 0);
    const pqdc::TopologyReport t = pqdc::measure_topology(mesh);
    CHECK(t.closed());
    CHECK(t.edge_manifold());
    CHECK(t.vertex_manifold());
    CHECK(t.consistently_oriented());
    CHECK(t.degenerate_face_count == 0);
    CHECK(t.non_finite_point_count == 0);
    CHECK(t.unreferenced_vertex_count == 0);
    CHECK(signed_volume(mesh) > 0);  // outward winding encloses positive volume
    return t;
}

/// Closed, edge-manifold, consistently oriented and finite: what every
/// closed surface of the CLI and property tests must be (weaker than
/// require_watertight: no volume, vertex-manifold or degeneracy checks).
inline void check_closed_manifold(const pqdc::Mesh& m) {
    REQUIRE(m.face_count() > 0);
    const pqdc::TopologyReport t = pqdc::measure_topology(m);
    CHECK(t.non_finite_point_count == 0);
    CHECK(t.closed());
    CHECK(t.edge_manifold());
    CHECK(t.consistently_oriented());
}

/// The eight corners of make_rotated_box(p), rotated independently of the
/// field's code (Rodrigues), so a wrong rotation there cannot hide.
inline std::array<openvdb::Vec3d, 8> box_corners(const pqdc::BoxParams& p) {
    using openvdb::Vec3d;
    const Vec3d k = p.axis.unitSafe();
    const double th = p.angle_degrees * M_PI / 180.0;
    auto rot = [&](const Vec3d& v) {
        return v * std::cos(th) + k.cross(v) * std::sin(th) + k * (k.dot(v) * (1 - std::cos(th)));
    };
    std::array<Vec3d, 8> c;
    for (int i = 0; i < 8; ++i) {
        const Vec3d local((i & 1 ? 1 : -1) * p.half_extents[0], (i & 2 ? 1 : -1) * p.half_extents[1],
                          (i & 4 ? 1 : -1) * p.half_extents[2]);
        c[i] = p.center + rot(local);
    }
    return c;
}

}  // namespace pqdc_test
