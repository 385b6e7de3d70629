#include "grid_bridge.hpp"

#include <boost/python.hpp>

namespace pqdc::python {
namespace {

// Boost.Python's converter registry lives in the shared libboost_python, so
// the shared_ptr converters pyopenvdb registered at its import are visible
// here. None converts to a null pointer, which extract() accepts: test it.
template <class GridT>
openvdb::GridBase::Ptr try_extract(PyObject* object) {
    boost::python::extract<typename GridT::Ptr> grid(object);
    if (!grid.check()) return nullptr;
    return grid();
}

}  // namespace

BorrowedGrid borrow_grid(pybind11::handle object) {
    BorrowedGrid out;
    if (!object || object.is_none()) return out;
    PyObject* o = object.ptr();
    if (!(out.grid = try_extract<openvdb::FloatGrid>(o)))
        if (!(out.grid = try_extract<openvdb::DoubleGrid>(o)))
            if (!(out.grid = try_extract<openvdb::Vec3SGrid>(o)))
                out.grid = try_extract<openvdb::BoolGrid>(o);
    return out;
}

bool grid_bridge_available() { return true; }

}  // namespace pqdc::python
