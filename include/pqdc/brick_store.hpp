// A brick store (issue 14): a grid split into one small .vdb file per brick,
// written by streaming the source once. It is read back either as one grid
// whose leaf buffers stay in those files (read_brick_store: the topology
// assembled), or, for the streamed runs, file by file (BrickStore: the
// topology never whole in memory). Both mesh with the source's bytes.
//
//   DIR/index.txt   "pqdc-brick-store 3", then "shell grid.vdb BYTES XXH3",
//                   then one line per brick: "brick FILE xmin ymin zmin xmax
//                   ymax zmax BYTES XXH3", then "end N" (N brick lines).
//                   XXH3: the file's 64-bit XXH3 checksum in 16 hex digits,
//                   checked before the file is parsed. Stores of format 2
//                   (no checksums) and 1 (no end line; sizes missing in the
//                   oldest) are still read.
//   DIR/grid.vdb    the grid without voxels: name, class, transform,
//                   metadata, background and the root's tiles
//   DIR/brick-N.vdb the source's leaves and tiles inside brick N's box (no
//                   halo: a brick's halo is read from its neighbours' files)
//
// The index is written last, so an interrupted split leaves no store; a
// split stopped through its progress callback or failing removes its files.
#pragma once

#include "pqdc/bricks.hpp"
#include "pqdc/procedural.hpp"
#include "pqdc/volume_io.hpp"

#include <openvdb/openvdb.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

namespace pqdc {

struct ExtractOptions;
namespace detail {
class StoreIndex;
}

struct BrickStoreSummary {
    std::uint64_t bricks = 0;  ///< brick files written
    std::uint64_t leaves = 0;  ///< leaf nodes in them
};

/// Called from the writing thread before the first brick and after each
/// brick box with the fraction of the boxes done (0 to 1). Returning false
/// stops the split: what was written is removed (the directory too, if the
/// split made it) and write_brick_store throws cancelled_error. The hook is
/// how an app's Ctrl-C leaves no files behind. May be empty.
using BrickStoreProgress = std::function<bool(double fraction)>;

/// Writes the float or double `grid` (which may be delay-loaded: each brick
/// loads only copies of its own leaves) as a brick store into directory
/// `dir` (created if missing; it must not hold a store or other files).
/// bricks.brick_size sets the files' extent (see pqdc/bricks.hpp). Throws
/// option_error, input_error (not a scalar grid) or io_error naming the path,
/// and cancelled_error when `progress` returned false; a split that throws
/// leaves nothing in `dir`.
BrickStoreSummary write_brick_store(const openvdb::GridBase& grid, const std::string& dir,
                                    const BrickOptions& bricks = BrickOptions{},
                                    const BrickStoreProgress& progress = {});

/// Writes the volume pqdc::sample_field(field, sampling) would make as a
/// brick store, sampling one brick at a time: memory holds one brick, so
/// volumes far larger than memory can be made (the scale benchmark's).
/// Meshing the store gives the same bytes as meshing sample_field's grid.
/// Throws like the overload above, and option_error for bad sampling.
BrickStoreSummary write_brick_store(const ScalarField& field, const ProceduralSampling& sampling,
                                    const std::string& dir, const BrickOptions& bricks = BrickOptions{},
                                    const BrickStoreProgress& progress = {});

/// True when `path` is a directory holding a brick store's index.txt.
bool is_brick_store(const std::string& path);

/// The grid of the brick store in `dir`: structure in memory, leaf buffers
/// left in the brick files (LoadedGrid::delay_loaded). Throws input_error
/// naming the store and file when the index or a brick file is missing or
/// unreadable.
LoadedGrid read_brick_store(const std::string& dir);

/// A brick store opened for the streamed runs (pqdc::extract_bricks and
/// pqdc::extract_distributed with a MeshStreamWriter), for stores whose
/// topology alone does not fit in memory: only index.txt and the shell grid
/// are read here. The run opens each brick file when it meshes a brick
/// whose box (with its halo) overlaps it, and keeps the files' parsed
/// topology in a cache of at most 1/8 of the memory limit; the candidate
/// list is merged from every file's own (12 bytes per candidate leaf).
/// Same bytes as meshing read_brick_store's grid. Copies share the store.
class BrickStore {
public:
    /// Throws input_error naming the store and the file when index.txt or
    /// the shell is missing, unreadable or fails its checksum, a line is
    /// bad, or a brick file's size differs from the index's. (A brick
    /// file's checksum is checked when the run first opens it.)
    explicit BrickStore(const std::string& dir);

    const std::string& path() const { return path_; }
    /// The grid without voxels: name, class, transform, metadata, background
    /// and the root's tiles.
    const openvdb::GridBase& shell() const { return *shell_; }
    /// Brick files in the store.
    std::size_t brick_files() const;
    /// True when meshing with `options` needs the whole topology after all,
    /// so the runs read the store with read_brick_store: when the isovalue
    /// is the grid's background (or the background is NaN), the interior
    /// rule and the warnings look at every active value.
    bool assembles_for(const ExtractOptions& options) const;
    /// The parsed index (for the library's runs).
    const detail::StoreIndex& index() const { return *index_; }

private:
    std::string path_;
    std::shared_ptr<const detail::StoreIndex> index_;
    openvdb::GridBase::Ptr shell_;
};

}  // namespace pqdc
