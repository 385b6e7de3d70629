// Mesh quality measures: topology, triangle shape, distance to the true
// surface and normal error. Used by the figure scripts, the tests and
// pqdc-measure. All measures are deterministic (same numbers for any thread
// count) and world-space.
//
//   pqdc::TopologyReport topo = pqdc::measure_topology(mesh);
//   if (!topo.closed() || !topo.edge_manifold()) ...
//   auto field = pqdc::make_procedural("sphere");
//   pqdc::DistanceStats d = pqdc::measure_distance(mesh, *field);
//   pqdc::DistanceStats r = pqdc::measure_distance(mesh, reference_mesh);
#pragma once

#include "pqdc/mesh.hpp"
#include "pqdc/procedural.hpp"

#include <openvdb/openvdb.h>

#include <cstddef>
#include <memory>
#include <string>

namespace pqdc {

/// Combinatorial facts about a polygon mesh. Edges are the polygon sides
/// (a quad has 4 edges, its diagonals are not edges). Faces with a repeated
/// vertex index are counted as degenerate and left out of every edge and
/// vertex count below them, since they have no well-defined sides.
struct TopologyReport {
    std::size_t vertex_count = 0;               ///< points in the mesh
    std::size_t unreferenced_vertex_count = 0;  ///< points no face uses
    std::size_t triangle_count = 0;
    std::size_t quad_count = 0;
    std::size_t edge_count = 0;                 ///< distinct undirected edges
    std::size_t boundary_edge_count = 0;        ///< edges used by exactly 1 face
    std::size_t non_manifold_edge_count = 0;    ///< edges used by 3 or more faces
    /// Edges used by exactly 2 faces that traverse it in the same direction
    /// (one of the two faces is flipped relative to the other).
    std::size_t inconsistent_edge_count = 0;
    /// Referenced vertices whose incident faces do not form one fan (faces
    /// connected through shared edges at that vertex), e.g. a bowtie.
    std::size_t non_manifold_vertex_count = 0;
    std::size_t degenerate_face_count = 0;      ///< repeated index, or zero area
    std::size_t non_finite_point_count = 0;     ///< points with a NaN or infinite coordinate
    /// Groups of faces connected through shared vertices. Unreferenced
    /// vertices are not components.
    std::size_t connected_component_count = 0;
    /// V - E + F over referenced vertices and non-degenerate faces (2 for
    /// each closed genus-0 component).
    long long euler_characteristic = 0;

    bool edge_manifold() const { return non_manifold_edge_count == 0; }
    bool vertex_manifold() const { return non_manifold_vertex_count == 0; }
    /// Every edge shared by two faces is traversed once in each direction.
    /// Only meaningful together with edge_manifold().
    bool consistently_oriented() const { return inconsistent_edge_count == 0; }
    bool closed() const { return boundary_edge_count == 0; }
};

/// Throws input_error when a face refers to a point that does not exist.
TopologyReport measure_topology(const Mesh& mesh);

/// Shape of the triangles (quads are split 0-1-2 / 0-2-3). A triangle's
/// quality is its smallest interior angle: 60 degrees for an equilateral
/// triangle, 0 for a degenerate one (zero-length sides count as 0).
/// Without triangles the angle figures are NaN (null in the JSON).
struct TriangleQuality {
    std::size_t triangle_count = 0;
    double min_angle_mean_degrees = 0;
    double min_angle_min_degrees = 0;
    /// The smallest min-angle such that at least 5% of triangles are at or
    /// below it (nearest rank).
    double min_angle_p05_degrees = 0;
    double fraction_below_10_degrees = 0;  ///< triangles with min angle < 10 degrees, in [0, 1]
};

TriangleQuality measure_triangle_quality(const Mesh& mesh);

/// Summary of unsigned distances, world units. Without samples (an empty
/// mesh, or every point skipped) mean, rms, max and mean_signed are NaN
/// (null in the JSON): there is no distance, and 0 would read as a perfect fit.
struct DistanceStats {
    std::size_t sample_count = 0;
    double mean = 0;
    double rms = 0;
    double max = 0;
    /// Mean of signed distances (positive outside): a systematic shrink or
    /// swell of the mesh shows here while mean stays positive either way.
    double mean_signed = 0;
    /// Points left out: a non-finite coordinate, or a distance or field value
    /// that is not finite there (e.g. 1e300 squared).
    std::size_t skipped_count = 0;
    /// Samples whose distance is a bound rather than a projection: the
    /// field's Newton projection did not converge (the nearest surface point
    /// found by marching along 28 directions is used instead, an upper bound;
    /// |f| / L, a lower bound, if none is found), or a grid sample lay outside
    /// the narrow band (clamped).
    std::size_t unreliable_count = 0;
};

struct FieldDistanceOptions {
    /// Newton steps q -= f(q) grad f(q) / |grad f(q)|^2 projecting a vertex
    /// onto f = 0. 1 is exact for a signed distance field. Range [1, 100].
    /// Default 8.
    int newton_steps = 8;
    /// A projection counts as converged when |f(q)| <= this (world units,
    /// assuming |grad f| ~ 1). Range > 0. Default 1e-9.
    double tolerance = 1e-9;
};

/// Distances from the mesh vertices to the surface f = 0 of a procedural
/// field: |p - q| for q the Newton projection of p onto f = 0 (exact for
/// signed distance fields, a close estimate for smooth fields near their
/// surface). Where the projection fails (it may not travel more than twice
/// |f| / |grad f|), the nearest surface point met by marching from p along
/// the gradient and the 26 lattice directions, with steps |f| / L
/// (L = field.lipschitz_bound()), so that a vanishing gradient cannot
/// inflate the distance.
/// Non-finite points are skipped. Throws option_error for invalid options.
DistanceStats measure_distance(const Mesh& mesh, const ScalarField& field,
                               const FieldDistanceOptions& options = {});

/// Distances from the mesh vertices to the zero level set of a level-set
/// grid: |trilinear sample at the vertex's world position| (values are world
/// distances). Samples whose magnitude reaches the background are outside
/// the narrow band and counted unreliable. Throws input_error for a fog
/// volume (its values are not distances).
DistanceStats measure_distance(const Mesh& mesh, const openvdb::FloatGrid& level_set);

struct MeshDistanceOptions {
    /// Most triangles per leaf of the bounding-box hierarchy over the
    /// reference. Changes speed and memory only, never a distance.
    /// Range [1, 64]. Default 4.
    int leaf_triangles = 4;
};

/// Distances from points to the surface of a reference mesh: its triangles
/// and its quads split 0-1-2 / 0-2-3, world units. Exact (up to rounding) for
/// any point, however far: the search descends a bounding-box hierarchy
/// nearest box first and skips only boxes farther than the best triangle
/// found, so there is no search radius to choose. Built once, O(F log F) for
/// F triangles; queries are const, safe to run concurrently, and their
/// results do not depend on thread count or call order. Copies share the
/// immutable search structure.
class MeshDistance {
public:
    /// Throws input_error when the reference has no faces, a face refers to
    /// a point that does not exist, or a point used by a face has a NaN or
    /// infinite coordinate (unused points are ignored); option_error for
    /// invalid options.
    explicit MeshDistance(const Mesh& reference, const MeshDistanceOptions& options = {});

