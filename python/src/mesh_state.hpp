// pqdc.Mesh's C++ data as plain Python values and back, so that a Mesh can
// be pickled (multiprocessing, joblib, dask hand results between processes).
#pragma once

#include "extract_job.hpp"

#include <pybind11/pybind11.h>

#include <memory>

namespace pqdc::python {

/// Everything a restored mesh needs: its arrays, its vertex normals and
/// values (sampled now from the grid it came from, if not yet: the grid
/// does not travel), the voxel size its decimation measures in, and its
/// stats.
pybind11::tuple mesh_state(MeshResult& result);

/// The mesh mesh_state() described; its vertex fields are the ones saved.
/// input_error for a tuple that is not such a state.
std::shared_ptr<MeshResult> mesh_from_state(const pybind11::tuple& state);

}  // namespace pqdc::python
