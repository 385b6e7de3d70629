// The Python names of what the library's messages call by their C++ field
// or command-line option, for exceptions and stats["warnings"].
#pragma once

#include <cstring>
#include <string>
#include <utility>

namespace pqdc::python {

/// The library's messages name its option fields and the CLI's options
/// (for C++ and command-line users); a Python caller reads its own keyword
/// arguments instead.
inline std::string in_python_names(std::string text) {
    static const std::pair<const char*, const char*> kNames[] = {
        {"AdaptiveOptions::base.", ""},
        {"AdaptiveOptions::max_error_voxels (--max-error)", "max_error"},
        {"AdaptiveOptions::max_cell_size_voxels (--max-cell-size)", "max_cell_size"},
        {"region.bbox (--bbox)", "bbox"},
        {"min_component_voxels (--min-component)", "min_component"},
        {"region.invert_mask (--invert-mask) needs a mask (--mask)", "invert_mask needs a mask (mask=)"},
        {"BrickOptions::brick_size", "brick_size"},
        {"BrickOptions::concurrent_runs", "brick_runs"},
        {"(choose one with --grid NAME)", "(choose one with grid=NAME)"},
        {"(options.region: a box or a mask)", "(bbox= or mask=)"},
        {"raise the memory limit", "raise memory_limit"},
        {"(--bbox, --mask)", "(bbox=, mask=)"},
        {"--min-component ", "min_component="},
        {"choose --isovalue inside it", "choose an isovalue inside it"},
        {"e.g. --isovalue ", "e.g. isovalue="},
        {"(--precision double)", "(precision=\"double\")"},
        {"write it with double precision (", "write it with double precision (precision=\"double\": "},
    };
    for (const auto& [cpp, python] : kNames)
        for (std::size_t at = text.find(cpp); at != std::string::npos; at = text.find(cpp, at + std::strlen(python)))
            text.replace(at, std::strlen(cpp), python);
    return text;
}

}  // namespace pqdc::python