    /// Distance from p to the nearest point of the reference surface, world
    /// units; NaN when p has a non-finite coordinate.
    double operator()(const openvdb::Vec3d& p) const;

    /// The same distance, negative when p is behind the nearest surface
    /// point: the sign of (p - q) . n for q the nearest point and n the
    /// angle-weighted pseudo-normal of the face, edge or vertex q lies on
    /// (Baerentzen and Aanaes 2005). For a closed, edge-manifold, consistently
    /// oriented reference with shared vertices (faces counter-clockwise seen
    /// from outside, as pqdc writes them) negative is exactly inside; for
    /// other references it is the side of the locally nearest surface.
    double signed_distance(const openvdb::Vec3d& p) const;

    /// Unit normal, (b - a) x (c - a) normalized, of the reference triangle
    /// nearest to p: the true surface normal at the nearest point when that
    /// lies inside a face. At a shared edge or corner, where the normal is not
    /// defined, it is the first nearest triangle found (a fixed choice for a
    /// given reference). Zero for a zero-area triangle, NaN when p has a
    /// non-finite coordinate.
    openvdb::Vec3d nearest_face_normal(const openvdb::Vec3d& p) const;

private:
    struct Impl;
    std::shared_ptr<const Impl> impl_;
};

/// Distances from the mesh vertices to the reference mesh's surface (see
/// MeshDistance), signed as MeshDistance::signed_distance. Exact, so
/// unreliable_count is 0. Non-finite points are skipped. Throws as the
/// MeshDistance constructor.
DistanceStats measure_distance(const Mesh& mesh, const Mesh& reference, const MeshDistanceOptions& options = {});
/// The same with a prebuilt search structure (measuring many meshes against
/// one reference).
DistanceStats measure_distance(const Mesh& mesh, const MeshDistance& reference);

/// Where normals are compared.
enum class NormalSampling {
    per_face,    ///< each face's normal vs the gradient at the surface point near its centroid
    per_vertex,  ///< area-weighted vertex normals vs the gradient at the surface point near the vertex
};

/// Angles between mesh normals and the field's true unit normal, degrees.
/// Without samples the angle figures are NaN (null in the JSON).
struct NormalDeviation {
    std::size_t sample_count = 0;
    double mean_degrees = 0;
    double rms_degrees = 0;
    double max_degrees = 0;
    /// Samples left out: zero-area faces / vertices without a normal, or a
    /// zero or non-finite field gradient (e.g. exactly on a crease).
    std::size_t skipped_count = 0;
};

/// Face normals of a quad use its diagonals' cross product (the vector area
/// of a non-planar quad). The true normal is grad f evaluated at the Newton
/// projection (options as in measure_distance) of the centroid or vertex
/// onto f = 0, so smooth non-SDF fields are judged on their surface.
NormalDeviation measure_normal_deviation(const Mesh& mesh, const ScalarField& field,
                                         NormalSampling sampling = NormalSampling::per_face,
                                         const FieldDistanceOptions& options = {});

/// Angles between the mesh's face normals (as above: quads by their
/// diagonals) and the reference surface's normal at the point nearest to the
/// face's centroid (MeshDistance::nearest_face_normal), degrees. Zero-area
/// faces, faces with a non-finite corner and zero-area nearest triangles are
/// skipped.
NormalDeviation measure_normal_deviation(const Mesh& mesh, const MeshDistance& reference);

/// Compact JSON objects (one line, keys in declaration order, doubles in
/// shortest round-trip form, non-finite as null).
std::string to_json(const TopologyReport& report);
std::string to_json(const TriangleQuality& quality);
std::string to_json(const DistanceStats& stats);
std::string to_json(const NormalDeviation& deviation);

}  // namespace pqdc
