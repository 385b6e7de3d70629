// Test shape: an L-shaped prism, the union of [0,2]x[0,1]x[0,1] and
// [0,1]x[0,2]x[0,1], rotated and then shifted. Its edge along (1,1,z) is a
// concave crease, where level sets and adaptive meshing are hardest.
#pragma once

#include "pqdc/mesh.hpp"

#include <openvdb/openvdb.h>

namespace pqdc_test {

/// Closed, consistently oriented (counter-clockwise seen from outside):
/// 12 points, 8 cap triangles (a fan around the reflex corner 3), 6 wall quads.
inline pqdc::Mesh l_prism(const openvdb::math::Mat3d& rotation = openvdb::math::Mat3d::identity(),
                          const openvdb::Vec3d& shift = openvdb::Vec3d(0.0)) {
    const double xy[6][2] = {{0, 0}, {2, 0}, {2, 1}, {1, 1}, {1, 2}, {0, 2}};  // counter-clockwise
    pqdc::Mesh m;
    for (int z = 0; z < 2; ++z)
        for (const auto& p : xy) m.points.push_back(rotation * openvdb::Vec3d(p[0], p[1], z) + shift);
    for (unsigned k : {4u, 5u, 0u, 1u}) {
        const unsigned next = k + 1 == 6 ? 0 : k + 1;
        m.triangles.emplace_back(3, next, k);          // bottom, facing -z
        m.triangles.emplace_back(9, 6 + k, 6 + next);  // top, facing +z
    }
    for (unsigned i = 0; i < 6; ++i) m.quads.emplace_back(i, (i + 1) % 6, 6 + (i + 1) % 6, 6 + i);  // walls
    return m;
}

}  // namespace pqdc_test
