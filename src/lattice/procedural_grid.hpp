// The sampled grid a procedural run meshes, for both extractors: bounded by
// the memory limit before anything is allocated, and only around the region.
#pragma once

#include "pqdc/extract.hpp"
#include "pqdc/procedural.hpp"

#include <openvdb/openvdb.h>

namespace pqdc::detail {

/// sample_field(field, sampling), with two limits:
/// - only the 128^3 lattice nodes within kProceduralHaloVoxels of the cells
///   options.region bounds are sampled (all of them when it is unbounded):
///   no other value is read by a run restricted to the region;
/// - resource_error as soon as the leaves counted so far would exceed the
///   memory limit (memory_limit(options)), while the lattice is classified.
openvdb::FloatGrid::Ptr sample_procedural_grid(const ScalarField& field, const ProceduralSampling& sampling,
                                               const ExtractOptions& options);

/// Voxels around the region's cells that are sampled too: more than any
/// stencil reaches (candidate blocks look one 8^3 block up, gradients two
/// voxels, crossings and normals of procedural fields come from the field).
constexpr int kProceduralHaloVoxels = 16;

}  // namespace pqdc::detail
