// pqdc.Mesh.decimate() and pqdc.decimate(): pqdc::decimate on a copy of a
// mesh, with the GIL released, as a new result that keeps the source grid
// (for its vertex normals) where the input still held it.
#pragma once

#include "extract_job.hpp"

#include <pybind11/numpy.h>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

namespace pqdc::python {

/// The options of decimate() after the Python layer checked their types.
/// Lengths are in voxels, as in pqdc::DecimateOptions.
struct DecimateRequest {
    std::size_t target_faces = 0;         ///< 0 = none
    double target_ratio = 0.0;            ///< 0 = none, else (0, 1]
    double max_distance = 0.0;            ///< voxels, 0 = none
    /// World units per voxel; 0 = the source grid's shortest voxel side, or
    /// the mean edge length for a mesh from arrays.
    double voxel_size = 0.0;
    std::string metric = "triangle";      ///< triangle | plane | curvature
    double sigma_position = -1.0;         ///< voxels, or pqdc::sigma_position_auto
    double sigma_normal = 0.05;           ///< dimensionless
    int threads = 0;                      ///< 0 = all cores
    std::uint64_t memory_limit = 0;       ///< bytes, 0 = 80% of physical memory
    /// The precision the result will be stored at: no collapse may create an
    /// intersection in the positions rounded to it
    /// (DecimateOptions::stored_precision). False: float32.
    bool double_precision = false;
    /// None, or callable(fraction) called between passes; False cancels.
    pybind11::object progress = pybind11::none();
};

/// Decimates a copy of `input`'s mesh. The result carries the decimation's
/// stats (prefixed "decimate_") after the input's, and the input's source
/// grid when it still holds it (call with the GIL held).
std::shared_ptr<MeshResult> decimate_result(MeshResult& input, const DecimateRequest& request);

/// Decimates the mesh given as arrays: vertices (N, 3) of any real dtype,
/// faces (M, 3) or (M, 4) of any integer dtype, normals (N, 3) carried over
/// or (0, 3) for none. Its vertex values are not available (there is no
/// field).
std::shared_ptr<MeshResult> decimate_arrays(const pybind11::array& vertices, const pybind11::array& faces,
                                            const pybind11::array& normals, const DecimateRequest& request);

}  // namespace pqdc::python
