// Out-of-core meshing, brick by brick: the same bytes as pqdc::extract
// (and, for adaptive mode, pqdc::extract_adaptive), with the volume's voxel
// values held in memory one brick at a time.
//
//   pqdc::LoadedGrid in = pqdc::read_scalar_grid("big.vdb", "", pqdc::VolumeLoading::delayed);
//   pqdc::Mesh mesh = pqdc::extract_bricks(*in.grid, options, pqdc::BrickOptions{});
//
// A brick is a box of whole 128^3 internal nodes that is one run of the
// tree order (128: one node; 4096: one root child, 4096^3 voxels; sizes in
// between are slabs of the same volume). For each brick in tree order a
// small tree is copied out of the volume holding the brick and a halo of
// 8 voxels (16 when the field is smoothed for denoising), its candidate
// leaves are meshed, and the tree is dropped. With a grid read with delayed
// loading the grid's own leaf buffers are never loaded: memory holds the
// topology, one brick and the mesh.
//
// The overloads that return a Mesh assemble it in memory (faces, the
// self-intersection repair and the unused-vertex pass run on the whole
// mesh, as in pqdc::extract); the one that takes a MeshStreamWriter never
// holds the whole mesh.
#pragma once

#include "pqdc/adaptive.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/mesh.hpp"
#include "pqdc/mesh_stream.hpp"
#include "pqdc/procedural.hpp"
#include "pqdc/stats.hpp"

#include <openvdb/openvdb.h>

#include <cstdint>
#include <functional>

