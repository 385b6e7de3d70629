// Distributed meshing: several processes (ranks) mesh one volume together
// and rank 0 gets the same bytes as pqdc::extract (uniform mode) or
// pqdc::extract_adaptive (adaptive mode).
//
//   MyMpiGroup group(MPI_COMM_WORLD);            // implements pqdc::RankGroup
//   pqdc::LoadedGrid in = pqdc::read_scalar_grid("big.vdb", "", pqdc::VolumeLoading::delayed);
//   pqdc::MeshStreamWriter out("big.ply");       // on every rank; each gets its part
//   pqdc::extract_distributed(*in.grid, options, pqdc::BrickOptions{}, group, out);
//   out.finish(group);                            // every rank: the parts joined in rank order
// or, with the whole mesh in rank 0's memory:
//   pqdc::Mesh mesh = pqdc::extract_distributed(*in.grid, options, pqdc::BrickOptions{}, group);
//   if (group.rank() == 0) pqdc::write_mesh(mesh, "big.ply");
//
// Every rank reads the volume's topology and cuts its candidate leaves into
// the bricks of pqdc::extract_bricks. Rank r takes the r-th of size()
// contiguous runs of bricks, balanced by their leaf counts, and runs the
// cells stage (values, quadrics, vertices) on them, reading only those
// bricks' values. Two ways on from there:
//  - streamed (the overload with a MeshStreamWriter): each rank also builds
//    its bricks' faces and keeps its part of the mesh in scratch files; the
//    ranks exchange vertex counts, rank 0 repairs self-intersections in the
//    part of the mesh near them, and each rank writes its pieces to its own
//    writer; MeshStreamWriter::finish(group) then joins the parts in rank
//    order, each rank writing its own at its offset in a shared file system.
//    No rank holds the whole mesh.
//  - in memory (the overloads returning a Mesh): the per-leaf results go to
//    rank 0 in rank order, which runs the faces, the self-intersection
//    repair and the unused-vertex pass on the whole mesh, as pqdc::extract
//    does. For callers that need the mesh itself.
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
#include "pqdc/mesh_stream.hpp"
#include "pqdc/procedural.hpp"
#include "pqdc/stats.hpp"

#include <openvdb/openvdb.h>

#include <functional>
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
    /// Collective: rank 0's `value` reaches every rank; every rank returns
    /// it (rank 0 its own). The other ranks' arguments are ignored. Values
    /// may be larger than 2 GiB. Throws on a transport failure.
    virtual std::string broadcast_from_root(std::string value) = 0;
    /// On a rank other than 0: sends `message` to rank 0, which takes it with
    /// receive_from(this rank). Messages from one rank arrive in the order
    /// sent. May wait until rank 0 takes it.
    virtual void send_to_root(std::string message) = 0;
    /// On rank 0: the next message rank `from` (1 to size() - 1) sent with
    /// send_to_root(), waiting for it.
    virtual std::string receive_from(int from) = 0;
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
/// The streamed distributed run: meshes like the streamed
/// extract_bricks(grid, options, bricks, out, each_piece, stats), its whole
/// pipeline shared among `group`'s ranks, so that no rank holds the mesh.
/// Rank r meshes the r-th run of bricks (cells, faces, the first exact
/// check) into scratch files next to its `out`; one all-gather of the
/// vertex counts per candidate leaf numbers every vertex globally; rank 0
/// repairs the part of the mesh near self-intersections that every rank
/// sends it; then each rank numbers its used vertices after the earlier
/// ranks' and appends its pieces to its own `out` (`each_piece` sees them
/// there, on their rank). Every rank passes a writer for the same target
/// and options; the caller then calls out.finish(group) on every rank,
/// which writes the file (see MeshStreamWriter::finish). STL pieces, whose
/// facets need every corner at hand, all go to rank 0's writer instead,
/// and so does the whole mesh when a vertex lies 1.5 voxels or more from
/// its cell (the fallback extract_bricks describes). `stats` is the whole
/// run's on rank 0. Memory per rank: the topology, one brick with its halo,
/// 8 bytes per candidate leaf, a bit per own vertex; rank 0 also the part
/// near self-intersections. Same exceptions and
/// transport contract as above.
void extract_distributed(const openvdb::GridBase& grid, const ExtractOptions& options, const BrickOptions& bricks,
                         RankGroup& group, MeshStreamWriter& out, const std::function<void(Mesh&)>& each_piece = {},
                         ExtractStats* stats = nullptr);
/// The streamed distributed run above on a brick store opened with
/// pqdc::BrickStore on every rank: each rank opens only the brick files its
/// own bricks and their halos overlap, after every rank has read each
/// file's candidates (the topology is never assembled). Same bytes.
void extract_distributed(const BrickStore& store, const ExtractOptions& options, const BrickOptions& bricks,
                         RankGroup& group, MeshStreamWriter& out, const std::function<void(Mesh&)>& each_piece = {},
                         ExtractStats* stats = nullptr);
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
