#include "pqdc/vertex_normals.hpp"

#include "pqdc/exceptions.hpp"

#include <openvdb/math/Operators.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <cmath>
#include <functional>
#include <string>
#include <vector>

namespace pqdc {
namespace {

using openvdb::Vec3d;

/// Area-weighted face normals summed at each vertex (quads as 0-1-2, 0-2-3).
std::vector<Vec3d> face_normal_sums(const Mesh& mesh) {
    std::vector<Vec3d> sum(mesh.points.size(), Vec3d(0.0));
    auto add = [&](unsigned a, unsigned b, unsigned c) {
        const Vec3d& pa = mesh.points[a];
        const Vec3d n = (mesh.points[b] - pa).cross(mesh.points[c] - pa);  // twice the area, outward by winding
        sum[a] += n, sum[b] += n, sum[c] += n;
    };
    for (const auto& t : mesh.triangles) add(t[0], t[1], t[2]);
    for (const auto& q : mesh.quads) add(q[0], q[1], q[2]), add(q[0], q[2], q[3]);
    return sum;
}

bool finite(const Vec3d& v) { return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]); }

/// Normalizes the gradients, orients them all by the one sign under which
/// they agree best with the faces, and falls back to the faces' normal.
void finish(Mesh& mesh, std::vector<Vec3d>& gradient) {
    const std::vector<Vec3d> faces = face_normal_sums(mesh);
    double agreement = 0;  // serial sum: the sign must not depend on thread scheduling
    for (std::size_t i = 0; i < gradient.size(); ++i) {
        const double len = gradient[i].length();
        if (finite(gradient[i]) && len > 0 && std::isfinite(len)) {
            gradient[i] /= len;
            const double f = faces[i].length();
            if (f > 0) agreement += gradient[i].dot(faces[i]) / f;
        } else {
            gradient[i] = Vec3d(0.0);
        }
    }
    const double sign = agreement < 0 ? -1.0 : 1.0;
    for (std::size_t i = 0; i < gradient.size(); ++i) {
        if (gradient[i] != Vec3d(0.0)) {
            gradient[i] *= sign;
        } else {
            const double f = faces[i].length();
            gradient[i] = f > 0 && std::isfinite(f) ? faces[i] / f : Vec3d(0.0);
        }
    }
    mesh.normals = std::move(gradient);
}

template <class GridT>
void grid_normals(Mesh& mesh, const GridT& grid) {
    const openvdb::math::Transform& xf = grid.transform();
    std::vector<Vec3d> gradient(mesh.points.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mesh.points.size(), 4096), [&](const auto& r) {
        auto acc = grid.getConstAccessor();
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            const Vec3d x = xf.worldToIndex(mesh.points[i]);
            const openvdb::Coord base(int(std::floor(x[0])), int(std::floor(x[1])), int(std::floor(x[2])));
            const Vec3d t = x - base.asVec3d();
            Vec3d g(0.0);
            for (int c = 0; c < 8; ++c) {
                const openvdb::Coord ijk = base.offsetBy(c & 1, (c >> 1) & 1, (c >> 2) & 1);
                const double w = ((c & 1) ? t[0] : 1 - t[0]) * ((c & 2) ? t[1] : 1 - t[1]) *
                                 ((c & 4) ? t[2] : 1 - t[2]);
                if (w == 0) continue;
                const auto gi = openvdb::math::ISGradient<openvdb::math::CD_2ND>::result(acc, ijk);
                g += w * Vec3d(gi[0], gi[1], gi[2]);
            }
            // A gradient is a covector: index-space to world through the inverse Jacobian transpose.
            gradient[i] = xf.baseMap()->applyIJT(g, x);
        }
    });
    finish(mesh, gradient);
}

}  // namespace

void compute_vertex_normals(Mesh& mesh, const openvdb::GridBase& grid) {
    if (const auto* f = dynamic_cast<const openvdb::FloatGrid*>(&grid)) return grid_normals(mesh, *f);
    if (const auto* d = dynamic_cast<const openvdb::DoubleGrid*>(&grid)) return grid_normals(mesh, *d);
    throw input_error("vertex normals need a float or double grid; grid '" + grid.getName() + "' holds " +
                      grid.valueType() + " values");
}

void compute_vertex_normals(Mesh& mesh, const ScalarField& field) {
    std::vector<Vec3d> gradient(mesh.points.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mesh.points.size(), 4096), [&](const auto& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) gradient[i] = field.gradient(mesh.points[i]);
    });
    finish(mesh, gradient);
}

}  // namespace pqdc
