#include "lattice/procedural_grid.hpp"

#include "lattice/region.hpp"
#include "lattice/resources.hpp"
#include "procedural/sampling.hpp"

#include <string>

namespace pqdc::detail {

openvdb::FloatGrid::Ptr sample_procedural_grid(const ScalarField& field, const ProceduralSampling& sampling,
                                               const ExtractOptions& options) {
    openvdb::CoordBBox nodes = openvdb::CoordBBox::inf();
    if (!options.region.empty()) {
        const openvdb::math::Transform::Ptr xf = procedural_transform(field, sampling);
        const Region region(options.region, *xf);
        nodes = region.cell_bounds();
        if (nodes != openvdb::CoordBBox::inf()) nodes.expand(kProceduralHaloVoxels);
    }
    // Each active block becomes a dense leaf (its node and its value buffer);
    // the tiles and the tree's internal nodes are small beside them.
    using Leaf = openvdb::FloatTree::LeafNodeType;
    constexpr double kLeafBytes = double(sizeof(Leaf) + Leaf::SIZE * sizeof(float));
    const double limit = double(memory_limit(options));
    const BlockCountCheck check = [&](std::uint64_t blocks) {
        const double bytes = double(blocks) * kLeafBytes;
        if (bytes <= limit) return;
        throw resource_error("the procedural field sampled at resolution " + std::to_string(sampling.resolution) +
                             " needs more than the " + byte_size_text(limit) + " allowed (more than " +
                             std::to_string(std::uint64_t(limit / kLeafBytes)) + " blocks of 8^3 values, " +
                             byte_size_text(kLeafBytes) + " each, counted before sampling); lower the resolution, mesh a "
                             "smaller region (options.region: a box or a mask), or raise the memory limit");
    };
    return sample_field_checked(field, sampling, nodes, check);
}

}  // namespace pqdc::detail

namespace pqdc {

openvdb::FloatGrid::Ptr sample_field_within_limits(const ScalarField& field, const ProceduralSampling& sampling,
                                                   const ExtractOptions& options) {
    validate(options);
    return detail::sample_procedural_grid(field, sampling, options);
}

}  // namespace pqdc
