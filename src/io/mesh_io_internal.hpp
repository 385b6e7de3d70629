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
#include <optional>
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
inline char* format_coordinate(char* first, char* last, double v, VertexPrecision precision) {
    if (precision == VertexPrecision::float32) return std::to_chars(first, last, static_cast<float>(v)).ptr;
    return std::to_chars(first, last, v).ptr;
}

/// "HEAD x y z\n", or "x y z\n" for an empty head.
void append_point_line(AtomicFileWriter& out, std::string_view head, const openvdb::Vec3d& p,
                       VertexPrecision precision);

/// Throws input_error (naming the target and the vertex) when a coordinate
/// of p does not fit in a float.
void check_float_range(const openvdb::Vec3d& p, std::uint64_t index, const std::string& target);

/// Throws input_error: `kind` ("triangle", "quad") `face` refers to `index`
/// but the mesh has `points` points.
[[noreturn]] void throw_bad_index(const std::string& target, const char* kind, std::uint64_t face,
                                  std::uint64_t index, std::uint64_t points);

/// Blanks within a line (not the line break).
inline bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v'; }

/// The whole of a text token as a double: std::errc() on success,
/// result_out_of_range when it does not fit, invalid_argument for anything
/// else. A leading '+' is accepted, which from_chars alone rejects.
std::errc read_number(std::string_view s, double& v);

/// A polygon as a triangle, a quad, or a fan of triangles around idx[0].
void add_polygon(Mesh& mesh, const std::vector<unsigned>& idx);

/// The file's bytes; input_error naming the path when it cannot be read.
std::string read_whole_file(const std::string& path);

/// What a file's header states about the mesh.
struct MeshCounts {
    std::uint64_t points = 0, triangles = 0, quads = 0;
    bool normals = false;
};

// Each format as its sections, in file order, so that write_mesh (one Mesh)
// and MeshStreamWriter (a mesh arriving in pieces, sections kept in scratch
// files) give the same bytes. `idx` holds `count` faces of `arity` (3 or 4)
// indices each, contiguous. Headers throw input_error naming `target` when
// the counts do not fit the format.
//   OBJ  header, v lines, vn lines, triangle f lines, quad f lines
//   PLY  header, vertex records (point, then normal), triangles, quads
//   OFF  header, point lines, triangle lines, quad lines
//   STL  header, facets of the triangles, facets of the quads (two each)
std::string obj_header(const MeshCounts& counts);
void obj_points(const openvdb::Vec3d* p, std::size_t count, std::string_view head, VertexPrecision precision,
                AtomicFileWriter& out);
void obj_faces(const unsigned* idx, std::size_t count, int arity, bool normals, AtomicFileWriter& out);
std::string ply_header(const MeshCounts& counts, VertexPrecision precision, const std::string& target);
/// `n` is null or holds one normal per point.
void ply_vertices(const openvdb::Vec3d* p, const openvdb::Vec3d* n, std::size_t count, VertexPrecision precision,
                  AtomicFileWriter& out);
void ply_faces(const unsigned* idx, std::size_t count, int arity, AtomicFileWriter& out);
std::string off_header(const MeshCounts& counts);
void off_points(const openvdb::Vec3d* p, std::size_t count, VertexPrecision precision, AtomicFileWriter& out);
void off_faces(const unsigned* idx, std::size_t count, int arity, AtomicFileWriter& out);
std::string stl_header(const MeshCounts& counts, const std::string& target);
void stl_facets(const openvdb::Vec3d* points, const unsigned* idx, std::size_t count, int arity,
                AtomicFileWriter& out);

/// The faces of a mesh as `idx` arrays for the section writers.
inline const unsigned* triangle_indices(const Mesh& mesh) {
    return mesh.triangles.empty() ? nullptr : mesh.triangles.front().asPointer();
}
inline const unsigned* quad_indices(const Mesh& mesh) {
    return mesh.quads.empty() ? nullptr : mesh.quads.front().asPointer();
}

void write_obj(const Mesh& mesh, AtomicFileWriter& out, const MeshWriteOptions& options);
void write_ply(const Mesh& mesh, AtomicFileWriter& out, const MeshWriteOptions& options);
void write_off(const Mesh& mesh, AtomicFileWriter& out, const MeshWriteOptions& options);
void write_stl(const Mesh& mesh, AtomicFileWriter& out);

/// What a header announces (see mesh_file_face_count): `head` is the file's
/// first bytes (the whole header, or nullopt), `file_size` its full size.
std::optional<std::uint64_t> ply_face_count(std::string_view head, std::uint64_t file_size);
std::optional<std::uint64_t> off_face_count(std::string_view head, std::uint64_t file_size);
std::optional<std::uint64_t> stl_face_count(std::string_view head, std::uint64_t file_size);

Mesh read_obj(const std::string& path, std::string_view data);
Mesh read_ply(const std::string& path, std::string_view data);
Mesh read_off(const std::string& path, std::string_view data);
Mesh read_stl(const std::string& path, std::string_view data);

}  // namespace io
}  // namespace pqdc
