// Mesh reading and writing: format choice, the checks every format shares,
// and the helpers of the per-format files (obj.cpp, ply.cpp, off.cpp,
// stl.cpp).
//
// Writers format into a large in-memory buffer and hand it to write(2) in big
// chunks; numbers are printed with std::to_chars, the shortest decimal that
// parses back to the same bits at the chosen precision. Every write goes to a
// temporary file in the target's directory that is fsync'ed and renamed over
// the target only when complete.
//
// Readers load the whole file and parse it in place; errors name the file and
// the line (text) or byte offset (binary) where the data stops making sense.
// Every reader turns polygons into faces with add_polygon, so an n-gon becomes
// the same triangles whichever format brought it.
#include "pqdc/mesh_io.hpp"

#include "pqdc/exceptions.hpp"

#include "io/mesh_io_internal.hpp"
#include "memory/huge_pages.hpp"

#include <cerrno>
#include <cmath>
#include <limits>
#include <cstdio>
#include <cstring>
#include <string>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace pqdc {
namespace io {

void append_point_line(AtomicFileWriter& out, std::string_view head, const openvdb::Vec3d& p,
                       VertexPrecision precision) {
    // head + 3 * (24 chars max for a shortest double + space) + newline.
    const std::size_t line_max = head.size() + 3 * 26 + 2;
    char* const begin = out.reserve(line_max);
    char* cur = std::copy(head.begin(), head.end(), begin);
    for (int k = 0; k < 3; ++k) {
        if (k > 0 || !head.empty()) *cur++ = ' ';
        cur = format_coordinate(cur, begin + line_max, p[k], precision);
    }
    *cur++ = '\n';
    out.advance(static_cast<std::size_t>(cur - begin));
}

void check_float_range(const openvdb::Vec3d& p, std::uint64_t index, const std::string& target) {
    for (int k = 0; k < 3; ++k)
        if (std::abs(p[k]) > double(std::numeric_limits<float>::max())) {
            char value[32];
            std::snprintf(value, sizeof value, "%.17g", p[k]);
            throw input_error("cannot write '" + target + "': vertex " + std::to_string(index) +
                              " has the coordinate " + value +
                              ", beyond float's range; write it with double precision (PLY, OBJ or OFF)");
        }
}

[[noreturn]] void throw_bad_index(const std::string& target, const char* kind, std::uint64_t face,
                                  std::uint64_t index, std::uint64_t points) {
    throw input_error("cannot write '" + target + "': " + kind + " " + std::to_string(face) + " refers to vertex " +
                      std::to_string(index) + " but the mesh has only " + std::to_string(points) + " points");
}

std::errc read_number(std::string_view s, double& v) {
    const char* first = s.data();
    const char* const last = s.data() + s.size();
    if (first != last && *first == '+') ++first;
    const auto r = std::from_chars(first, last, v);
    if (r.ec != std::errc()) return r.ec;
    return r.ptr == last ? std::errc() : std::errc::invalid_argument;
}

namespace {

/// The first corner from which a fan of triangles covers the polygon
/// without folding over: every triangle faces the polygon's (Newell) normal.
/// Any corner of a convex polygon, a corner that sees the whole of a concave
/// star-shaped one; 0 when none does or a corner is not read yet (an OBJ
/// face naming a later vertex).
std::size_t fan_apex(const std::vector<openvdb::Vec3d>& points, const std::vector<unsigned>& idx) {
    const std::size_t n = idx.size();
    for (unsigned i : idx)
        if (i >= points.size()) return 0;
    openvdb::Vec3d normal(0.0);
    for (std::size_t k = 0; k < n; ++k) normal += points[idx[k]].cross(points[idx[(k + 1) % n]]);
    for (std::size_t apex = 0; apex < n; ++apex) {
        const openvdb::Vec3d& a = points[idx[apex]];
        bool folds = false;
        for (std::size_t k = 1; k + 1 < n && !folds; ++k) {
            const openvdb::Vec3d& b = points[idx[(apex + k) % n]];
            const openvdb::Vec3d& c = points[idx[(apex + k + 1) % n]];
            folds = !((b - a).cross(c - a).dot(normal) > 0);
        }
        if (!folds) return apex;
    }
    return 0;
}

}  // namespace

void add_polygon(Mesh& mesh, const std::vector<unsigned>& idx) {
    if (idx.size() == 3) {
        mesh.triangles.emplace_back(idx[0], idx[1], idx[2]);
    } else if (idx.size() == 4) {
        mesh.quads.emplace_back(idx[0], idx[1], idx[2], idx[3]);
    } else {
        const std::size_t n = idx.size(), apex = fan_apex(mesh.points, idx);
        for (std::size_t k = 1; k + 1 < n; ++k)
            mesh.triangles.emplace_back(idx[apex], idx[(apex + k) % n], idx[(apex + k + 1) % n]);
    }
}

namespace {

/// A mesh file opened for reading, closed on every path out.
class MeshFile {
public:
    explicit MeshFile(const std::string& path) : path_(path) {
        fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
        if (fd_ < 0) {
            const int err = errno;
            throw input_error("cannot read mesh '" + path + "': " + std::strerror(err));
        }
        struct stat st {};
        if (::fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode)) {
            ::close(fd_);
            throw input_error("cannot read mesh '" + path + "': not a regular file");
        }
        size_ = static_cast<std::uint64_t>(st.st_size);
    }
    ~MeshFile() { ::close(fd_); }
    MeshFile(const MeshFile&) = delete;
    MeshFile& operator=(const MeshFile&) = delete;

