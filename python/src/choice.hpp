// A string option of the Python API to its C++ enum, or option_error
// listing the accepted names (one rule for every request).
#pragma once

#include <pqdc/exceptions.hpp>

#include <initializer_list>
#include <string>
#include <utility>

namespace pqdc::python {

template <class Enum>
Enum parse_choice(const std::string& option, const std::string& value,
                  std::initializer_list<std::pair<const char*, Enum>> choices) {
    std::string names;
    for (const auto& [name, e] : choices) {
        if (value == name) return e;
        names += std::string(names.empty() ? "'" : ", '") + name + "'";
    }
    throw option_error(option + " must be one of " + names + ", got '" + value + "'");
}

}  // namespace pqdc::python
