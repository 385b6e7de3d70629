// What extract.hpp promises about a mesh, checked against the grid it came
// from. Shared by the property tests and the libFuzzer target.
#pragma once

#include "pqdc/adaptive.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/measure.hpp"
#include "pqdc/mesh.hpp"
#include "lattice/smooth_field.hpp"

#include <openvdb/openvdb.h>

#include <cmath>
#include <sstream>
#include <string>

namespace pqdc_test {

/// The domain rule of extract.hpp computed directly from the grid: a cell
/// takes part when one of its 8 corners is active and none is NaN; the
/// surface is closed when every sign-changing lattice edge has an active
/// end point (so all four cells around it take part) and there is no NaN.
template <class GridT>
struct DomainOracle {
    const GridT& grid;
    double isovalue;
    double sign;  // +1: inside below the isovalue
    mutable typename GridT::ConstAccessor acc;

    DomainOracle(const GridT& g, const pqdc::ExtractOptions& o)
        : grid(g), isovalue(o.isovalue), sign(inside_sign(g, o)), acc(g.getConstAccessor()) {}

    static double inside_sign(const GridT& g, const pqdc::ExtractOptions& o) {
        if (o.interior == pqdc::Interior::below_isovalue) return 1.0;
        if (o.interior == pqdc::Interior::above_isovalue) return -1.0;
        // Interior::automatic: class, then the background (outside), as
        // pqdc::choose_interior documents; the active-boundary vote for a
        // background equal to the isovalue is its own (test_interior.cpp).
        if (g.getGridClass() == openvdb::GRID_LEVEL_SET) return 1.0;
        if (g.getGridClass() == openvdb::GRID_FOG_VOLUME) return -1.0;
        const double bg = double(g.background());
        if (bg > o.isovalue) return 1.0;
        if (bg < o.isovalue) return -1.0;
        return pqdc::choose_interior(g, o).side == pqdc::Interior::above_isovalue ? -1.0 : 1.0;
    }

    double value(const openvdb::Coord& p) const { return sign * (double(acc.getValue(p)) - isovalue); }
    bool inside(const openvdb::Coord& p) const { return value(p) < 0.0; }
    bool active(const openvdb::Coord& p) const { return acc.isValueOn(p); }

    /// The cell with minimum corner c takes part and the surface crosses it.
    bool cell_in_domain_with_surface(const openvdb::Coord& c) const {
        bool any_active = false, any_in = false, any_out = false;
        for (int k = 0; k < 8; ++k) {
            const openvdb::Coord p = c + openvdb::Coord(k & 1, (k >> 1) & 1, (k >> 2) & 1);
            if (std::isnan(value(p))) return false;
            any_active |= active(p);
            (inside(p) ? any_in : any_out) = true;
        }
        return any_active && any_in && any_out;
    }

    bool has_nan() const {
        for (auto it = grid.tree().cbeginValueAll(); it; ++it)
            if (std::isnan(double(*it))) return true;
        return std::isnan(double(grid.background()));
    }

