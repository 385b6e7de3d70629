// Internal: the option checks' rule for enum fields, shared by every
// options struct (extraction, decimation).
#pragma once

#include "pqdc/exceptions.hpp"

#include <string>

namespace pqdc::detail {

/// An enum field must hold one of its named values, 0 to `last` (a cast
/// integer is a caller's bug, which would otherwise pick a branch silently):
/// option_error "FIELD holds N, not one of its enum's values".
template <class Enum>
void check_enum(const std::string& field, Enum value, Enum last) {
    const int v = static_cast<int>(value);
    if (v < 0 || v > static_cast<int>(last))
        throw option_error(field + " holds " + std::to_string(v) + ", not one of its enum's values");
}

}  // namespace pqdc::detail
