// Procedural signed scalar fields (negative inside) with analytic gradients,
// and their sampling onto a sparse OpenVDB lattice. Fields live in world
// space; the lattice is a uniform grid over the field's bounds.
#pragma once

#include <openvdb/openvdb.h>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace pqdc {

/// A scalar field f: R^3 -> R, negative inside the surface f = 0.
class ScalarField {
public:
    virtual ~ScalarField() = default;
    /// f at a world-space point.
    virtual double value(const openvdb::Vec3d& p_world) const = 0;
    /// Analytic gradient of f at a world-space point (may be zero or one-sided at kinks).
    virtual openvdb::Vec3d gradient(const openvdb::Vec3d& p_world) const = 0;
    /// L such that |f(a) - f(b)| <= L |a - b| for all a, b (world units per
    /// world unit). Used to skip lattice blocks that cannot contain surface.
    virtual double lipschitz_bound() const = 0;
    /// A world-space box containing the whole surface f = 0.
    virtual openvdb::BBoxd bounds() const = 0;
};

/// |p - center| - radius.
struct SphereParams {
    openvdb::Vec3d center{0.0, 0.0, 0.0};  ///< world units
    double radius = 1.0;                   ///< world units, > 0
};

/// Exact signed distance to a box rotated about `axis` by `angle_degrees`
/// around its center. Sharp corners and edges: the test bed for features.
struct BoxParams {
    openvdb::Vec3d center{0.0, 0.0, 0.0};             ///< world units
    openvdb::Vec3d half_extents{0.6, 0.45, 0.35};      ///< world units, each > 0
    openvdb::Vec3d axis{1.0, 2.0, 3.0};               ///< rotation axis, any non-zero length
    double angle_degrees = 30.0;                      ///< rotation about axis
};

/// The paper's Figure 3 field, "fractal simplex noise with a sphere cut out":
///   g(p) = |p - center| - radius + amplitude * fbm(frequency * p)
///   f(p) = max(g(p), cut_radius - |p - cut_center|)
/// fbm = sum over octaves o of gain^o * simplex(lacunarity^o * x), seeded.
/// The cut makes a sharp crease where it meets the noisy surface.
struct Figure3Params {
    openvdb::Vec3d center{0.0, 0.0, 0.0};      ///< world units
    double radius = 1.0;                       ///< world units, > 0
    openvdb::Vec3d cut_center{0.55, 0.45, 0.6};///< world units
    double cut_radius = 0.7;                   ///< world units, >= 0 (0 = no cut)
    double noise_amplitude = 0.08;             ///< world units, >= 0
    double noise_frequency = 4.0;              ///< cycles per world unit, > 0
    int octaves = 4;                           ///< [1, 16]
    double lacunarity = 2.0;                   ///< frequency ratio between octaves, > 1
    double gain = 0.5;                         ///< amplitude ratio between octaves, (0, 1)
    std::uint32_t seed = 1;                    ///< permutes the noise lattice
};

std::unique_ptr<ScalarField> make_sphere(const SphereParams& params);
std::unique_ptr<ScalarField> make_rotated_box(const BoxParams& params);
std::unique_ptr<ScalarField> make_figure3(const Figure3Params& params);

/// Names accepted by make_procedural: "sphere", "box", "figure3".
std::vector<std::string> procedural_names();
/// The named field with default parameters; throws option_error listing the names.
std::unique_ptr<ScalarField> make_procedural(const std::string& name);

/// How a procedural field is laid onto a lattice.
struct ProceduralSampling {
    int resolution = 128;       ///< lattice cells along the longest side of bounds(); [4, 16384]
    double margin_voxels = 3.0; ///< empty voxels around bounds(); >= 2
    /// Leaf blocks within this many voxels of every block the surface may
    /// cross are active and dense too, as in a level set with a wide band;
    /// infinity makes every block of procedural_index_bbox active, a dense
    /// volume like a scan (its values are f, unclamped). Voxels, >= 0.
    /// Default 0: only the blocks the surface may cross.
    double active_band_voxels = 0.0;
};

/// The lattice transform: uniform voxel size = longest side of bounds() /
/// resolution, translated so index (0,0,0) lies margin_voxels voxels below
/// bounds().min(). Throws option_error on invalid sampling settings.
openvdb::math::Transform::Ptr procedural_transform(const ScalarField& field,
                                                   const ProceduralSampling& sampling);

/// The index-space box of lattice points covering bounds() plus the margin.
openvdb::CoordBBox procedural_index_bbox(const ScalarField& field,
                                         const ProceduralSampling& sampling);

/// Samples f at the lattice points of procedural_index_bbox into a sparse
/// FloatGrid (class GRID_LEVEL_SET, values in world units). Every 8^3 leaf
/// block that could hold a lattice cell crossed by the surface (judged with
/// lipschitz_bound) is active and dense; the others become inactive tiles
/// holding +/-background with the field's sign there. TBB-parallel,
/// deterministic. background defaults to 3 voxels.
openvdb::FloatGrid::Ptr sample_field(const ScalarField& field, const ProceduralSampling& sampling);

/// sample_field's grid restricted to the 128^3 lattice nodes (OpenVDB's
/// lowest internal nodes) that overlap `nodes` (index space): the same
/// leaves, values and tiles there, nothing elsewhere. How a brick store is
/// written one brick at a time (pqdc/brick_store.hpp).
openvdb::FloatGrid::Ptr sample_field(const ScalarField& field, const ProceduralSampling& sampling,
                                     const openvdb::CoordBBox& nodes);

}  // namespace pqdc