namespace pqdc {

class BrickStore;

struct BrickOptions {
    /// Voxels per brick, as the edge of a cube of the same volume: a power
    /// of two from 128 to 4096. Memory for values grows with its cube
    /// (256: 16.7 M voxels, 64 MiB of float values plus the halo). The
    /// output does not depend on it. Default 256.
    int brick_size = 256;
    /// Runs of bricks one process meshes at once in a streamed run (the
    /// extract_bricks overload with a MeshStreamWriter), each on its own
    /// thread, one brick at a time: the per-brick work is largely serial,
    /// so this is what puts a second core to work. Memory grows with it:
    /// one brick in flight and 48 bytes per candidate leaf per run.
    /// 0: the threads TBB may use, at most 4, and fewer when the runs'
    /// per-leaf entries would take more than an eighth of the memory limit.
    /// 1 to 64 otherwise. The output does not depend on it. Default 0.
    int concurrent_runs = 0;
};

/// Throws option_error naming the field when options are out of range.
void validate(const BrickOptions& options);

/// Meshes like pqdc::extract(grid, options, stats), reading the grid's
/// values brick by brick. The grid may have been read with delayed loading
/// (VolumeLoading::delayed): its leaf buffers then stay in the file, and
/// each brick reads copies of the leaves it needs. Same exceptions as extract.
Mesh extract_bricks(const openvdb::FloatGrid& grid, const ExtractOptions& options, const BrickOptions& bricks,
                    ExtractStats* stats = nullptr);
Mesh extract_bricks(const openvdb::DoubleGrid& grid, const ExtractOptions& options, const BrickOptions& bricks,
                    ExtractStats* stats = nullptr);
/// Dispatches on the grid's value type (float, double); other types throw input_error.
Mesh extract_bricks(const openvdb::GridBase& grid, const ExtractOptions& options, const BrickOptions& bricks,
                    ExtractStats* stats = nullptr);
/// Meshes like extract_bricks(grid, options, bricks, stats) and writes the
/// mesh to `out` brick by brick instead of returning it (the caller then
/// calls out.finish()): the file has the in-core run's bytes, and memory
/// holds the topology, one brick with its halo, the part of the mesh near
/// self-intersections the untangle stage repairs, and a bit per vertex.
/// Each brick's faces and vertices wait in two scratch files next to the
/// output (about 40 bytes per vertex and 4 per face index), so its disk
/// needs room for those beside the output. `each_piece` (may be empty) sees
/// every piece, with its final positions and global face indices, before it
/// is appended: the place for per-vertex attributes that depend on the
/// vertex alone (with options.vertex_normals the piece already has its
/// normals; `out` must then be made with_normals, else option_error).
/// Vertices placed
/// 1.5 voxels or more from their cells (containment off) make the
/// untangle stage's locality argument fail: the mesh is then assembled in
/// memory as extract_bricks does, and written in one piece.
void extract_bricks(const openvdb::GridBase& grid, const ExtractOptions& options, const BrickOptions& bricks,
                    MeshStreamWriter& out, const std::function<void(Mesh&)>& each_piece = {},
                    ExtractStats* stats = nullptr);

/// The streamed run above on a brick store opened with pqdc::BrickStore,
/// whose topology is never assembled: memory holds the candidate list (12
/// bytes per candidate leaf), the brick files' topology cache and what the
/// run above holds besides the topology. Same bytes as the run above on
/// read_brick_store(store.path()).grid; same exceptions.
void extract_bricks(const BrickStore& store, const ExtractOptions& options, const BrickOptions& bricks,
                    MeshStreamWriter& out, const std::function<void(Mesh&)>& each_piece = {},
                    ExtractStats* stats = nullptr);

/// Like pqdc::extract(field, sampling, ...): the sampled grid is in memory,
/// the cells stage runs brick by brick (same bytes).
Mesh extract_bricks(const ScalarField& field, const ProceduralSampling& sampling, const ExtractOptions& options,
                    const BrickOptions& bricks, ExtractStats* stats = nullptr);

/// Adaptive mode brick by brick: the same bytes as pqdc::extract_adaptive
/// with the same arguments. A separate entry point (not an option of
/// extract_adaptive) because the grid may be delay-loaded, which
/// extract_adaptive would load whole. The stages that read every candidate's
/// values (noise estimate, smooth field, the finest level's Hermite data and
/// its merges into cells of up to 8 voxels) read one brick plus halo at a
/// time; the upper octree levels and the polygons then read copies of the
/// leaves near the surface, a few per thread at a time (smoothed leaf by
/// leaf on noisy grids). The grid's own leaves are never loaded. Memory: the
/// topology, one brick, and output-sized data (the octree nodes that stay,
/// the mesh). The untangle stage's uniform fallback meshes with extract_bricks.
/// Same exceptions as extract_adaptive, and option_error for bad bricks.
Mesh extract_adaptive_bricks(const openvdb::FloatGrid& grid, const AdaptiveOptions& options,
                             const BrickOptions& bricks, AdaptiveStats* stats = nullptr);
Mesh extract_adaptive_bricks(const openvdb::DoubleGrid& grid, const AdaptiveOptions& options,
                             const BrickOptions& bricks, AdaptiveStats* stats = nullptr);
/// Dispatches on the grid's value type (float, double); other types throw input_error.
Mesh extract_adaptive_bricks(const openvdb::GridBase& grid, const AdaptiveOptions& options,
                             const BrickOptions& bricks, AdaptiveStats* stats = nullptr);
/// Like pqdc::extract_adaptive(field, sampling, ...): the sampled grid is in
/// memory, the finest level and its first merges are built brick by brick
/// (same bytes).
Mesh extract_adaptive_bricks(const ScalarField& field, const ProceduralSampling& sampling,
                             const AdaptiveOptions& options, const BrickOptions& bricks,
                             AdaptiveStats* stats = nullptr);

/// Bytes the grid's voxel values and nodes take when fully in memory (for
/// a delay-loaded grid, what loading it would take): what decides between
/// pqdc::extract and extract_bricks against a memory limit.
std::uint64_t in_core_bytes(const openvdb::GridBase& grid);

/// The memory limit extraction applies: options.memory_limit_bytes, or 80%
/// of physical memory when it is 0 (bytes).
std::uint64_t effective_memory_limit(const ExtractOptions& options);

}  // namespace pqdc
