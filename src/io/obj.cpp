// Wavefront OBJ: v, vn and f lines.
#include "io/mesh_io_internal.hpp"
#include "memory/huge_pages.hpp"

#include "pqdc/exceptions.hpp"

#include <cstring>
#include <string>
#include <string_view>
#include <vector>

namespace pqdc {
namespace io {
namespace {

/// Lines starting with "v ", "vn " and "f ": the sizes to reserve (a hint:
/// continuation lines and leading blanks are not counted). One memchr pass,
/// cheap beside parsing; growing the arrays instead copied each of them
/// about twice, through fresh 4 KiB pages (memory/huge_pages.hpp).
struct LineCounts {
    std::size_t points = 0, normals = 0, faces = 0;
};

LineCounts count_lines(std::string_view data) {
    LineCounts n;
    for (std::size_t pos = 0; pos < data.size();) {
        const std::string_view head = data.substr(pos, 3);
        if (head.size() >= 2 && head[0] == 'v' && head[1] == ' ') ++n.points;
        else if (head == "vn ") ++n.normals;
        else if (head.size() >= 2 && head[0] == 'f' && head[1] == ' ') ++n.faces;
        const void* end = std::memchr(data.data() + pos, '\n', data.size() - pos);
        if (!end) break;
        pos = std::size_t(static_cast<const char*>(end) - data.data()) + 1;
    }
    return n;
}

class ObjParser {
public:
    ObjParser(const std::string& path, std::string_view data) : path_(path), data_(data) {}

    Mesh parse() {
        Mesh mesh;
        std::vector<openvdb::Vec3d> normals;
        std::vector<unsigned> face;
        const LineCounts expected = count_lines(data_);
        detail::reserve_large(mesh.points, expected.points);
        detail::reserve_large(normals, expected.normals);
        // Triangles or quads, whichever the file has: pages never touched cost nothing.
        detail::reserve_large(mesh.triangles, expected.faces);
        detail::reserve_large(mesh.quads, expected.faces);
        std::size_t pos = 0;
        while (pos < data_.size()) {
            ++line_;
            std::size_t end = data_.find('\n', pos);
            if (end == std::string_view::npos) end = data_.size();
            std::string_view line = data_.substr(pos, end - pos);
            pos = end + 1;
            // Continuation lines ("\" at the end) are rare; join them.
            std::string joined;
            while (!line.empty() && (line.back() == '\\' || (line.back() == '\r' && line.size() >= 2 &&
                                                             line[line.size() - 2] == '\\'))) {
                joined.append(line.substr(0, line.find_last_of('\\')));
                joined.push_back(' ');
                if (pos >= data_.size()) break;
                std::size_t e2 = data_.find('\n', pos);
                if (e2 == std::string_view::npos) e2 = data_.size();
                line = data_.substr(pos, e2 - pos);
                pos = e2 + 1;
                ++line_;
            }
            if (!joined.empty()) {
                joined.append(line);
                line = joined;
            }
            cur_ = line;
            skip_space();
            if (cur_.empty() || cur_.front() == '#') continue;
            const std::string_view keyword = token();
            if (keyword == "v") {
                openvdb::Vec3d p;
                for (int k = 0; k < 3; ++k) p[k] = number();
                // Extra values (w, or per-vertex colors some tools add) are ignored.
                mesh.points.push_back(p);
            } else if (keyword == "vn") {
                openvdb::Vec3d n;
                for (int k = 0; k < 3; ++k) n[k] = number();
                normals.push_back(n);
            } else if (keyword == "f") {
                face.clear();
                skip_space();
                while (!cur_.empty()) {
                    const std::string_view t = token();
                    face.push_back(face_index(t, mesh.points.size()));
                    note_normal(t, face.back(), normals.size());
                    skip_space();
                }
                if (face.size() < 3) fail("face has " + std::to_string(face.size()) + " vertices, needs at least 3");
                add_polygon(mesh, face);
            }
            // vt, g, o, s, l, usemtl, mtllib...: not geometry pqdc keeps.
        }
        mesh.normals = vertex_normals(normals, mesh.points.size());
        return mesh;
    }

private:
    [[noreturn]] void fail(const std::string& what) const {
        throw input_error("cannot read OBJ '" + path_ + "' line " + std::to_string(line_) + ": " + what);
    }

    void skip_space() {
        std::size_t i = 0;
        while (i < cur_.size() && is_space(cur_[i])) ++i;
        cur_.remove_prefix(i);
    }

    std::string_view token() {
        skip_space();
        std::size_t i = 0;
        while (i < cur_.size() && !is_space(cur_[i])) ++i;
        std::string_view t = cur_.substr(0, i);
        cur_.remove_prefix(i);
        return t;
    }

    double number() {
        const std::string_view t = token();
        if (t.empty()) fail("vertex has fewer than 3 coordinates");
        double v = 0.0;
        const std::errc ec = read_number(t, v);
        if (ec == std::errc::result_out_of_range) fail("coordinate '" + std::string(t) + "' is out of range");
        if (ec != std::errc()) fail("'" + std::string(t) + "' is not a number");
        return v;
    }

    /// The vn lines as per-vertex normals: by position, one to one, when no
    /// face corner names a normal (pqdc writes "a//a", others "a"); else
    /// through the corners' "a//c" where every corner names a vn line and
    /// each vertex one only (vertices no face uses take theirs by position
    /// when the counts pair up); none otherwise (per-corner normals).
    std::vector<openvdb::Vec3d> vertex_normals(std::vector<openvdb::Vec3d>& normals, std::size_t points) const {
        const bool pair_up = !normals.empty() && normals.size() == points;
        if (!corner_with_normal_) return pair_up ? std::move(normals) : std::vector<openvdb::Vec3d>{};
        if (corner_without_normal_ || not_per_vertex_) return {};
        std::vector<openvdb::Vec3d> out(points);
        for (std::size_t v = 0; v < points; ++v) {
            const long long n = v < normal_of_.size() ? normal_of_[v] : -1;
            if (n >= 0) out[v] = normals[std::size_t(n)];
            else if (pair_up) out[v] = normals[v];
            else return {};
        }
        return out;
    }

