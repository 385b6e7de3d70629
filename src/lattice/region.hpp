// options.region (box and mask) prepared for one grid: which lattice cells
// may take part, for both extractors. Cells are judged by their centre, so a
// mask and its inverse split the cells exactly.
#pragma once

#include "pqdc/extract.hpp"
#include "pqdc/mesh.hpp"

#include <openvdb/openvdb.h>

#include <optional>
#include <string>

namespace pqdc::detail {

class Region {
public:
    /// Throws input_error naming the mask grid when its value type is not
    /// supported or its transform is not affine.
    Region(const MeshRegion& region, const openvdb::math::Transform& grid_xf);

    bool unbounded() const { return !bbox_ && !mask_; }

    /// Index-space box holding the minimum corner of every cell that may take
    /// part (conservative); CoordBBox::inf() when unbounded or inverted.
    openvdb::CoordBBox cell_bounds() const { return bounds_; }

    /// Per-thread test (it holds a tree accessor).
    class Probe {
    public:
        explicit Probe(const Region& r) : r_(r) {
            if (r.mask_) acc_.emplace(*r.mask_);
        }
        bool unbounded() const { return r_.unbounded(); }
        /// True when the cell with minimum corner `cell` has its centre in the region.
        bool contains(const openvdb::Coord& cell) {
            if (r_.unbounded()) return true;
            const openvdb::Vec3d centre = cell.asVec3d() + openvdb::Vec3d(0.5);
            openvdb::Vec3d world(0.0);
            if (r_.bbox_ || !r_.same_transform_) world = r_.grid_xf_.indexToWorld(centre);
            if (r_.bbox_ && !r_.in_bbox(world)) return false;
            if (!r_.mask_) return true;
            return acc_->isValueOn(r_.same_transform_ ? cell : r_.mask_voxel(world)) != r_.invert_;
        }
        /// The same test for any index-space point (a cell's centre gives contains(cell)).
        bool contains_point(const openvdb::Vec3d& index) {
            if (r_.unbounded()) return true;
            const openvdb::Vec3d world = r_.grid_xf_.indexToWorld(index);
            if (r_.bbox_ && !r_.in_bbox(world)) return false;
            if (!r_.mask_) return true;
            return acc_->isValueOn(r_.mask_voxel(world)) != r_.invert_;
        }

    private:
        const Region& r_;
        std::optional<openvdb::tree::ValueAccessor<const openvdb::MaskTree>> acc_;
    };

private:
    /// The mask voxel deciding a world point: the nearest, ties towards the
    /// lower index (so for a cell centre with the grid's own transform, the
    /// voxel at the cell's minimum corner; contains() takes that exactly).
    openvdb::Coord mask_voxel(const openvdb::Vec3d& world) const;
    bool in_bbox(const openvdb::Vec3d& world) const {
        for (int a = 0; a < 3; ++a)
            if (!(world[a] >= bbox_->min()[a] && world[a] <= bbox_->max()[a])) return false;
        return true;
    }

    const openvdb::math::Transform& grid_xf_;
    std::optional<openvdb::BBoxd> bbox_;
    openvdb::MaskTree::Ptr mask_;  ///< in the mask grid's index space
    openvdb::math::Transform::ConstPtr mask_xf_;
    bool same_transform_ = false;
    bool invert_ = false;
    openvdb::CoordBBox bounds_ = openvdb::CoordBBox::inf();
};

/// Keeps the faces of an index-space mesh whose every vertex lies in the
/// region and drops the points no face uses. The adaptive extractor needs it
/// on top of restricting its finest cells: merged cells and the crossings
/// between empty leaves reach past them.
void keep_faces_in_region(const Region& region, Mesh& index_mesh);

}  // namespace pqdc::detail
