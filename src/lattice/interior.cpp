#include "lattice/interior.hpp"

namespace pqdc::detail {

Signing grid_signing(openvdb::GridClass grid_class, const ExtractOptions& options) {
    Interior interior = options.interior;
    if (interior == Interior::automatic)
        interior = grid_class == openvdb::GRID_FOG_VOLUME ? Interior::above_isovalue : Interior::below_isovalue;
    Signing s;
    s.isovalue = options.isovalue;
    s.sign = interior == Interior::above_isovalue ? -1.0 : 1.0;
    return s;
}

}  // namespace pqdc::detail
