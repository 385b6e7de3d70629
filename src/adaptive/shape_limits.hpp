// The steps of adaptive stage "polygons" that improve triangle shapes:
// tangential relaxation (relax.hpp), then angle flips (angle_flips.hpp).
// Stage "untangle" switches both off when it retries a mesh it could not
// repair (adaptive/untangle.cpp).
#pragma once

#include "adaptive/angle_flips.hpp"
#include "adaptive/relax.hpp"

namespace pqdc::adaptive_detail {

struct ShapeLimits {
    RelaxLimits relax;
    AngleFlipLimits flips;

    /// Neither step: the marching-cubes triangles as they are.
    static ShapeLimits none() {
        ShapeLimits s;
        s.relax.sweeps = 0;
        s.flips.max_sweeps = 0;
        return s;
    }
    bool any() const { return relax.sweeps > 0 || flips.max_sweeps > 0; }
};

}  // namespace pqdc::adaptive_detail
