// Stage "untangle"'s whole-mesh check for the uniform extractor: the exact
// result of find_self_intersections, found without a spatial broad phase by
// proving most of the mesh free of intersections from the lattice.
//
// Why it is enough to look at quad stars. Every face of the uniform mesh is
// the quad around one crossing lattice edge, with a corner in each of the
// four cells around it (split into two triangles, or kept as a quad and
// split 0-1-2 / 0-2-3 by the finder). Put each corner at its cell's center
// and the quad becomes the unit square of the dual lattice: two such squares
// that share no corner cell are disjoint faces of a cubical complex with
// integer coordinates, so in index space they are at least 1 apart in the
// max norm. A vertex lies delta_v (max norm) from its cell's center, and a
// triangle's points move at most as far as its farthest corner. So two
// triangles of quads without a common corner cell can meet only if
// delta(T1) + delta(T2) >= 1: with D the largest delta of the mesh, only if
// both have a corner with delta >= 1 - D ("loose" corners; with vertices
// clamped to their cells D <= 1/2 up to rounding, and only clamped vertices
// are loose). Every other intersecting pair lies in the quad star S(c) of
// a cell c: the triangles of all quads with a corner in c.
//
// The certificate. For a cell with one vertex v whose quads form one closed
// fan (v, a_i, b_i, a_i+1), S(c) is a disc with v inside and the boundary
// a_1 b_1 a_2 b_2 ... . If, projected onto one coordinate plane (exact 2D
// signs), every triangle of S(c) turns the same way and the boundary is
// star-shaped around v (each boundary edge turns that way seen from v, and
// the boundary winds around v once), the projection is a simplicial map of
// the disc that preserves orientation and is one-to-one on its boundary,
// hence one-to-one: no two triangles of S(c) meet except in their common
// edges and corners. The projection most nearly facing the star is tried
// first, then the other two (a crease along a lattice axis is seen edge-on
// in the first: on the noisy CSG part of Figure 3 at 512 cells this halves
// the stars left to test, 84 k -> 49 k of 1.69 M). Stars that fail (folds, open borders, cells with
// several patches, more than 12 quads) have all their pairs tested exactly,
// and the loose triangles are checked against each other by
// find_self_intersections. Pairs, their order and the degenerate triangles
// are then exactly find_self_intersections_at's (an [untangle] test
// compares both on lattice meshes of random signs, a sphere and a thin
// sheet, with vertices near their cells' centers, anywhere in them, on
// their faces and beyond them, also after a round of moves).
#pragma once

#include "lattice/transform.hpp"
#include "pqdc/mesh.hpp"
#include "pqdc/self_intersections.hpp"
#include "uniform/safe_positions.hpp"

#include <cmath>
#include <cstdint>
#include <memory>
#include <vector>

namespace pqdc::detail {

/// What the uniform extractor knows of its mesh's vertices: their cells,
/// from one of `safe` and `cells`.
struct LatticeVertices {
    /// Per vertex: its safe position (uniform/safe_positions.hpp), world
    /// space; it lies inside the vertex's cell, which is read from it.
    const std::vector<openvdb::Vec3d>* safe = nullptr;
    /// Per vertex: cell_patches() (patch number and the cell's patch count).
    const std::vector<std::uint8_t>* patches = nullptr;
    const LatticeTransform* xf = nullptr;
    /// Per vertex: its cell, where `safe` is null (8 bytes a vertex, not 24).
    const VertexCells* cells = nullptr;

    std::size_t size() const { return safe ? safe->size() : cells ? cells->size() : 0; }
    /// Index-space center of vertex v's cell.
    openvdb::Vec3d cell_center(std::size_t v) const {
        if (!safe) return cells->cell(v).asVec3d() + openvdb::Vec3d(0.5);
        const openvdb::Vec3d s = xf->transform->worldToIndex((*safe)[v]);
        return openvdb::Vec3d(std::floor(s[0]), std::floor(s[1]), std::floor(s[2])) + openvdb::Vec3d(0.5);
    }
};

/// How the check went (for tests and statistics).
struct QuadStarCounts {
    std::uint64_t certified_cells = 0;  ///< quad stars proven free of intersections
    std::uint64_t tested_cells = 0;     ///< quad stars whose pairs were tested one by one
    std::uint64_t loose_triangles = 0;  ///< triangles checked against each other by the general finder
    bool general = false;               ///< the argument did not apply: the general finder ran
};

/// The check kept between the untangle stage's rounds: the faces do not
/// change, so the quads around each vertex are found once, and a round's
/// recheck looks only at the stars around the vertices it moved.
class QuadStarCheck {
public:
    /// `mesh` (its faces) and `lattice` must outlive the object.
    QuadStarCheck(const Mesh& mesh, const LatticeVertices& lattice);
    /// find_self_intersections_at(mesh, points, options), the same result.
    SelfIntersections whole(const std::vector<openvdb::Vec3d>& points, const SelfIntersectionOptions& options,
                            QuadStarCounts* counts = nullptr);
    /// After whole() ran without the general finder, with only the sorted
    /// vertices `moved` changed since: every intersecting pair with a
    /// triangle at a moved vertex and every degenerate or non-finite such
    /// triangle (what a move can create), and any other intersecting pair
    /// of the stars around them. False when it does not apply (whole() used
    /// the general finder, or a move left the bound on the offsets).
    bool near(const std::vector<openvdb::Vec3d>& points, const std::vector<std::uint32_t>& moved,
              SelfIntersections& out);

private:
    struct State;
    const Mesh& mesh_;
    LatticeVertices lattice_;
    std::shared_ptr<State> state_;  ///< set by whole() when the argument applies
};

/// find_self_intersections_at(mesh, points, options), the same result, for a
/// mesh of the uniform extractor (split triangles 2k and 2k+1 form the quad
/// around lattice edge k; `lattice` describes its vertices). Meshes where
/// the argument above does not apply (a quad that is not two triangles of
/// four cells, non-finite points, D >= 1 - margin) get the general finder.
SelfIntersections find_self_intersections_by_quad_stars(const Mesh& mesh, const std::vector<openvdb::Vec3d>& points,
                                                         const LatticeVertices& lattice,
                                                         const SelfIntersectionOptions& options,
                                                         QuadStarCounts* counts = nullptr);

}  // namespace pqdc::detail