    /// The whole file, also what was appended since it was opened.
    std::string read_all() const {
        // One byte more than the size seen at open: a file that kept its
        // size fills the buffer short of its end, and is not copied into a
        // larger one (which every read did: a copy and a zero fill of 1.5x
        // the file).
        std::string data;
        detail::reserve_large(data, static_cast<std::size_t>(size_) + 1);
        data.resize(static_cast<std::size_t>(size_) + 1);
        std::size_t got = fill(data, 0);
        while (got == data.size()) {  // the file grew
            data.resize(data.size() + 65536 + data.size() / 2);
            got = fill(data, got);
        }
        data.resize(got);
        return data;
    }

    /// The file's first `bytes` bytes, or all of a shorter file.
    std::string read_head(std::size_t bytes) const {
        std::string data(static_cast<std::size_t>(std::min<std::uint64_t>(size_, bytes)), '\0');
        data.resize(fill(data, 0));
        return data;
    }

    /// The size when opened, bytes.
    std::uint64_t size() const { return size_; }

private:
    /// Reads into data[got...] until it is full or the file ends; the bytes held then.
    std::size_t fill(std::string& data, std::size_t got) const {
        while (got < data.size()) {
            const ssize_t r = ::read(fd_, &data[got], data.size() - got);
            if (r < 0) {
                if (errno == EINTR) continue;
                const int err = errno;
                throw input_error("cannot read mesh '" + path_ + "': " + std::strerror(err));
            }
            if (r == 0) break;
            got += static_cast<std::size_t>(r);
        }
        return got;
    }

    const std::string& path_;
    int fd_ = -1;
    std::uint64_t size_ = 0;
};

}  // namespace

std::string read_whole_file(const std::string& path) { return MeshFile(path).read_all(); }

}  // namespace io

namespace {

std::string lowercase(std::string s) {
    for (char& c : s) {
        if (c >= 'A' && c <= 'Z') c = static_cast<char>(c - 'A' + 'a');
    }
    return s;
}

// A mesh whose faces point outside its vertex array cannot be written in any
// format faithfully; say so instead of writing a file no reader accepts.
void check_mesh(const Mesh& mesh, const std::string& path, bool float_coordinates) {
    const std::size_t n = mesh.points.size();
    auto bad = [&](std::size_t face, const char* kind, unsigned index) { io::throw_bad_index(path, kind, face, index, n); };
    for (std::size_t f = 0; f < mesh.triangles.size(); ++f)
        for (int k = 0; k < 3; ++k)
            if (mesh.triangles[f][k] >= n) bad(f, "triangle", mesh.triangles[f][k]);
    for (std::size_t f = 0; f < mesh.quads.size(); ++f)
        for (int k = 0; k < 4; ++k)
            if (mesh.quads[f][k] >= n) bad(f, "quad", mesh.quads[f][k]);
    if (float_coordinates)
        for (std::size_t i = 0; i < n; ++i) io::check_float_range(mesh.points[i], i, path);
    if (!mesh.normals.empty() && mesh.normals.size() != n)
        throw input_error("cannot write '" + path + "': the mesh has " + std::to_string(mesh.normals.size()) +
                          " normals for " + std::to_string(n) + " points (give one per point or none)");
}

/// Roughly the file's size, for progress (exact for PLY and STL).
std::uint64_t expected_bytes(const Mesh& mesh, MeshFormat format, VertexPrecision precision) {
    const std::uint64_t real = precision == VertexPrecision::float32 ? 4 : 8;
    const std::uint64_t nv = mesh.points.size(), nt = mesh.triangles.size(), nq = mesh.quads.size();
    const std::uint64_t per_vertex = mesh.normals.empty() ? 3 : 6;
    switch (format) {
        case MeshFormat::ply: return 300 + nv * per_vertex * real + nt * 13 + nq * 17;
        case MeshFormat::stl: return 84 + 50 * (nt + 2 * nq);
        case MeshFormat::obj:
        case MeshFormat::off: return 64 + nv * per_vertex * (real == 4 ? 11 : 20) + (nt + nq) * 28;
    }
    return 1;
}

}  // namespace

