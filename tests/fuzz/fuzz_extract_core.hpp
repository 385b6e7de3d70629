// The libFuzzer target's body, also replayed over tests/fuzz/corpus by the
// unit tests: bytes -> a small scalar grid and extraction options ->
// pqdc::extract -> every promise of extract.hpp (finite points, indices in
// range, edge-manifold, consistently oriented, vertices in crossed cells,
// closed and outward when the domain rule says the surface is closed).
//
// Input layout (missing bytes read as 0):
//   0  flags: bit0 double grid, bits1-3 sigma_n choice, bit4 quads,
//      bit5 unconstrained containment, bits6-7 interior (auto, below, above, auto)
//   1  bit0 fog-volume class; bits1-7 isovalue = (b >> 1) / 16 - 4
//   2-4 lattice size nx, ny, nz = 1 + b % 12
//   5  background value code
//   6  transform: < 128 identity; else uniform scale 10^(b % 11 - 4) (1e-4..1e6),
//      rotation and optional mirror from byte 7, origin far out when bit 6 is set
//   8  tile count (b % 4), then 3 bytes per tile: position, value code, active
//   then ceil(nx ny nz / 8) bytes of active bits (missing: active), then one
//   value code per voxel. Value codes: 0x80 NaN, 0x81 +Inf, 0x82 -Inf,
//   0x83/0x84 +-denormal, 0x85/0x86 +-huge, 0x87 -0.0, else int8 / 16.
#pragma once

#include "../robust_oracle.hpp"

#include "pqdc/exceptions.hpp"
#include "pqdc/extract.hpp"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>

namespace pqdc_fuzz {

class ByteReader {
public:
    ByteReader(const std::uint8_t* data, std::size_t size) : data_(data), size_(size) {}
    std::uint8_t next() { return pos_ < size_ ? data_[pos_++] : 0; }
    bool exhausted() const { return pos_ >= size_; }

private:
    const std::uint8_t* data_;
    std::size_t size_;
    std::size_t pos_ = 0;
};

template <class T>
T value_from_code(std::uint8_t c) {
    const T huge = sizeof(T) == 4 ? T(3e38) : T(1e308);
    const T denormal = sizeof(T) == 4 ? T(1e-41) : T(1e-310);
    switch (c) {
        case 0x80: return std::numeric_limits<T>::quiet_NaN();
        case 0x81: return std::numeric_limits<T>::infinity();
        case 0x82: return -std::numeric_limits<T>::infinity();
        case 0x83: return denormal;
        case 0x84: return -denormal;
        case 0x85: return huge;
        case 0x86: return -huge;
        case 0x87: return T(-0.0);
        default: return T(std::int8_t(c)) / T(16);
    }
}

/// Largest relative deviation of M^T M from s^2 I for the map's linear part.
inline double map_anisotropy(const openvdb::math::Transform& xf) {
    const openvdb::Mat3d m = xf.baseMap()->getAffineMap()->getMat4().getMat3();
    const openvdb::Mat3d mtm = m.transpose() * m;
    const double s2 = (mtm(0, 0) + mtm(1, 1) + mtm(2, 2)) / 3.0;
    double worst = 0;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) worst = std::max(worst, std::abs(mtm(i, j) - (i == j ? s2 : 0.0)) / s2);
    return worst;
}

