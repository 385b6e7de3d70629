// Distributed meshing: several processes (ranks) mesh one volume together
// and rank 0 gets the same bytes as pqdc::extract (uniform mode) or
// pqdc::extract_adaptive (adaptive mode).
//
//   MyMpiGroup group(MPI_COMM_WORLD);            // implements pqdc::RankGroup
//   pqdc::LoadedGrid in = pqdc::read_scalar_grid("big.vdb", "", pqdc::VolumeLoading::delayed);
//   pqdc::Mesh mesh = pqdc::extract_distributed(*in.grid, options, pqdc::BrickOptions{}, group);
//   if (group.rank() == 0) pqdc::write_mesh(mesh, "big.ply");
//
// Every rank reads the volume's topology and cuts its candidate leaves into
// the bricks of pqdc::extract_bricks. Rank r takes the r-th of size()
// contiguous runs of bricks, balanced by their leaf counts, and runs the
// cells stage (values, quadrics, vertices) on them, reading only those
// bricks' values. The per-leaf results go to rank 0 in rank order; rank 0
// then runs the faces, the self-intersection repair and the unused-vertex
// pass on the whole mesh, as pqdc::extract does. So the cells stage, which
// reads the voxel values, scales out, while the mesh is assembled in rank 0's
// memory (streaming the later stages brick by brick is the next step).
//
// Adaptive mode shares stage "hermite" the same way: each rank builds the
// finest octree level (cells, Hermite data, vertices) of its bricks and
// sends it to rank 0, which builds the octree, the polygons and the
// untangle stage alone, as extract_adaptive_bricks does; when untangle
// rebuilds the octree, rank 0 reads the bricks again by itself.
//
// The library owns no transport: the caller passes a RankGroup (pqdc-mpi
// implements it over MPI; a test can use threads). Ranks must share the
// byte order and word size of rank 0, and every rank must call
// extract_distributed with the same input and options.
#pragma once

#include "pqdc/adaptive.hpp"
#include "pqdc/bricks.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/mesh.hpp"
#include "pqdc/procedural.hpp"
#include "pqdc/stats.hpp"

#include <openvdb/openvdb.h>

#include <string>
#include <vector>

namespace pqdc {

/// The transport between the ranks of one distributed run. The library calls
/// it on every rank in the same order.
class RankGroup {
public:
    virtual ~RankGroup() = default;
    /// This process's rank, 0 to size() - 1.
    virtual int rank() const = 0;
    /// The number of ranks, at least 1.
    virtual int size() const = 0;
    /// Collective: every rank passes its part; rank 0 receives all parts in
    /// rank order (its own first), the other ranks an empty vector. Parts may
    /// be larger than 2 GiB. Throws on a transport failure.
    virtual std::vector<std::string> gather_at_root(std::string part) = 0;
};

/// Meshes like pqdc::extract(grid, options, stats), the work of the cells
/// stage shared among `group`'s ranks brick by brick (`bricks` as for
/// extract_bricks). Returns the whole mesh on rank 0 and an empty mesh on
/// every other rank; `stats` (rank 0) counts every rank's cells. The grid
/// may be delay-loaded (VolumeLoading::delayed): each rank then reads only
/// its own bricks' values. Same exceptions as extract; a rank that throws
/// leaves the others waiting in gather_at_root, so the transport must end
/// the run (pqdc-mpi aborts the MPI job).
Mesh extract_distributed(const openvdb::GridBase& grid, const ExtractOptions& options, const BrickOptions& bricks,
                         RankGroup& group, ExtractStats* stats = nullptr);
/// Procedural fields: every rank samples the field, then shares the cells
/// stage as above.
Mesh extract_distributed(const ScalarField& field, const ProceduralSampling& sampling, const ExtractOptions& options,
                         const BrickOptions& bricks, RankGroup& group, ExtractStats* stats = nullptr);

/// Adaptive mode: like pqdc::extract_adaptive_bricks(grid, options, bricks,
/// stats), the finest level's bricks shared among `group`'s ranks (see the
/// file comment). Rank 0 returns the whole mesh and `stats` counts every
/// rank's cells; every other rank returns an empty mesh. Same exceptions
/// and the same transport contract as extract_distributed.
Mesh extract_adaptive_distributed(const openvdb::GridBase& grid, const AdaptiveOptions& options,
                                  const BrickOptions& bricks, RankGroup& group, AdaptiveStats* stats = nullptr);
/// Procedural fields: every rank samples the field, then shares stage
/// "hermite" as above.
Mesh extract_adaptive_distributed(const ScalarField& field, const ProceduralSampling& sampling,
                                  const AdaptiveOptions& options, const BrickOptions& bricks, RankGroup& group,
                                  AdaptiveStats* stats = nullptr);

}  // namespace pqdc