    /// Records the normal corner token `t` (at vertex v) names, if any;
    /// `defined`: the vn lines read so far (negative indices count back).
    void note_normal(std::string_view t, unsigned v, std::size_t defined) {
        const std::size_t first = t.find('/');
        const std::size_t second = first == std::string_view::npos ? first : t.find('/', first + 1);
        if (second == std::string_view::npos || second + 1 >= t.size()) {
            corner_without_normal_ = true;
            return;
        }
        corner_with_normal_ = true;
        const std::string_view c = t.substr(second + 1);
        long long i = 0;
        const auto r = std::from_chars(c.data(), c.data() + c.size(), i);
        const long long n = i > 0 ? i - 1 : static_cast<long long>(defined) + i;
        // A reference to no vn line: the positions are still good; the
        // normals are not trusted (dropped, as per-corner ones are).
        const bool names_a_line = r.ec == std::errc() && r.ptr == c.data() + c.size() && i != 0 && n >= 0 &&
                                  n < static_cast<long long>(defined);
        if (normal_of_.size() <= v) normal_of_.resize(std::size_t(v) + 1, -1);
        if (!names_a_line || (normal_of_[v] >= 0 && normal_of_[v] != n)) not_per_vertex_ = true;
        normal_of_[v] = n;
    }

    unsigned face_index(std::string_view t, std::size_t vertex_count) {
        // "a", "a/b", "a/b/c", "a//c": the position index (note_normal reads c).
        const std::string_view head = t.substr(0, t.find('/'));
        long long i = 0;
        const auto r = std::from_chars(head.data(), head.data() + head.size(), i);
        if (head.empty() || r.ec != std::errc() || r.ptr != head.data() + head.size())
            fail("face index '" + std::string(t) + "' is not an integer");
        long long resolved = i > 0 ? i - 1 : static_cast<long long>(vertex_count) + i;  // negative: relative
        if (i == 0 || resolved < 0 || resolved >= static_cast<long long>(vertex_count))
            fail("face index " + std::to_string(i) + " does not name one of the " + std::to_string(vertex_count) +
                 " vertices defined so far");
        return static_cast<unsigned>(resolved);
    }

    const std::string& path_;
    std::string_view data_;
    std::string_view cur_;
    std::size_t line_ = 0;
    std::vector<long long> normal_of_;    ///< per vertex: the vn its corners name (-1: none)
    bool corner_with_normal_ = false;     ///< a corner names a normal ("a//c", "a/b/c")
    bool corner_without_normal_ = false;  ///< a corner names none ("a", "a/b")
    bool not_per_vertex_ = false;         ///< a vertex names two, or a name is no vn line
};

// "f a b c\n" (or "f a//a b//b c//c\n" with normals), indices from 1.
void append_face_line(AtomicFileWriter& out, const unsigned* idx, int n, bool with_normals) {
    constexpr std::size_t kFaceMax = 2 + 4 * (2 * 11 + 3) + 2;
    char* const begin = out.reserve(kFaceMax);
    char* cur = begin;
    *cur++ = 'f';
    for (int k = 0; k < n; ++k) {
        *cur++ = ' ';
        const std::uint64_t i = static_cast<std::uint64_t>(idx[k]) + 1;
        cur = std::to_chars(cur, begin + kFaceMax, i).ptr;
        if (with_normals) {
            *cur++ = '/';
            *cur++ = '/';
            cur = std::to_chars(cur, begin + kFaceMax, i).ptr;
        }
    }
    *cur++ = '\n';
    out.advance(static_cast<std::size_t>(cur - begin));
}

}  // namespace

std::string obj_header(const MeshCounts& counts) {
    return "# pqdc mesh: " + std::to_string(counts.points) + " vertices, " + std::to_string(counts.triangles) +
           " triangles, " + std::to_string(counts.quads) + " quads\n";
}

void obj_points(const openvdb::Vec3d* p, std::size_t count, std::string_view head, VertexPrecision precision,
                AtomicFileWriter& out) {
    for (std::size_t i = 0; i < count; ++i) append_point_line(out, head, p[i], precision);
}

void obj_faces(const unsigned* idx, std::size_t count, int arity, bool normals, AtomicFileWriter& out) {
    for (std::size_t f = 0; f < count; ++f, idx += arity) append_face_line(out, idx, arity, normals);
}

void write_obj(const Mesh& mesh, AtomicFileWriter& out, const MeshWriteOptions& options) {
    const MeshCounts counts{mesh.points.size(), mesh.triangles.size(), mesh.quads.size(), !mesh.normals.empty()};
    out.append(obj_header(counts));
    obj_points(mesh.points.data(), mesh.points.size(), "v", options.precision, out);
    obj_points(mesh.normals.data(), mesh.normals.size(), "vn", options.precision, out);
    obj_faces(triangle_indices(mesh), mesh.triangles.size(), 3, counts.normals, out);
    obj_faces(quad_indices(mesh), mesh.quads.size(), 4, counts.normals, out);
}

Mesh read_obj(const std::string& path, std::string_view data) { return ObjParser(path, data).parse(); }

}  // namespace io
}  // namespace pqdc
