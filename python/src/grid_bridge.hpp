// The one place that knows how Python objects from pyopenvdb are laid out.
// Debian 12's pyopenvdb (OpenVDB 10.0) is a Boost.Python module; OpenVDB
// 10.1+ switched to pybind11 and later nanobind, and a port replaces only
// grid_bridge_*.cpp.
#pragma once

#include <pybind11/pybind11.h>

#include <openvdb/openvdb.h>

#include <memory>

namespace pqdc::python {

/// A grid borrowed from a Python object. `grid` may hold a reference to the
/// Python object (Boost.Python's shared_ptr deleter decrements it), so the
/// handle must be destroyed with the GIL held; the grid itself may be read
/// without the GIL.
struct BorrowedGrid {
    openvdb::GridBase::Ptr grid;
};

/// The grid behind a pyopenvdb grid object, or an empty grid pointer when
/// `object` is not a pyopenvdb grid (or pyopenvdb was never imported: the
/// converters are registered by its import). Call with the GIL held.
BorrowedGrid borrow_grid(pybind11::handle object);

/// Whether the bridge was built (Boost.Python found at build time).
bool grid_bridge_available();

}  // namespace pqdc::python
