// Reading and writing OpenVDB volumes with errors a user can act on.
#pragma once

#include <openvdb/openvdb.h>

#include <string>
#include <vector>

namespace pqdc {

/// A grid read from a .vdb file, with what was chosen and why.
struct LoadedGrid {
    openvdb::GridBase::Ptr grid;          ///< a FloatGrid or DoubleGrid (read_mask_grid: see there)
    std::vector<std::string> grid_names;  ///< every grid in the file, by name (the order vdb_print lists)
    std::vector<std::string> scalar_grid_names;  ///< the float/double ones
    bool chosen_automatically = false;   ///< no name was given and the first scalar grid was taken
};

/// Reads the scalar grid `grid_name` from `path`, or, when grid_name is
/// empty, the first float or double grid in the order vdb_print lists them
/// (by name). Throws input_error
/// naming the file (and grid) for a missing/unreadable/non-VDB/corrupt file,
/// a file without grids, an unknown grid name (listing the names there are)
/// or a non-scalar grid (listing the scalar ones).
LoadedGrid read_scalar_grid(const std::string& path, const std::string& grid_name = "");

/// The same for a grid to use as ExtractOptions::region.mask: bool, mask,
/// float, double or int32 (scalar_grid_names then lists those).
LoadedGrid read_mask_grid(const std::string& path, const std::string& grid_name = "");

/// Writes one grid to a .vdb file atomically (temporary file + rename);
/// throws io_error naming the path on failure.
void write_grid(const openvdb::GridBase& grid, const std::string& path);

}  // namespace pqdc
