#include "grid_bridge.hpp"

namespace pqdc::python {

// Built when Boost.Python is missing: pyopenvdb grids are not recognized
// (they raise TypeError like any other unsupported object).
BorrowedGrid borrow_grid(pybind11::handle) { return {}; }

bool grid_bridge_available() { return false; }

}  // namespace pqdc::python