MeshFormat mesh_format_from_name(const std::string& name) {
    const std::string n = lowercase(name);
    if (n == "obj") return MeshFormat::obj;
    if (n == "ply") return MeshFormat::ply;
    if (n == "off") return MeshFormat::off;
    if (n == "stl") return MeshFormat::stl;
    throw option_error("unknown mesh format '" + name + "'; use obj, ply, off or stl");
}

const char* mesh_format_name(MeshFormat format) {
    switch (format) {
        case MeshFormat::obj: return "OBJ";
        case MeshFormat::ply: return "PLY";
        case MeshFormat::off: return "OFF";
        case MeshFormat::stl: return "STL";
    }
    return "?";
}

bool format_holds_vertex_normals(MeshFormat format) {
    return format == MeshFormat::ply || format == MeshFormat::obj;
}

VertexPrecision stored_vertex_precision(MeshFormat format, VertexPrecision requested) {
    return format == MeshFormat::stl ? VertexPrecision::float32 : requested;
}

MeshFormat mesh_format_from_path(const std::string& path) {
    const std::size_t slash = path.find_last_of('/');
    const std::size_t dot = path.find_last_of('.');
    const std::string ext =
        (dot == std::string::npos || (slash != std::string::npos && dot < slash)) ? "" : lowercase(path.substr(dot));
    if (ext == ".obj") return MeshFormat::obj;
    if (ext == ".ply") return MeshFormat::ply;
    if (ext == ".off") return MeshFormat::off;
    if (ext == ".stl") return MeshFormat::stl;
    throw option_error("cannot tell the mesh format of '" + path +
                       "' from its extension; use .obj, .ply, .off or .stl");
}

void write_mesh(const Mesh& mesh, const std::string& path, const MeshWriteOptions& options) {
    if (path == "-" && !options.format)
        throw option_error("writing a mesh to standard output needs a format (obj, ply, off or stl)");
    const MeshFormat format = options.format ? *options.format : mesh_format_from_path(path);
    check_mesh(mesh, path == "-" ? "standard output" : path,
               stored_vertex_precision(format, options.precision) == VertexPrecision::float32);
    io::AtomicFileWriter out(path);
    if (options.progress) out.set_progress(options.progress, expected_bytes(mesh, format, options.precision));
    switch (format) {
        case MeshFormat::obj: io::write_obj(mesh, out, options); break;
        case MeshFormat::ply: io::write_ply(mesh, out, options); break;
        case MeshFormat::off: io::write_off(mesh, out, options); break;
        case MeshFormat::stl: io::write_stl(mesh, out); break;
    }
    out.commit();
    if (options.progress) options.progress(1.0);
}

std::optional<std::uint64_t> mesh_file_face_count(const std::string& path) {
    const MeshFormat format = mesh_format_from_path(path);
    if (format == MeshFormat::obj) return std::nullopt;  // no header
    // Headers are short; one with more comments than this gets no early count.
    constexpr std::size_t kHeadBytes = 65536;
    const io::MeshFile file(path);
    const std::string head = file.read_head(kHeadBytes);
    switch (format) {
        case MeshFormat::ply: return io::ply_face_count(head, file.size());
        case MeshFormat::off: return io::off_face_count(head, file.size());
        case MeshFormat::stl: return io::stl_face_count(head, file.size());
        case MeshFormat::obj: break;
    }
    return std::nullopt;
}

Mesh read_mesh(const std::string& path) {
    const MeshFormat format = mesh_format_from_path(path);
    const std::string data = io::read_whole_file(path);
    switch (format) {
        case MeshFormat::obj: return io::read_obj(path, data);
        case MeshFormat::ply: return io::read_ply(path, data);
        case MeshFormat::off: return io::read_off(path, data);
        case MeshFormat::stl: return io::read_stl(path, data);
    }
    return {};
}

}  // namespace pqdc
