// Reading and writing OpenVDB volumes with errors a user can act on.
#pragma once

#include <openvdb/openvdb.h>

#include <cstdint>
#include <string>
#include <vector>

namespace pqdc {

/// A grid read from a .vdb file, with what was chosen and why.
struct LoadedGrid {
    openvdb::GridBase::Ptr grid;          ///< a FloatGrid or DoubleGrid (read_mask_grid: see there)
    std::vector<std::string> grid_names;  ///< every grid in the file, by name (the order vdb_print lists)
    std::vector<std::string> scalar_grid_names;  ///< the float/double ones
    bool chosen_automatically = false;   ///< no name was given and the first scalar grid was taken
    bool delay_loaded = false;           ///< read with VolumeLoading::delayed (or chosen so): buffers in the file
};

/// How read_scalar_grid loads voxel values.
enum class VolumeLoading {
    whole,    ///< every leaf buffer read (and checked) now; the file may change afterwards
    /// Only the tree's structure is read; leaf buffers stay in the
    /// memory-mapped file (OpenVDB's delayed loading) and are read when
    /// touched. For pqdc::extract_bricks (pqdc/bricks.hpp), which reads
    /// copies of each brick's leaves and never loads the grid's own. The file
    /// must not change while the grid is in use. Files written as one stream
    /// (no grid offsets) are read whole.
    delayed,
    /// delayed when the grid's in-memory size, as the file's metadata
    /// records it (file_mem_bytes, written by OpenVDB's io::File), exceeds
    /// the given threshold; whole otherwise or without that record.
    delayed_if_larger,
};

/// How a whole read (VolumeLoading::whole, or delayed_if_larger below its
/// threshold) decompresses the leaf buffers.
enum class LeafDecoding {
    /// One after the other from the file, as OpenVDB's io::File reads them.
    /// Corrupt files throw input_error (none of 300 bit-flipped files
    /// crashed it, though OpenVDB's reader is known to on some).
    serial,
    /// The file mapped, then the buffers in parallel, each on its own. The
    /// same grid, about twice as fast on two cores (a 12.7 M-voxel sphere
    /// 0.50-0.66 s -> 0.30 s), more on more. But OpenVDB's mapped reader
    /// checks less: in a sweep of 300 bit-flipped files, 28 crashed the
    /// process instead of throwing (12 of them read fine serially). For
    /// callers that isolate the read in a process of their own, as the pqdc
    /// command does.
    parallel,
};

/// Reads the scalar grid `grid_name` from `path`, or, when grid_name is
/// empty, the first float or double grid in the order vdb_print lists them
/// (by name). Throws input_error
/// naming the file (and grid) for a missing/unreadable/non-VDB/corrupt file,
/// a file without grids, an unknown grid name (listing the names there are)
/// or a non-scalar grid (listing the scalar ones).
/// `delay_above_bytes`: the threshold of VolumeLoading::delayed_if_larger.
/// `decoding`: see LeafDecoding.
LoadedGrid read_scalar_grid(const std::string& path, const std::string& grid_name = "",
                            VolumeLoading loading = VolumeLoading::whole, std::uint64_t delay_above_bytes = 0,
                            LeafDecoding decoding = LeafDecoding::serial);

/// The same for a grid to use as ExtractOptions::region.mask: bool, mask,
/// float, double or int32 (scalar_grid_names then lists those).
LoadedGrid read_mask_grid(const std::string& path, const std::string& grid_name = "");

/// Writes one grid to a .vdb file atomically (temporary file + rename), in
/// the seekable format of OpenVDB's io::File (it can be delay-loaded);
/// standard output ("-") gets the stream format;
/// throws io_error naming the path on failure.
void write_grid(const openvdb::GridBase& grid, const std::string& path);

}  // namespace pqdc
