// Uniform dual contouring with probabilistic plane quadrics: the in-core
// driver (pqdc::extract), the whole grid and the whole mesh in memory.
//
// The pipeline (uniform/pipeline.hpp strings it together), each stage in the
// file named after it; every stage is leaf-parallel and deterministic
// (per-leaf counts, an exclusive prefix sum, then each leaf fills its own
// slice of preallocated arrays), in the manner of OpenVDB's
// VolumeToMesh::operator():
//   candidates      lattice/candidates.hpp       blocks that may hold a cell with an active corner
//   noise estimate  lattice/noise_estimate.hpp   residuals of local linear fits near the surface
//   (parameters)    lattice/auto_parameters.cpp  sigma_n, gradient stencil, quadric filter
//   cells           per candidate leaf, with its values fetched once:
//                     fetch           lattice/value_block.hpp
//                     classify        uniform/classify.cpp (configurations, ambiguous faces)
//                     place vertices  uniform/place_vertices.hpp (Hermite samples, quadrics, filter, solve)
//   gather          uniform/gather.cpp (per-leaf vertex lists concatenated in leaf order)
//   faces           uniform/faces.cpp (one quad or two triangles per crossing edge)
//   untangle        uniform/untangle.cpp: the quad-star check and the repair of
//                   lattice/untangle.cpp towards the safe positions (uniform/safe_positions.cpp)
//                   (no self-intersections), then unused vertices are dropped
// The stages read values through a values policy; here InCoreValues, the
// tree read directly. The brick-by-brick and distributed drivers
// (scale/extract_bricks.cpp) pass theirs to the same pipeline: same bytes.
#include "pqdc/extract.hpp"

#include "lattice/noise_estimate.hpp"
#include "lattice/smooth_field.hpp"
#include "uniform/pipeline.hpp"

#include <memory>

namespace pqdc::detail {
namespace {

/// The values of a tree held in memory, read directly (the in-core run).
/// The brick driver's counterpart is scale/brick_values.hpp.
template <class TreeT>
class InCoreValues {
public:
    using Tree = TreeT;
    InCoreValues(const TreeT& tree, const Signing& signing) : tree_(tree), signing_(signing) {}

    /// Memory per candidate leaf that is checked before stage "cells": all
    /// its results may be held at once (here, every candidate a surface leaf).
    static constexpr double kCandidateBytes = double(LeafResults::kEntryBytes + kCellRecordBytes);

    std::vector<openvdb::Coord> candidate_blocks(const ExtractOptions& options, const openvdb::CoordBBox& clip) const {
        return detail::candidate_blocks(tree_, kCandidateBytes, options, clip);
    }

    NoiseEstimate estimate_noise(const std::vector<openvdb::Coord>& leaves) const {
        return detail::estimate_noise(tree_, signing_, leaves);
    }

    /// Stage "cells" over every candidate leaf; with `smooth`, of the smoothed field.
    template <class Stage>
    void run_cells(Stage& stage, bool smooth, const Progress& progress, StageTimer& timer) const {
        std::unique_ptr<TreeT> smoothed;
        if (smooth) {
            const ProgressSpan smoothing(progress, 0.0, 0.0);
            smoothed = smooth_field(tree_, signing_, &smoothing);
            timer.done("smooth field");
        }
        stage.run(smoothed ? *smoothed : tree_, 0, stage.leaves().size(), progress, 0.0, 0.45);
    }

private:
    const TreeT& tree_;
    const Signing& signing_;
};

/// The reading policy of the in-core run (uniform/pipeline.hpp).
struct InCoreReading {
    void check() const {}
    bool by_bricks() const { return false; }
    template <class TreeT, class Body>
    Mesh with_values(const TreeT& tree, const Signing& signing, const Body& body) const {
        return body(InCoreValues<TreeT>(tree, signing));
    }
};

}  // namespace
}  // namespace pqdc::detail

namespace pqdc {

Mesh extract(const openvdb::FloatGrid& grid, const ExtractOptions& options, ExtractStats* stats) {
    return detail::extract_grid(grid, options, detail::InCoreReading{}, stats);
}

Mesh extract(const openvdb::DoubleGrid& grid, const ExtractOptions& options, ExtractStats* stats) {
    return detail::extract_grid(grid, options, detail::InCoreReading{}, stats);
}

Mesh extract(const openvdb::GridBase& grid, const ExtractOptions& options, ExtractStats* stats) {
    return detail::extract_any_grid(grid, options, detail::InCoreReading{}, stats);
}

Mesh extract(const ScalarField& field, const ProceduralSampling& sampling, const ExtractOptions& options,
             ExtractStats* stats) {
    return detail::extract_procedural(field, sampling, options, detail::InCoreReading{}, stats);
}

}  // namespace pqdc