template <class GridT>
std::string run_grid(ByteReader& in, std::uint8_t flags, std::uint8_t class_byte) {
    using T = typename GridT::ValueType;
    static const double sigmas[8] = {0.0, 1e-3, 0.05, 0.1, 0.5, 10.0, std::numeric_limits<double>::infinity(), 0.1};
    pqdc::ExtractOptions options;
    options.sigma_n = sigmas[(flags >> 1) & 7];
    options.faces = (flags & 16) ? pqdc::FaceType::quads : pqdc::FaceType::triangles;
    options.containment = (flags & 32) ? pqdc::Containment::unconstrained : pqdc::Containment::clamp_to_cell;
    const int interior = flags >> 6;
    options.interior = interior == 1   ? pqdc::Interior::below_isovalue
                       : interior == 2 ? pqdc::Interior::above_isovalue
                                       : pqdc::Interior::automatic;
    options.isovalue = double(class_byte >> 1) / 16.0 - 4.0;
    options.memory_limit_bytes = std::size_t(512) << 20;

    const int nx = 1 + in.next() % 12, ny = 1 + in.next() % 12, nz = 1 + in.next() % 12;
    auto grid = GridT::create(value_from_code<T>(in.next()));
    if (class_byte & 1) grid->setGridClass(openvdb::GRID_FOG_VOLUME);
    const std::uint8_t xf_code = in.next(), rot_code = in.next();
    if (xf_code >= 128) {
        const double s = std::pow(10.0, double(xf_code % 11) - 4.0);
        openvdb::Mat4d m = openvdb::Mat4d::identity();
        m.setToRotation(openvdb::Vec3d(1.0, double(rot_code & 7) - 3.0, 2.0).unit(), double(rot_code) * 0.05);
        m.preScale(openvdb::Vec3d(s, s, (rot_code & 128) ? -s : s));
        if (xf_code & 64) m.setTranslation(openvdb::Vec3d(1e6, -2e6, 3e5));
        try {
            grid->setTransform(openvdb::math::Transform::createLinearTransform(m));
        } catch (const openvdb::Exception&) {
            return "";  // OpenVDB itself refuses this map; nothing of pqdc's to test
        }
    }
    const int tiles = in.next() % 4;
    for (int i = 0; i < tiles; ++i) {
        const std::uint8_t pos = in.next(), code = in.next(), active = in.next();
        const openvdb::Coord o(8 * ((pos & 3) % 3) - 8, 8 * (((pos >> 2) & 3) % 3) - 8, 8 * (((pos >> 4) & 3) % 3) - 8);
        grid->tree().fill(openvdb::CoordBBox(o, o + openvdb::Coord(7)), value_from_code<T>(code), active & 1);
    }
    const int count = nx * ny * nz;
    std::vector<std::uint8_t> active_bits((count + 7) / 8);
    bool bits_present = !in.exhausted();
    for (auto& b : active_bits) b = bits_present ? in.next() : 0xff;
    auto acc = grid->getAccessor();
    for (int i = 0; i < count; ++i) {
        const openvdb::Coord p(i % nx, (i / nx) % ny, i / (nx * ny));
        const T v = value_from_code<T>(in.next());
        if (active_bits[i / 8] & (1u << (i % 8))) acc.setValue(p, v);
        else acc.setValueOff(p, v);
    }

    pqdc::ExtractStats stats;
    pqdc::Mesh mesh;
    try {
        mesh = pqdc::extract(*grid, options, &stats);
    } catch (const std::exception& e) {
        return std::string("extract threw: ") + e.what();
    }
    const std::string uniform = pqdc_test::check_mesh_promises(*grid, options, mesh, stats);
    // The same input through the adaptive extractor, merging freely.
    pqdc::AdaptiveOptions adaptive;
    adaptive.base = options;
    adaptive.max_error_voxels = 0.5;
    adaptive.max_cell_size_voxels = 8;
    pqdc::AdaptiveStats adaptive_stats;
    try {
        mesh = pqdc::extract_adaptive(*grid, adaptive, &adaptive_stats);
    } catch (const std::exception& e) {
        return uniform + "extract_adaptive threw: " + e.what();
    }
    return uniform + pqdc_test::check_adaptive_promises(*grid, options, mesh, adaptive_stats);
}

/// "" when every promise holds, otherwise what broke.
inline std::string check_one_input(const std::uint8_t* data, std::size_t size) {
    openvdb::initialize();
    ByteReader in(data, size);
    const std::uint8_t flags = in.next(), class_byte = in.next();
    return (flags & 1) ? run_grid<openvdb::DoubleGrid>(in, flags, class_byte)
                       : run_grid<openvdb::FloatGrid>(in, flags, class_byte);
}

}  // namespace pqdc_fuzz
