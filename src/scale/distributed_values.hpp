// How the uniform brick driver (scale/extract_bricks.cpp) reads values when the ranks
// of a pqdc::RankGroup mesh one volume (pqdc::extract_distributed): each
// rank runs the cells stage on its own run of bricks (rank_bricks) exactly
// as BrickValues does, then the ranks' per-leaf results meet at rank 0
// (scale/cell_parts.hpp). Rank 0 goes on with the whole mesh; on the other
// ranks the results are left empty, so their later stages make an empty mesh.
#pragma once

#include "pqdc/distributed.hpp"
#include "scale/brick_values.hpp"
#include "scale/cell_parts.hpp"

#include <stdexcept>
#include <string>
#include <vector>

namespace pqdc::detail {

template <class TreeT>
class DistributedValues {
public:
    using Tree = TreeT;

    DistributedValues(const BrickSource<TreeT>& source, const Signing& signing, int brick_size, RankGroup& group)
        : bricks_(source, signing, brick_size, &group), group_(group) {}

    std::vector<openvdb::Coord> candidate_blocks(const ExtractOptions& options, const openvdb::CoordBBox& clip) const {
        return bricks_.candidate_blocks(options, clip);
    }

    /// The same sample on every rank, so every rank chooses the same parameters.
    NoiseEstimate estimate_noise(const std::vector<openvdb::Coord>& leaves) const {
        return bricks_.estimate_noise(leaves);
    }

    /// Stage "cells" on this rank's bricks, then the exchange.
    template <class Stage>
    void run_cells(Stage& stage, bool smooth, const Progress& progress, StageTimer&) const {
        const std::vector<BrickRun> bricks = split_into_bricks(stage.leaves(), bricks_.brick_size());
        const auto [first, last] = rank_bricks(bricks, group_.rank(), group_.size());
        bricks_.run_bricks(stage, bricks, first, last, smooth, progress);
        // Rank 0 keeps its own results where they are and sends nothing.
        std::string part;
        if (group_.rank() != 0 && first < last)
            part = encode_cell_part(stage.results(), bricks[first].begin, bricks[last - 1].end, stage.counters());
        std::vector<std::string> parts = group_.gather_at_root(std::move(part));
        if (group_.rank() != 0) return;
        if (parts.size() != std::size_t(group_.size()))
            throw std::logic_error("internal error: the rank group gathered " + std::to_string(parts.size()) +
                                   " parts from " + std::to_string(group_.size()) + " ranks");
        for (std::size_t k = 1; k < parts.size(); ++k) {
            if (!parts[k].empty()) stage.absorb(decode_cell_part(parts[k], stage.leaves(), stage.results()));
            std::string().swap(parts[k]);
        }
    }

private:
    const BrickValues<TreeT> bricks_;
    RankGroup& group_;
};

}  // namespace pqdc::detail
