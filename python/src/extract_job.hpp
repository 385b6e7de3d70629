// One extraction as the Python package runs it: source (array, pyopenvdb
// grid or .vdb file) to grid, grid to mesh (uniform or adaptive), vertex
// normals and values from the grid, with the GIL released throughout.
#pragma once

#include "mesh_fields.hpp"

#include <pqdc/mesh.hpp>

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <array>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace pqdc::python {

/// The options of pqdc.extract() after the Python layer checked their types.
/// Strings are parsed (and rejected with option_error) here.
struct Request {
    double isovalue = 0.0;
    double sigma_n = -1.0;                ///< pqdc::sigma_n_auto, or >= 0
    std::string interior = "auto";        ///< auto | below | above
    std::string faces = "triangles";      ///< triangles | quads
    std::string normals = "auto";         ///< auto | central | sharp | least_squares (grid crossings)
    std::string denoise = "auto";         ///< auto | on | off
    std::string containment = "clamp";    ///< clamp | unconstrained
    bool adaptive = false;
    double max_error = 0.1;               ///< adaptive: voxels
    int max_cell_size = 64;               ///< adaptive: voxels, power of two
    int threads = 0;                      ///< 0 = all cores
    std::uint64_t memory_limit = 0;       ///< bytes, 0 = 80% of physical memory
    double min_component = 0.0;           ///< voxels (ExtractOptions::min_component_voxels), 0 keeps all
    pybind11::object progress = pybind11::none();
    /// World-unit box (xmin, ymin, zmin, xmax, ymax, zmax) to mesh; empty = everything.
    std::vector<double> bbox;
    /// ExtractOptions::region.mask from a pyopenvdb grid (None: not given)...
    pybind11::object mask_grid = pybind11::none();
    /// ... or from a .vdb file (empty: none), grid mask_grid_name (empty: the
    /// file's first bool/mask/float/double/int32 grid). Numpy masks are an
    /// argument of extract_array.
    std::string mask_path, mask_grid_name;
    bool invert_mask = false;             ///< mesh where the mask does not hold
    /// The precision the mesh will be stored at: the self-intersection
    /// repair checks the positions rounded to it
    /// (ExtractOptions::stored_precision). False: float32, as Mesh.write's
    /// and the CLI's default.
    bool double_precision = false;
    // Arrays only.
    std::array<double, 3> spacing{1.0, 1.0, 1.0};  ///< world x, y, z voxel size
    std::array<double, 3> origin{0.0, 0.0, 0.0};   ///< world position of voxel (0, 0, 0)
    bool zyx = false;                     ///< numpy axes are z, y, x (image stacks)
    bool sparse = true;                   ///< false: every voxel stored (reference conversion)
};

/// What the vertex normals and values are sampled from, kept until they are
/// first asked for (most callers only want the mesh).
struct FieldSource {
    /// For a pyopenvdb grid this holds a Python reference: reset it with the GIL.
    openvdb::GridBase::ConstPtr grid;
    double outward_sign = 1.0;            ///< +1 inside below the isovalue, -1 above
    bool array = false;                   ///< points = origin + spacing * index
    std::array<double, 3> spacing{1, 1, 1}, origin{0, 0, 0};
    /// The shortest voxel side, world units: the voxel of Mesh.decimate()'s
    /// lengths (kept when the grid is dropped). 0 = unknown (a mesh from arrays).
    double voxel_size = 0.0;
};

struct MeshResult {
    Mesh mesh;  ///< normals only while write_mesh_file() writes them (under write_lock)
    std::mutex write_lock;
    FieldSource source;
    std::once_flag sampled;
    VertexFields fields;                  ///< valid once `sampled` ran
    std::vector<std::pair<std::string, std::uint64_t>> counts;
    std::vector<std::pair<std::string, double>> seconds;
    /// Noise estimate, sigma_n used, ...; None (nullopt) for a figure that
    /// does not apply, where the CLI's --stats writes null.
    std::vector<std::pair<std::string, std::optional<double>>> values;
    std::vector<std::pair<std::string, std::string>> choices;  ///< gradient used
    std::vector<std::pair<std::string, std::string>> labels;
    std::vector<std::string> warnings;    ///< ExtractStats::warnings
    /// The precision whose rounded positions the extraction or decimation
    /// checked for self-intersections: "float", "double", or "" (a mesh read
    /// from a file: unknown).
    std::string checked_precision;
    /// Why a vertex field is missing (fields holds fewer entries than
    /// points): a decimated mesh whose source grid was already released, a
    /// mesh from arrays or from a file. Empty when both can be had.
    std::string fields_unavailable;
};

/// An array's shape as numpy prints it, "(3, 4)" or "(5,)", for messages.
std::string shape_text(const pybind11::array& a);

/// Samples result.fields on first use (GIL held on entry; released while
/// sampling; Ctrl-C cancels). Then drops the grid.
const VertexFields& vertex_fields(MeshResult& result);
/// vertex_fields(result).normals or .values, or input_error saying why the
/// mesh has none (instead of an empty array).
const std::vector<openvdb::Vec3d>& vertex_normals(MeshResult& result);
const std::vector<double>& vertex_values(MeshResult& result);

std::shared_ptr<MeshResult> extract_array(const pybind11::array& array, const pybind11::object& mask,
                                          const Request& request);
/// Returns nullptr when `object` is not a pyopenvdb grid.
std::shared_ptr<MeshResult> extract_grid_object(const pybind11::handle& object, const Request& request);
/// How pqdc.extract_to_file() streams the mesh into its file.
struct StreamRequest {
    std::string output;                   ///< .obj, .ply, .off or .stl (precision: Request::double_precision)
    int brick_size = 256;                 ///< BrickOptions::brick_size, voxels
    int brick_runs = 0;                   ///< BrickOptions::concurrent_runs, 0 = automatic
};

/// Meshes the .vdb file or brick store at `path` brick by brick and streams
/// the mesh into r.output (pqdc::extract_bricks to a MeshStreamWriter, as
/// `pqdc --out-of-core` does): the result holds no mesh, only the stats.
std::shared_ptr<MeshResult> extract_file_to(const std::string& path, const std::string& grid_name, const Request& r,
                                            const StreamRequest& s);

std::shared_ptr<MeshResult> extract_file(const std::string& path, const std::string& grid_name,
                                         const Request& request);

/// pqdc::write_brick_store of the .vdb file's grid (read delay-loaded, so a
/// brick at a time is in memory), GIL released: (brick files, leaves).
/// `progress` (None or callable(fraction)) and Ctrl-C can stop it between
/// bricks; the files written are then removed.
std::pair<std::uint64_t, std::uint64_t> split_file(const std::string& path, const std::string& grid_name,
                                                   const std::string& dir, int brick_size, pybind11::object progress);

}  // namespace pqdc::python
