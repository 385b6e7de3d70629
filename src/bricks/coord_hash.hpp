// A hash of openvdb::Coord for unordered containers of voxel or leaf
// coordinates (OpenVDB's own Coord::hash keeps only a few low bits).
#pragma once

#include <openvdb/openvdb.h>

#include <cstddef>
#include <cstdint>

namespace pqdc::detail {

struct CoordHash {
    std::size_t operator()(const openvdb::Coord& c) const {
        return std::size_t(std::uint64_t(std::uint32_t(c.x())) * 0x9E3779B97F4A7C15ull ^
                           std::uint64_t(std::uint32_t(c.y())) * 0xC2B2AE3D27D4EB4Full ^
                           std::uint64_t(std::uint32_t(c.z())) * 0x165667B19E3779F9ull);
    }
};

}  // namespace pqdc::detail
