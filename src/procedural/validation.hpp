// Parameter checks of the procedural fields and their sampling: option_error
// naming the field, the parameter and its valid range.
#pragma once

#include "pqdc/exceptions.hpp"

#include <openvdb/openvdb.h>

#include <cmath>
#include <sstream>
#include <string>

namespace pqdc::procedural_detail {

using openvdb::Vec3d;

// ------------------------------------------------------------ validation

inline std::string format_number(double v)
{
    std::ostringstream s;
    s.precision(17);
    s << v;
    return s.str();
}

inline std::string format_vec(const Vec3d& v)
{
    return "(" + format_number(v[0]) + ", " + format_number(v[1]) + ", " + format_number(v[2]) + ")";
}

inline void require(bool ok, const std::string& field, const std::string& param, const std::string& range,
             const std::string& got)
{
    if (!ok) {
        throw option_error(field + ": " + param + " must be " + range + " (got " + got + ")");
    }
}

inline bool finite(const Vec3d& v)
{
    return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
}


}  // namespace pqdc::procedural_detail
