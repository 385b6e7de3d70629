// Small analytic meshes shared by the tests of the mesh consumers
// (measures, renderer).
#pragma once

#include "pqdc/mesh.hpp"

#include <openvdb/openvdb.h>

#include <cmath>

namespace pqdc_test {

/// A closed, outward-oriented UV sphere: a pole vertex at each end, rings-1
/// rings of `segments` vertices, triangles at the poles and quads between.
inline pqdc::Mesh uv_sphere(openvdb::Vec3d center, double radius, int rings, int segments) {
    pqdc::Mesh m;
    const double pi = 3.14159265358979323846;
    m.points.push_back(center + openvdb::Vec3d(0, 0, radius));
    for (int i = 1; i < rings; ++i) {
        const double t = pi * i / rings;
        for (int j = 0; j < segments; ++j) {
            const double f = 2 * pi * j / segments;
            const openvdb::Vec3d unit(std::sin(t) * std::cos(f), std::sin(t) * std::sin(f), std::cos(t));
            m.points.push_back(center + radius * unit);
        }
    }
    m.points.push_back(center + openvdb::Vec3d(0, 0, -radius));
    const unsigned south = unsigned(m.points.size() - 1);
    auto at = [&](int i, int j) { return unsigned(1 + (i - 1) * segments + (j % segments)); };
    for (int j = 0; j < segments; ++j) {
        m.triangles.emplace_back(0, at(1, j), at(1, j + 1));
        m.triangles.emplace_back(at(rings - 1, j), south, at(rings - 1, j + 1));
        for (int i = 1; i + 1 < rings; ++i)
            m.quads.emplace_back(at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
    }
    return m;
}

}  // namespace pqdc_test
