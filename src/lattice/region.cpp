#include "lattice/region.hpp"

#include "pqdc/exceptions.hpp"

#include <openvdb/tools/LevelSetUtil.h>

#include <cmath>

namespace pqdc::detail {
namespace {

/// The mask grid's "holds" set as topology: active voxels, or for level
/// sets the inside (narrow band below zero and the enclosed interior).
openvdb::MaskTree::Ptr mask_topology(const openvdb::GridBase& g) {
    const bool level_set = g.getGridClass() == openvdb::GRID_LEVEL_SET;
    if (const auto* f = dynamic_cast<const openvdb::FloatGrid*>(&g)) {
        if (level_set)
            return std::make_shared<openvdb::MaskTree>(openvdb::tools::sdfInteriorMask(*f)->tree(), false,
                                                       openvdb::TopologyCopy());
        return std::make_shared<openvdb::MaskTree>(f->tree(), false, openvdb::TopologyCopy());
    }
    if (const auto* d = dynamic_cast<const openvdb::DoubleGrid*>(&g)) {
        if (level_set)
            return std::make_shared<openvdb::MaskTree>(openvdb::tools::sdfInteriorMask(*d)->tree(), false,
                                                       openvdb::TopologyCopy());
        return std::make_shared<openvdb::MaskTree>(d->tree(), false, openvdb::TopologyCopy());
    }
    if (const auto* b = dynamic_cast<const openvdb::BoolGrid*>(&g))
        return std::make_shared<openvdb::MaskTree>(b->tree(), false, openvdb::TopologyCopy());
    if (const auto* m = dynamic_cast<const openvdb::MaskGrid*>(&g))
        return std::make_shared<openvdb::MaskTree>(m->tree(), false, openvdb::TopologyCopy());
    if (const auto* i = dynamic_cast<const openvdb::Int32Grid*>(&g))
        return std::make_shared<openvdb::MaskTree>(i->tree(), false, openvdb::TopologyCopy());
    throw input_error("mask grid '" + g.getName() + "' holds " + g.valueType() +
                      " values; a mask is a bool, mask, float, double or int32 grid (active voxels, or the inside "
                      "of a level set)");
}

/// Index-space box of `world` (its 8 corners mapped), widened to the cells
/// whose centres may fall in it.
openvdb::CoordBBox cells_of_world_box(const openvdb::BBoxd& world, const openvdb::math::Transform& xf) {
    openvdb::Vec3d lo(INFINITY), hi(-INFINITY);
    for (int n = 0; n < 8; ++n) {
        const openvdb::Vec3d w(n & 1 ? world.max().x() : world.min().x(), n & 2 ? world.max().y() : world.min().y(),
                               n & 4 ? world.max().z() : world.min().z());
        const openvdb::Vec3d i = xf.worldToIndex(w);
        lo = openvdb::Vec3d(std::min(lo.x(), i.x()), std::min(lo.y(), i.y()), std::min(lo.z(), i.z()));
        hi = openvdb::Vec3d(std::max(hi.x(), i.x()), std::max(hi.y(), i.y()), std::max(hi.z(), i.z()));
    }
    // Centre c = min + 0.5 in [lo, hi]; one more cell each way for rounding.
    // Clamped well inside int range (boxes may be huge or far away).
    auto to_int = [](double v) { return int(std::max(-1e9, std::min(1e9, v))); };
    return openvdb::CoordBBox(openvdb::Coord(to_int(std::floor(lo.x() - 0.5)) - 1, to_int(std::floor(lo.y() - 0.5)) - 1,
                                             to_int(std::floor(lo.z() - 0.5)) - 1),
                              openvdb::Coord(to_int(std::ceil(hi.x() - 0.5)) + 1, to_int(std::ceil(hi.y() - 0.5)) + 1,
                                             to_int(std::ceil(hi.z() - 0.5)) + 1));
}

openvdb::CoordBBox intersect(const openvdb::CoordBBox& a, const openvdb::CoordBBox& b) {
    openvdb::CoordBBox r(openvdb::Coord::maxComponent(a.min(), b.min()), openvdb::Coord::minComponent(a.max(), b.max()));
    return r;  // may be empty (min > max): no cell takes part
}

}  // namespace

Region::Region(const MeshRegion& region, const openvdb::math::Transform& grid_xf)
    : grid_xf_(grid_xf), bbox_(region.bbox), invert_(region.invert_mask) {
    if (bbox_) bounds_ = intersect(bounds_, cells_of_world_box(*bbox_, grid_xf));
    if (!region.mask) return;
    const openvdb::GridBase& m = *region.mask;
    if (!m.transform().isLinear())
        throw input_error("mask grid '" + m.getName() + "' has a " + m.transform().mapType() +
                          " transform, which is not affine; resample the mask to a linear transform");
    mask_ = mask_topology(m);
    mask_xf_ = m.constTransformPtr();
    same_transform_ = m.transform() == grid_xf;
    if (invert_) return;
    openvdb::CoordBBox active;
    mask_->evalActiveVoxelBoundingBox(active);
    if (active.empty()) {
        bounds_ = openvdb::CoordBBox(openvdb::Coord(1), openvdb::Coord(0));  // empty: nothing takes part
        return;
    }
    const openvdb::BBoxd world = m.transform().indexToWorld(
        openvdb::BBoxd(active.min().asVec3d() - openvdb::Vec3d(0.5), active.max().asVec3d() + openvdb::Vec3d(0.5)));
    bounds_ = intersect(bounds_, cells_of_world_box(world, grid_xf));
}

openvdb::Coord Region::mask_voxel(const openvdb::Vec3d& world) const {
    const openvdb::Vec3d i = mask_xf_->worldToIndex(world);
    constexpr double kTie = 1e-6;  // index units: far above the round trip's rounding, far below a voxel
    auto voxel = [](double v) { return int(std::max(-2e9, std::min(2e9, std::floor(v + 0.5 - kTie)))); };
    return openvdb::Coord(voxel(i.x()), voxel(i.y()), voxel(i.z()));
}

void keep_faces_in_region(const Region& region, Mesh& m) {
    if (region.unbounded()) return;
    Region::Probe probe(region);
    std::vector<std::uint8_t> inside(m.points.size());
    for (std::size_t i = 0; i < m.points.size(); ++i) inside[i] = probe.contains_point(m.points[i]);
    std::vector<std::uint8_t> used(m.points.size(), 0);
    auto keep = [&](auto& faces) {
        std::size_t kept = 0;
        for (const auto& f : faces) {
            bool all = true;
            for (int k = 0; k < int(f.size); ++k) all = all && inside[f[k]];
            if (!all) continue;
            for (int k = 0; k < int(f.size); ++k) used[f[k]] = 1;
            faces[kept++] = f;
        }
        faces.resize(kept);
    };
    keep(m.triangles);
    keep(m.quads);
    std::vector<openvdb::Index32> remap(m.points.size());
    openvdb::Index32 n = 0;
    for (std::size_t i = 0; i < m.points.size(); ++i) {
        remap[i] = n;
        if (used[i]) m.points[n++] = m.points[i];
    }
    m.points.resize(n);
    for (auto& t : m.triangles)
        for (int k = 0; k < 3; ++k) t[k] = remap[t[k]];
    for (auto& q : m.quads)
        for (int k = 0; k < 4; ++k) q[k] = remap[q[k]];
}

}  // namespace pqdc::detail
