// How the uniform brick driver (scale/extract_bricks.cpp) reads values when meshing
// brick by brick (issue 14, phase 1): the stages that read the volume's
// values see only small trees copied out of a BrickSource, one brick (plus
// halo) at a time, so the input held in memory is the topology plus one
// brick. The noise estimate stays global: it reads at most
// kNoiseMaxLeaves blocks spread over the whole candidate list, copied into
// one small tree.
//
// Phase 1 only: the per-leaf results are kept and the faces, untangle and
// unused-vertex stages then run on the assembled mesh as in core; streaming
// those brick by brick (and the writers) is phase 2.
#pragma once

#include "lattice/interior.hpp"
#include "lattice/noise_estimate.hpp"
#include "lattice/resources.hpp"
#include "lattice/smooth_field.hpp"
#include "lattice/stage_timer.hpp"
#include "bricks/brick_source.hpp"
#include "bricks/bricks.hpp"
#include "bricks/mapped_pages.hpp"
#include "ranks/rank_exchange.hpp"
#include "uniform/cells.hpp"

#include <memory>
#include <vector>

namespace pqdc::detail {

template <class TreeT>
class BrickValues {
public:
    using Tree = TreeT;

    /// `brick_size`: BrickOptions::brick_size, validated. `group`: the ranks
    /// that compute the candidates together (candidate_blocks is then
    /// collective); null for this process alone.
    BrickValues(const BrickSource<TreeT>& source, const Signing& signing, int brick_size, RankGroup* group = nullptr)
        : source_(source), signing_(signing), brick_size_(brick_size), group_(group) {}

    const BrickSource<TreeT>& source() const { return source_; }
    typename TreeT::ValueType background() const { return source_.background(); }

    /// Memory per candidate leaf checked before stage "cells": only its
    /// entries. Most candidates of a dense volume (a scan) hold no surface,
    /// so the cell records are checked as they accrue, brick by brick
    /// (run_bricks), instead of assuming every candidate holds some.
    static constexpr double kCandidateBytes = double(LeafResults::kEntryBytes);

    /// Stage "candidates" (lattice/candidates.hpp) of the source.
    std::vector<openvdb::Coord> candidate_blocks(const ExtractOptions& options, const openvdb::CoordBBox& clip) const {
        SoloRank alone;
        return source_.candidate_blocks(kCandidateBytes, options, clip, group_ ? *group_ : alone);
    }

    NoiseEstimate estimate_noise(const std::vector<openvdb::Coord>& leaves) const {
        const std::vector<openvdb::Coord> sample = noise_sample(leaves);
        TreeT values(background());
        // The sample is spread over the whole file, and each leaf read maps
        // the pages around it too (the kernel's fault-around: 64 KiB): on a
        // 3.2 GB store the 1024 blocks mapped 1.7 GB. So the copies are
        // loaded and the mapped pages dropped in batches.
        constexpr std::size_t kBatch = 64;
        for (std::size_t i = 0; i < sample.size(); ++i) {
            source_.copy_box(noise_block_points(sample[i]), values);
            if ((i + 1) % kBatch != 0 && i + 1 != sample.size()) continue;
            for (auto it = values.beginLeaf(); it; ++it) it->buffer().data();  // loads an out-of-core copy
            release_mapped_volume_pages();
        }
        return detail::estimate_noise(values, signing_, sample);
    }

    /// Stage "cells" brick by brick; with `smooth`, each brick's tree is
    /// smoothed (smooth_field) before it is meshed.
    template <class Stage>
    void run_cells(Stage& stage, bool smooth, const Progress& progress, StageTimer&) const {
        const std::vector<BrickRun> bricks = split_into_bricks(stage.leaves(), brick_size_);
        run_bricks(stage, bricks, 0, bricks.size(), smooth, progress);
    }

    /// The share of the run's progress (from 0) that run_bricks reports over its bricks.
    static constexpr double kCellsProgress = 0.45;

    /// Stage "cells" on bricks [first, last) of `bricks` (split_into_bricks
    /// of the stage's leaves), progress going from 0 to kCellsProgress over them.
    template <class Stage>
    void run_bricks(Stage& stage, const std::vector<BrickRun>& bricks, std::size_t first, std::size_t last,
                    bool smooth, const Progress& progress) const {
        const int halo = brick_halo(stage.reach(), smooth);
        const double n = double(last - first);
        std::uint64_t records = 0;
        for (std::size_t k = first; k < last; ++k) {
            std::unique_ptr<TreeT> values = values_around(bricks[k].box, halo, smooth);
            stage.run(*values, bricks[k].begin, bricks[k].end, progress, kCellsProgress * double(k - first) / n,
                      kCellsProgress * double(k + 1 - first) / n);
            values.reset();
            release_mapped_volume_pages();  // else every brick's file pages stay resident to the end
            records += stage.record_bytes(bricks[k].begin, bricks[k].end);
            check_memory(double(records), stage.options(), "cell records");
        }
    }

    int brick_size() const { return brick_size_; }

    /// A tree of the source's values in `box` grown by `halo` voxels,
    /// smoothed (smooth_field) with `smooth`.
    std::unique_ptr<TreeT> values_around(openvdb::CoordBBox box, int halo, bool smooth) const {
        box.expand(halo);
        auto values = std::make_unique<TreeT>(background());
        source_.copy_box(box, *values);
        if (smooth) values = smooth_field(*values, signing_);
        return values;
    }

private:
    const BrickSource<TreeT>& source_;
    const Signing& signing_;
    const int brick_size_;
    RankGroup* const group_;
};

}  // namespace pqdc::detail
