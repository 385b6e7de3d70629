// Internal to src/io/: what the per-format readers and writers share (byte
// order, number formatting and parsing, polygon splitting, whole-file reads)
// and the entry points mesh_io.cpp dispatches to, one pair per format in the
// manner of pmp-library's io/ folder.
#pragma once

#include "pqdc/mesh.hpp"
#include "pqdc/mesh_io.hpp"

#include "io/atomic_file.hpp"

#include <algorithm>
#include <charconv>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>
#include <system_error>
#include <type_traits>
#include <vector>

namespace pqdc {
namespace io {

using detail::AtomicFileWriter;

inline bool host_is_little_endian() {
    const std::uint16_t probe = 1;
    unsigned char first;
    std::memcpy(&first, &probe, 1);
    return first == 1;
}

// Little-endian stores and loads independent of the host byte order.
template <typename T>
void store_le(char* dst, T value) {
    static_assert(std::is_trivially_copyable<T>::value, "");
    unsigned char bytes[sizeof(T)];
    std::memcpy(bytes, &value, sizeof(T));
    if (!host_is_little_endian()) std::reverse(bytes, bytes + sizeof(T));
    std::memcpy(dst, bytes, sizeof(T));
}

template <typename T>
T load_le(const char* src) {
    unsigned char bytes[sizeof(T)];
    std::memcpy(bytes, src, sizeof(T));
    if (!host_is_little_endian()) std::reverse(bytes, bytes + sizeof(T));
    T value;
    std::memcpy(&value, bytes, sizeof(T));
    return value;
}

/// Shortest round-trip decimal of v at the given precision (float32 prints
/// the float nearest to v with the fewest digits that read back to it).
inline char* format_coordinate(char* first, char* last, double v, vertex_precision precision) {
    if (precision == vertex_precision::float32) return std::to_chars(first, last, static_cast<float>(v)).ptr;
    return std::to_chars(first, last, v).ptr;
}

/// "HEAD x y z\n", or "x y z\n" for an empty head.
void append_point_line(AtomicFileWriter& out, std::string_view head, const openvdb::Vec3d& p,
                       vertex_precision precision);

bool is_space(char c);

/// The whole of a text token as a double: std::errc() on success,
/// result_out_of_range when it does not fit, invalid_argument for anything
/// else. A leading '+' is accepted, which from_chars alone rejects.
std::errc read_number(std::string_view s, double& v);

/// A polygon as a triangle, a quad, or a fan of triangles around idx[0].
void add_polygon(Mesh& mesh, const std::vector<unsigned>& idx);

/// The file's bytes; input_error naming the path when it cannot be read.
std::string read_whole_file(const std::string& path);

void write_obj(const Mesh& mesh, AtomicFileWriter& out, const MeshWriteOptions& options);
void write_ply(const Mesh& mesh, AtomicFileWriter& out, const MeshWriteOptions& options);
void write_off(const Mesh& mesh, AtomicFileWriter& out, const MeshWriteOptions& options);
void write_stl(const Mesh& mesh, AtomicFileWriter& out);

Mesh read_obj(const std::string& path, std::string_view data);
Mesh read_ply(const std::string& path, std::string_view data);
Mesh read_off(const std::string& path, std::string_view data);
Mesh read_stl(const std::string& path, std::string_view data);

}  // namespace io
}  // namespace pqdc
