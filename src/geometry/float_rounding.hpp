// Doubles rounded to the floats a float file stores (internal): the
// positions the self-intersection checks of the untangle stage and of
// decimation test when the output is written in float.
//
// Why not simply double(float(v)): GCC 12.2 (Debian 12's compiler), at -O2
// and -O3, can vectorize the rounding of two neighbouring coordinates and
// fold the vector double -> float -> double pair into a copy. A function
// returning {double(float(p.x)), double(float(p.y)), double(float(p.z))}
// (decimation's first version) or Vec3d(Vec3f(p)) came back with x and y
// unrounded and only z rounded, so checks "at float" tested points the file
// did not hold. The volatile float is a barrier the vectorizer cannot fold
// (a store and a load per coordinate).
#pragma once

#include "pqdc/vec3.hpp"

#include <openvdb/Types.h>

namespace pqdc::detail {

/// v rounded to the nearest float (ties to even).
inline float nearest_float(double v) {
    const volatile float f = static_cast<float>(v);
    return f;
}

/// The same, as a double.
inline double rounded_to_float(double v) { return nearest_float(v); }

inline openvdb::Vec3d rounded_to_float(const openvdb::Vec3d& p) {
    return {rounded_to_float(p[0]), rounded_to_float(p[1]), rounded_to_float(p[2])};
}

inline vec3<double> rounded_to_float(const vec3<double>& p) {
    return {rounded_to_float(p.x), rounded_to_float(p.y), rounded_to_float(p.z)};
}

}  // namespace pqdc::detail
