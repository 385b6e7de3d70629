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
#include <string>
#include <utility>
#include <vector>

namespace pqdc::python {

/// The options of pqdc.extract() after the Python layer checked their types.
/// Strings are parsed (and rejected with option_error) here.
struct Request {
    double isovalue = 0.0;
    double sigma_n = 0.1;
    std::string interior = "auto";        ///< auto | below | above
    std::string faces = "triangles";      ///< triangles | quads
    std::string normals = "central";      ///< central | sharp (Hermite normals of grid crossings)
    std::string containment = "clamp";    ///< clamp | unconstrained
    bool adaptive = false;
    double max_error = 0.1;               ///< adaptive: voxels
    int max_cell_size = 64;               ///< adaptive: voxels, power of two
    int threads = 0;                      ///< 0 = all cores
    std::uint64_t memory_limit = 0;       ///< bytes, 0 = 80% of physical memory
    pybind11::object progress = pybind11::none();
    // Arrays only.
    std::array<double, 3> spacing{1.0, 1.0, 1.0};  ///< world x, y, z voxel size
    std::array<double, 3> origin{0.0, 0.0, 0.0};   ///< world position of voxel (0, 0, 0)
    bool zyx = false;                     ///< numpy axes are z, y, x (image stacks)
    bool sparse = true;                   ///< false: every voxel stored (reference conversion)
};

struct MeshResult {
    Mesh mesh;
    VertexFields fields;
    std::vector<std::pair<std::string, std::uint64_t>> counts;
    std::vector<std::pair<std::string, double>> seconds;
    std::vector<std::pair<std::string, std::string>> labels;
};

std::shared_ptr<MeshResult> extract_array(const pybind11::array& array, const pybind11::object& mask,
                                          const Request& request);
/// Returns nullptr when `object` is not a pyopenvdb grid.
std::shared_ptr<MeshResult> extract_grid_object(const pybind11::handle& object, const Request& request);
std::shared_ptr<MeshResult> extract_file(const std::string& path, const std::string& grid_name,
                                         const Request& request);

}  // namespace pqdc::python
