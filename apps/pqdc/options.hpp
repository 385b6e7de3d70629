// pqdc's command line: what the user asked for, validated.
#pragma once

#include "pqdc/adaptive.hpp"
#include "pqdc/bricks.hpp"
#include "pqdc/decimate.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/mesh_io.hpp"
#include "pqdc/procedural.hpp"

#include <optional>
#include "pqdc/version.hpp"

#include <set>
#include <string>
#include <vector>

namespace pqdc_app {

constexpr const char* kVersion = pqdc::version_string;

struct CliOptions {
    std::string input;   ///< .vdb path; "-" = standard input; empty with --procedural
    std::string output;  ///< mesh path, may hold "{grid}"; "-" = standard output
    std::optional<pqdc::MeshFormat> format;  ///< --format; otherwise from the extension
    pqdc::VertexPrecision precision = pqdc::VertexPrecision::float32;
    bool vertex_normals = false;
    std::vector<std::string> grids;  ///< --grid a,b; empty = the first scalar grid; {"*"} = every scalar grid
    std::string grid_text;           ///< --grid as given: a grid whose own name holds commas is found by it
    std::string procedural;
    std::string write_volume;
    std::string stats_path;  ///< may hold "{grid}"
    pqdc::ExtractOptions extract;  ///< region.bbox from --bbox; region.mask is read by the job
    std::string mask_path;   ///< --mask FILE.vdb[:GRID]: the file ("" = no mask)
    std::string mask_grid;   ///< its grid ("" = the first usable grid)
    bool invert_mask = false;  ///< --invert-mask (set into extract.region with the mask, by the job)
    pqdc::ProceduralSampling sampling;
    pqdc::Figure3Params figure3;
    bool adaptive = false;
    double max_error_voxels = pqdc::AdaptiveOptions{}.max_error_voxels;
    int max_cell_size_voxels = pqdc::AdaptiveOptions{}.max_cell_size_voxels;
    /// --min-component: components whose bounding-box diagonal is below this
    /// many voxels are removed (pqdc::remove_small_components); 0 keeps all.
    double min_component_voxels = 0;
    bool decimate = false;                 ///< --decimate
    pqdc::DecimateOptions decimation;      ///< its targets; voxel_size and threads are set per job
    /// --out-of-core (or --brick-size): mesh a .vdb grid brick by brick from
    /// the file; also chosen when the grid's in-memory size exceeds the memory limit.
    bool out_of_core = false;
    pqdc::BrickOptions bricks;
    int threads = 0;
    bool quiet = false;
    bool force_progress = false;
    std::set<std::string> given;  ///< long names of the options on the command line

    bool has(const std::string& long_name) const { return given.count(long_name) != 0; }
    bool several_grids() const { return grids.size() > 1 || (grids.size() == 1 && grids[0] == "*"); }
};

/// Which program parses: pqdc, or pqdc-mpi (the same options; its own --help).
enum class Program { pqdc, pqdc_mpi };

/// Parses and validates argv; false when --help or --version was printed.
/// Throws pqdc_cli::UsageError.
bool parse_command_line(int argc, char** argv, CliOptions& options, Program program);

/// Throws pqdc_cli::UsageError unless -o and --stats give each of several
/// grids a file of its own (not -o -; {grid} in the name). At parse time for
/// --grid '*', once the file is read for a list (one name may hold commas).
void check_one_mesh_per_file(const CliOptions& options);

/// The output pattern with "{grid}" replaced by the grid's name ('/' and
/// other characters a file name cannot hold become '_').
std::string expand_grid_pattern(const std::string& pattern, const std::string& grid);

}  // namespace pqdc_app
