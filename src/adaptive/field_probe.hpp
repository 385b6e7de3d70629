// The signed field (negative inside) at arbitrary index-space points, for the
// octree's error terms and the polygons' empty leaves and crossings: trilinear
// samples of a grid, or the exact procedural field.
#pragma once

#include "lattice/interior.hpp"
#include "pqdc/procedural.hpp"

#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>

#include <memory>

namespace pqdc::adaptive_detail {

/// Per-thread evaluation of the signed field g at index-space points.
class FieldProbe {
public:
    virtual ~FieldProbe() = default;
    virtual double value(const openvdb::Vec3d& p_index) = 0;
};

class FieldSource {
public:
    virtual ~FieldSource() = default;
    virtual std::unique_ptr<FieldProbe> probe() const = 0;
};

/// grad g at an index-space point: central differences `step` voxels to
/// either side.
openvdb::Vec3d field_gradient(FieldProbe& probe, const openvdb::Vec3d& p_index, double step);
/// |grad g| at an index-space point (central differences, half a voxel apart).
double field_gradient_length(FieldProbe& probe, const openvdb::Vec3d& p_index);
/// First-order distance |g(p)| / gradient_length from an index-space point to
/// the surface, in voxels, with a gradient length measured at or near p
/// (field_gradient_length); infinity where it vanishes or g is not finite.
double field_distance_voxels(FieldProbe& probe, const openvdb::Vec3d& p_index, double gradient_length);
/// One Newton step of p towards g = 0 along the gradient (p itself where the
/// gradient vanishes or the step would leave a box of `reach` voxels).
openvdb::Vec3d project_to_surface(FieldProbe& probe, const openvdb::Vec3d& p_index, double reach);

/// A grid's values, trilinearly interpolated and signed.
template <class GridT>
class GridField final : public FieldSource {
public:
    GridField(const GridT& grid, const detail::Signing& signing) : grid_(grid), signing_(signing) {}
    std::unique_ptr<FieldProbe> probe() const override { return std::make_unique<Probe>(grid_, signing_); }

private:
    struct Probe final : FieldProbe {
        Probe(const GridT& g, const detail::Signing& s) : acc(g.getConstAccessor()), signing(s) {}
        double value(const openvdb::Vec3d& p) override {
            return signing(double(openvdb::tools::BoxSampler::sample(acc, p)));
        }
        typename GridT::ConstAccessor acc;
        detail::Signing signing;
    };
    const GridT& grid_;
    detail::Signing signing_;
};

/// The exact field of a procedural surface, at index points of its lattice.
class ProceduralField final : public FieldSource {
public:
    ProceduralField(const ScalarField& f, const openvdb::math::Transform& xf) : f_(f), xf_(xf) {}
    std::unique_ptr<FieldProbe> probe() const override { return std::make_unique<Probe>(f_, xf_); }

private:
    struct Probe final : FieldProbe {
        Probe(const ScalarField& f, const openvdb::math::Transform& xf) : f(f), xf(xf) {}
        double value(const openvdb::Vec3d& p) override { return f.value(xf.indexToWorld(p)); }
        const ScalarField& f;
        const openvdb::math::Transform& xf;
    };
    const ScalarField& f_;
    const openvdb::math::Transform& xf_;
};

}  // namespace pqdc::adaptive_detail