    bool predicts_closed() const {
        if (has_nan()) return false;
        openvdb::CoordBBox box = grid.evalActiveVoxelBoundingBox();
        if (box.empty()) return true;
        box.expand(2);
        for (int x = box.min().x(); x <= box.max().x(); ++x)
            for (int y = box.min().y(); y <= box.max().y(); ++y)
                for (int z = box.min().z(); z <= box.max().z(); ++z) {
                    const openvdb::Coord p(x, y, z);
                    for (int a = 0; a < 3; ++a) {
                        openvdb::Coord q = p;
                        q[a] += 1;
                        if (inside(p) != inside(q) && !active(p) && !active(q)) return false;
                    }
                }
        return true;
    }
};

/// Enclosed volume, relative to the centroid so far-away meshes do not cancel badly.
inline double signed_volume(const pqdc::Mesh& m) {
    openvdb::Vec3d c(0.0);
    for (const auto& p : m.points) c += p;
    if (!m.points.empty()) c /= double(m.points.size());
    double v = 0;
    auto tri = [&](unsigned a, unsigned b, unsigned d) {
        v += (m.points[a] - c).dot((m.points[b] - c).cross(m.points[d] - c)) / 6.0;
    };
    for (const auto& t : m.triangles) tri(t[0], t[1], t[2]);
    for (const auto& q : m.quads) {
        tri(q[0], q[1], q[2]);
        tri(q[0], q[2], q[3]);
    }
    return v;
}

/// Outward orientation, exactly: with vertices strictly inside their cells,
/// a quad's four vertices lie in the four cells around one sign-changing
/// lattice edge, one per quadrant around it, so its vector area points along
/// the edge; it must point from the inside end to the outside end (flipped
/// for a mirroring transform, as extract() flips the winding). Unlike the
/// enclosed volume this holds for features thinner than a cell, where
/// clamped vertices make a closed surface self-intersect.
template <class GridT>
std::string check_quad_orientation(const GridT& grid, const DomainOracle<GridT>& oracle, const pqdc::Mesh& mesh) {
    const openvdb::Mat3d m = grid.transform().baseMap()->getAffineMap()->getMat4().getMat3();
    const double mirror = m.det() < 0 ? -1.0 : 1.0;
    std::size_t misplaced = 0, wrong_way = 0;
    for (const auto& q : mesh.quads) {
        openvdb::Vec3d p[4];
        openvdb::Coord cell[4];
        for (int k = 0; k < 4; ++k) {
            p[k] = grid.transform().worldToIndex(mesh.points[q[k]]);
            cell[k] = openvdb::Coord(int(std::floor(p[k].x())), int(std::floor(p[k].y())), int(std::floor(p[k].z())));
        }
        int axis = -1;
        for (int a = 0; a < 3; ++a)
            if (cell[0][a] == cell[1][a] && cell[0][a] == cell[2][a] && cell[0][a] == cell[3][a]) axis = a;
        if (axis < 0) {
            ++misplaced;
            continue;
        }
        openvdb::Coord start = cell[0];
        for (int k = 1; k < 4; ++k) start = openvdb::Coord::maxComponent(start, cell[k]);
        start[axis] = cell[0][axis];
        openvdb::Coord end = start;
        end[axis] += 1;
        if (oracle.inside(start) == oracle.inside(end)) {
            ++misplaced;
            continue;
        }
        const openvdb::Vec3d area = (p[2] - p[0]).cross(p[3] - p[1]);
        const double outward = (oracle.inside(start) ? 1.0 : -1.0) * area[axis] * mirror;
        if (!(outward > 0)) ++wrong_way;
    }
    std::ostringstream bad;
    if (misplaced) bad << misplaced << " quads not around a sign-changing lattice edge; ";
    if (wrong_way) bad << wrong_way << " quads facing inwards; ";
    return bad.str();
}

/// Every promise of extract() about `mesh`; returns "" or what is broken.
template <class GridT>
std::string check_mesh_promises(const GridT& grid, const pqdc::ExtractOptions& options, const pqdc::Mesh& mesh,
                                const pqdc::ExtractStats& stats) {
    std::ostringstream bad;
    const std::size_t n = mesh.points.size();
    for (const auto& t : mesh.triangles)
        if (t[0] >= n || t[1] >= n || t[2] >= n) return "triangle index out of range";
    for (const auto& q : mesh.quads)
        if (q[0] >= n || q[1] >= n || q[2] >= n || q[3] >= n) return "quad index out of range";
    const pqdc::TopologyReport t = pqdc::measure_topology(mesh);
    if (t.non_finite_point_count) bad << t.non_finite_point_count << " non-finite points; ";
    if (!t.edge_manifold()) bad << t.non_manifold_edge_count << " non-manifold edges; ";
    if (!t.consistently_oriented()) bad << t.inconsistent_edge_count << " inconsistently oriented edges; ";
    if (t.unreferenced_vertex_count) bad << t.unreferenced_vertex_count << " vertices no face uses; ";
    if (stats.vertices != n) bad << "stats.vertices " << stats.vertices << " != " << n << "; ";
    if (mesh.empty()) return bad.str();

    // A denoised run classifies the cells of its smoothed field
    // (src/lattice/smooth_field.hpp): the cells to check against are those.
    typename GridT::Ptr smoothed;
    if (stats.seconds("smooth field") > 0) {
        const DomainOracle<GridT> raw(grid, options);
        pqdc::detail::Signing signing;
        signing.isovalue = options.isovalue;
        signing.sign = raw.sign;
        smoothed = GridT::create(typename GridT::TreePtrType(pqdc::detail::smooth_field(grid.tree(), signing)));
        smoothed->setTransform(grid.transform().copy());
        smoothed->setGridClass(grid.getGridClass());
    }
    const DomainOracle<GridT> oracle(smoothed ? *smoothed : grid, options);
    if (options.containment == pqdc::Containment::clamp_to_cell) {
        std::size_t outside = 0;
        for (const auto& p : mesh.points) {
            const openvdb::Vec3d i = grid.transform().worldToIndex(p);
            const openvdb::Coord cell(int(std::floor(i.x())), int(std::floor(i.y())), int(std::floor(i.z())));
            if (!oracle.cell_in_domain_with_surface(cell)) ++outside;
        }
        if (outside) bad << outside << " vertices outside every cell the surface crosses; ";
    }
    if (oracle.predicts_closed() && !t.closed()) bad << t.boundary_edge_count << " boundary edges on a closed surface; ";
    if (options.containment == pqdc::Containment::clamp_to_cell)
        bad << check_quad_orientation(smoothed ? *smoothed : grid, oracle, mesh);
    return bad.str();
}

/// Every promise of extract_adaptive() about `mesh`: finite, indices in
/// range, edge-manifold, consistently oriented, no unused vertex, and closed
/// and outward (positive enclosed volume) where the domain rule says the
/// surface is closed. Returns "" or what is broken.
template <class GridT>
std::string check_adaptive_promises(const GridT& grid, const pqdc::ExtractOptions& options, const pqdc::Mesh& mesh,
                                    const pqdc::AdaptiveStats& stats) {
    std::ostringstream bad;
    const std::size_t n = mesh.points.size();
    for (const auto& t : mesh.triangles)
        if (t[0] >= n || t[1] >= n || t[2] >= n) return "adaptive: triangle index out of range";
    for (const auto& q : mesh.quads)
        if (q[0] >= n || q[1] >= n || q[2] >= n || q[3] >= n) return "adaptive: quad index out of range";
    const pqdc::TopologyReport t = pqdc::measure_topology(mesh);
    if (t.non_finite_point_count) bad << "adaptive: " << t.non_finite_point_count << " non-finite points; ";
    if (!t.edge_manifold()) bad << "adaptive: " << t.non_manifold_edge_count << " non-manifold edges; ";
    if (!t.consistently_oriented()) bad << "adaptive: " << t.inconsistent_edge_count << " inconsistently oriented edges; ";
    if (t.unreferenced_vertex_count) bad << "adaptive: " << t.unreferenced_vertex_count << " vertices no face uses; ";
    if (stats.vertices != n) bad << "adaptive: stats.vertices " << stats.vertices << " != " << n << "; ";
    if (mesh.empty()) return bad.str();
    if (DomainOracle<GridT>(grid, options).predicts_closed()) {
        if (!t.closed()) bad << "adaptive: " << t.boundary_edge_count << " boundary edges on a closed surface; ";
        else if (!(signed_volume(mesh) > 0)) bad << "adaptive: closed mesh encloses volume " << signed_volume(mesh) << " (inward); ";
    }
    return bad.str();
}

}  // namespace pqdc_test
