// Mesh reading and writing (OBJ, PLY, OFF, STL).
//
// Writers format into a large in-memory buffer and hand it to write(2) in big
// chunks; doubles are printed with std::to_chars, the shortest decimal that
// parses back to the same bits, so OBJ and OFF round trips are exact. Every write
// goes to a temporary file in the target's directory that is fsync'ed and
// renamed over the target only when complete.
//
// Readers load the whole file and parse it in place; errors name the file and
// the line (text) or byte offset (binary) where the data stops making sense.
// Every reader turns polygons into faces with add_polygon, so an n-gon becomes
// the same triangles whichever format brought it.
#include "pqdc/mesh_io.hpp"

#include "pqdc/exceptions.hpp"

#include "atomic_file.hpp"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <string_view>
#include <vector>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace pqdc {

namespace {

using detail::AtomicFileWriter;

std::string lowercase(std::string s) {
    for (char& c : s) {
        if (c >= 'A' && c <= 'Z') c = static_cast<char>(c - 'A' + 'a');
    }
    return s;
}

std::string errno_text(int err) { return std::strerror(err); }

// Little-endian stores independent of the host byte order.
template <typename T>
void store_le(char* dst, T value) {
    static_assert(std::is_trivially_copyable<T>::value, "");
    unsigned char bytes[sizeof(T)];
    std::memcpy(bytes, &value, sizeof(T));
    const std::uint16_t probe = 1;
    unsigned char first;
    std::memcpy(&first, &probe, 1);
    if (first != 1) std::reverse(bytes, bytes + sizeof(T));
    std::memcpy(dst, bytes, sizeof(T));
}

template <typename T>
T load_le(const char* src) {
    unsigned char bytes[sizeof(T)];
    std::memcpy(bytes, src, sizeof(T));
    const std::uint16_t probe = 1;
    unsigned char first;
    std::memcpy(&first, &probe, 1);
    if (first != 1) std::reverse(bytes, bytes + sizeof(T));
    T value;
    std::memcpy(&value, bytes, sizeof(T));
    return value;
}

// A mesh whose faces point outside its vertex array cannot be written in any
// format faithfully; say so instead of writing a file no reader accepts.
void check_face_indices(const Mesh& mesh, const std::string& path) {
    const std::size_t n = mesh.points.size();
    auto bad = [&](std::size_t face, const char* kind, unsigned index) {
        throw input_error("cannot write '" + path + "': " + kind + " " + std::to_string(face) +
                          " refers to vertex " + std::to_string(index) + " but the mesh has only " +
                          std::to_string(n) + " points");
    };
    for (std::size_t f = 0; f < mesh.triangles.size(); ++f)
        for (int k = 0; k < 3; ++k)
            if (mesh.triangles[f][k] >= n) bad(f, "triangle", mesh.triangles[f][k]);
    for (std::size_t f = 0; f < mesh.quads.size(); ++f)
        for (int k = 0; k < 4; ++k)
            if (mesh.quads[f][k] >= n) bad(f, "quad", mesh.quads[f][k]);
}

// "HEAD x y z\n", or "x y z\n" for an empty head.
void append_point_line(AtomicFileWriter& out, std::string_view head, const openvdb::Vec3d& p) {
    // head + 3 * (24 chars max for a shortest double + space) + newline.
    const std::size_t line_max = head.size() + 3 * 26 + 2;
    char* const begin = out.reserve(line_max);
    char* cur = std::copy(head.begin(), head.end(), begin);
    for (int k = 0; k < 3; ++k) {
        if (k > 0 || !head.empty()) *cur++ = ' ';
        cur = std::to_chars(cur, begin + line_max, p[k]).ptr;
    }
    *cur++ = '\n';
    out.advance(static_cast<std::size_t>(cur - begin));
}

// "HEAD i0 i1 ...\n" with every index plus base (OBJ counts from 1).
void append_face_line(AtomicFileWriter& out, char head, const unsigned* idx, int n, std::uint64_t base) {
    constexpr std::size_t kFaceMax = 2 + 4 * 12 + 2;
    char* const begin = out.reserve(kFaceMax);
    char* cur = begin;
    *cur++ = head;
    for (int k = 0; k < n; ++k) {
        *cur++ = ' ';
        cur = std::to_chars(cur, begin + kFaceMax, static_cast<std::uint64_t>(idx[k]) + base).ptr;
    }
    *cur++ = '\n';
    out.advance(static_cast<std::size_t>(cur - begin));
}

void write_obj(const Mesh& mesh, AtomicFileWriter& out) {
    out.append("# pqdc mesh: " + std::to_string(mesh.points.size()) + " vertices, " +
               std::to_string(mesh.triangles.size()) + " triangles, " + std::to_string(mesh.quads.size()) +
               " quads\n");
    for (const auto& p : mesh.points) append_point_line(out, "v", p);
    for (const auto& t : mesh.triangles) append_face_line(out, 'f', t.asPointer(), 3, 1);
    for (const auto& q : mesh.quads) append_face_line(out, 'f', q.asPointer(), 4, 1);
}

// No comment line: several small OFF readers in the wild (bench_extract's
// among them) expect the counts right after "OFF".
void write_off(const Mesh& mesh, AtomicFileWriter& out) {
    out.append("OFF\n" + std::to_string(mesh.points.size()) + " " + std::to_string(mesh.face_count()) + " 0\n");
    for (const auto& p : mesh.points) append_point_line(out, "", p);
    for (const auto& t : mesh.triangles) append_face_line(out, '3', t.asPointer(), 3, 0);
    for (const auto& q : mesh.quads) append_face_line(out, '4', q.asPointer(), 4, 0);
}

void write_ply(const Mesh& mesh, AtomicFileWriter& out, const std::string& path) {
    constexpr std::size_t kMaxIndex = static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max());
    if (mesh.points.size() > kMaxIndex) {
        throw input_error("cannot write '" + path + "': " + std::to_string(mesh.points.size()) +
                          " points exceed PLY's int32 vertex indices; write OBJ instead");
    }
    std::string header;
    header += "ply\nformat binary_little_endian 1.0\ncomment written by pqdc\n";
    header += "element vertex " + std::to_string(mesh.points.size()) + "\n";
    header += "property double x\nproperty double y\nproperty double z\n";
    header += "element face " + std::to_string(mesh.face_count()) + "\n";
    header += "property list uchar int vertex_indices\nend_header\n";
    out.append(header);
    for (const auto& p : mesh.points) {
        char* dst = out.reserve(24);
        store_le(dst, p[0]);
        store_le(dst + 8, p[1]);
        store_le(dst + 16, p[2]);
    }
    for (const auto& t : mesh.triangles) {
        char* dst = out.reserve(13);
        dst[0] = 3;
        for (int k = 0; k < 3; ++k) store_le(dst + 1 + 4 * k, static_cast<std::int32_t>(t[k]));
    }
    for (const auto& q : mesh.quads) {
        char* dst = out.reserve(17);
        dst[0] = 4;
        for (int k = 0; k < 4; ++k) store_le(dst + 1 + 4 * k, static_cast<std::int32_t>(q[k]));
    }
}

void write_stl(const Mesh& mesh, AtomicFileWriter& out, const std::string& path) {
    const std::size_t triangle_count = mesh.triangles.size() + 2 * mesh.quads.size();
    if (triangle_count > std::numeric_limits<std::uint32_t>::max()) {
        throw input_error("cannot write '" + path + "': " + std::to_string(triangle_count) +
                          " triangles exceed binary STL's 32-bit count; write PLY or OBJ instead");
    }
    char header[84] = {};
    const char title[] = "binary STL written by pqdc";
    std::memcpy(header, title, sizeof title - 1);
    store_le(header + 80, static_cast<std::uint32_t>(triangle_count));
    out.append(header, sizeof header);
    auto emit = [&](unsigned a, unsigned b, unsigned c) {
        const openvdb::Vec3d& pa = mesh.points[a];
        const openvdb::Vec3d& pb = mesh.points[b];
        const openvdb::Vec3d& pc = mesh.points[c];
        openvdb::Vec3d n = (pb - pa).cross(pc - pa);
        const double len = n.length();
        n = len > 0.0 ? n / len : openvdb::Vec3d(0.0);
        char* dst = out.reserve(50);
        const openvdb::Vec3d* vs[4] = {&n, &pa, &pb, &pc};
        for (int v = 0; v < 4; ++v)
            for (int k = 0; k < 3; ++k) store_le(dst + 12 * v + 4 * k, static_cast<float>((*vs[v])[k]));
        store_le(dst + 48, std::uint16_t(0));
    };
    for (const auto& t : mesh.triangles) emit(t[0], t[1], t[2]);
    for (const auto& q : mesh.quads) {
        emit(q[0], q[1], q[2]);
        emit(q[0], q[2], q[3]);
    }
}

// --------------------------------------------------------------------------
// Reading.

std::string read_whole_file(const std::string& path) {
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) {
        const int err = errno;
        throw input_error("cannot read mesh '" + path + "': " + errno_text(err));
    }
    struct stat st {};
    if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
        ::close(fd);
        throw input_error("cannot read mesh '" + path + "': not a regular file");
    }
    std::string data;
    data.resize(static_cast<std::size_t>(st.st_size));
    std::size_t got = 0;
    for (;;) {
        if (got == data.size()) data.resize(data.size() + 65536 + data.size() / 2);  // file grew
        const ssize_t r = ::read(fd, &data[got], data.size() - got);
        if (r < 0) {
            if (errno == EINTR) continue;
            const int err = errno;
            ::close(fd);
            throw input_error("cannot read mesh '" + path + "': " + errno_text(err));
        }
        if (r == 0) break;
        got += static_cast<std::size_t>(r);
    }
    ::close(fd);
    data.resize(got);
    return data;
}

// Adds a polygon as a triangle, a quad, or (for larger polygons) a fan of
// triangles, so n-gons from other tools still load.
void add_polygon(Mesh& mesh, const std::vector<unsigned>& idx) {
    if (idx.size() == 3) {
        mesh.triangles.emplace_back(idx[0], idx[1], idx[2]);
    } else if (idx.size() == 4) {
        mesh.quads.emplace_back(idx[0], idx[1], idx[2], idx[3]);
    } else {
        for (std::size_t k = 1; k + 1 < idx.size(); ++k) mesh.triangles.emplace_back(idx[0], idx[k], idx[k + 1]);
    }
}

bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v'; }

/// The whole of a text token as a double, as every text reader takes its
/// numbers: std::errc() on success, result_out_of_range when it does not fit,
/// invalid_argument for anything else (empty, trailing characters). A leading
/// '+' is accepted, which from_chars alone rejects.
std::errc read_number(std::string_view s, double& v) {
    const char* first = s.data();
    const char* const last = s.data() + s.size();
    if (first != last && *first == '+') ++first;
    const auto r = std::from_chars(first, last, v);
    if (r.ec != std::errc()) return r.ec;
    return r.ptr == last ? std::errc() : std::errc::invalid_argument;
}

class ObjParser {
public:
    ObjParser(const std::string& path, std::string_view data) : path_(path), data_(data) {}

    Mesh parse() {
        Mesh mesh;
        std::vector<unsigned> face;
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
            } else if (keyword == "f") {
                face.clear();
                skip_space();
                while (!cur_.empty()) {
                    face.push_back(face_index(mesh.points.size()));
                    skip_space();
                }
                if (face.size() < 3) fail("face has " + std::to_string(face.size()) + " vertices, needs at least 3");
                add_polygon(mesh, face);
            }
            // vn, vt, g, o, s, l, usemtl, mtllib...: not geometry pqdc keeps.
        }
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

    unsigned face_index(std::size_t vertex_count) {
        const std::string_view t = token();
        // "a", "a/b", "a/b/c", "a//c": only the position index matters.
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
};

// ASCII OFF as Geomview and CGAL write it: whitespace-separated numbers that
// may break lines anywhere, except that a vertex's extra values (the ST, C and
// N header prefixes) and a face's color run to the end of the line they start
// on. Counts and indices are parsed as numbers and then required to be whole,
// so that "3.5" gets a message saying what is wrong with it.
class OffParser {
public:
    OffParser(const std::string& path, std::string_view data) : path_(path), data_(data) {}

    Mesh parse() {
        if (!advance())
            throw input_error("cannot read OFF '" + path_ + "': the file has no data (empty or only comments)");
        const std::string_view header = token_;
        if (header.size() < 3 || header.substr(header.size() - 3) != "OFF")
            fail("not an OFF file (first word '" + std::string(header) + "', expected OFF, COFF, NOFF...)");
        const std::string_view prefix = header.substr(0, header.size() - 3);
        if (prefix.find_first_of("4n") != std::string_view::npos)
            fail("'" + std::string(header) + "': only 3D OFF files are supported (no 4OFF/nOFF)");
        if (prefix.find_first_not_of("STCN") != std::string_view::npos)
            fail("not an OFF file (first word '" + std::string(header) + "')");
        const bool vertex_extras = !prefix.empty();

        next("the vertex count");
        if (token_ == "BINARY") fail("binary OFF is not supported; convert it to ASCII OFF first");
        const std::size_t nv = whole_number("the vertex count");
        const std::size_t nf = count("the face count");
        count("the edge count");

        Mesh mesh;
        // A corrupt count must not allocate gigabytes before the data runs
        // out: every vertex takes at least 6 characters, every face 8.
        mesh.points.reserve(std::min(nv, data_.size() / 6));
        mesh.triangles.reserve(std::min(nf, data_.size() / 8));
        for (std::size_t v = 0; v < nv; ++v) {
            openvdb::Vec3d p;
            p[0] = number("a vertex coordinate");
            const std::size_t vertex_line = token_line_;
            p[1] = number("a vertex coordinate");
            p[2] = number("a vertex coordinate");
            mesh.points.push_back(p);
            if (vertex_extras) skip_rest_of_line(vertex_line);
        }
        std::vector<unsigned> face;
        for (std::size_t f = 0; f < nf; ++f) {
            const std::size_t n = count("a face's vertex count");
            const std::size_t face_line = token_line_;
            if (n < 3) fail("face " + std::to_string(f) + " has " + std::to_string(n) + " vertices (need >= 3)");
            face.clear();  // grows as indices are read, so a huge n cannot allocate up front
            for (std::size_t k = 0; k < n; ++k) {
                const std::size_t i = count("a vertex index");
                if (i >= nv)
                    fail("face " + std::to_string(f) + " uses vertex " + std::to_string(i) + " but there are only " +
                         std::to_string(nv));
                face.push_back(static_cast<unsigned>(i));
            }
            skip_rest_of_line(face_line);
            add_polygon(mesh, face);
        }
        return mesh;  // anything after the last face is ignored
    }

private:
    [[noreturn]] void fail(const std::string& what) const { fail_at(token_line_, what); }

    [[noreturn]] void fail_at(std::size_t line, const std::string& what) const {
        throw input_error("cannot read OFF '" + path_ + "' line " + std::to_string(line) + ": " + what);
    }

    // Moves token_ to the next word, past white space, line breaks and '#'
    // comments; false at the end of the data.
    bool advance() {
        while (pos_ < data_.size()) {
            const char c = data_[pos_];
            if (c == '\n') {
                ++line_;
                ++pos_;
            } else if (is_space(c)) {
                ++pos_;
            } else if (c == '#') {
                pos_ = std::min(data_.find('\n', pos_), data_.size());
            } else {
                const std::size_t start = pos_;
                while (pos_ < data_.size() && data_[pos_] != '\n' && data_[pos_] != '#' && !is_space(data_[pos_]))
                    ++pos_;
                token_ = data_.substr(start, pos_ - start);
                token_line_ = line_;
                return true;
            }
        }
        return false;
    }

    void next(const char* what) {
        if (advance()) return;
        // The last line, not the empty one after a final line break.
        const bool final_break = !data_.empty() && data_.back() == '\n';
        fail_at(final_break ? line_ - 1 : line_, std::string("file ends before ") + what);
    }

    double number(const char* what) {
        next(what);
        return token_value(what);
    }

    double token_value(const char* what) const {
        double v = 0.0;
        if (read_number(token_, v) != std::errc() || !std::isfinite(v))
            fail(std::string("expected ") + what + ", found '" + std::string(token_) + "'");
        return v;
    }

    std::size_t count(const char* what) {
        next(what);
        return whole_number(what);
    }

    std::size_t whole_number(const char* what) const {
        const double v = token_value(what);
        if (v < 0 || v != std::floor(v) || v > 1e9)
            fail(std::string("expected ") + what + " (a whole number >= 0), found '" + std::string(token_) + "'");
        return static_cast<std::size_t>(v);
    }

    void skip_rest_of_line(std::size_t line) {
        if (line_ == line) pos_ = std::min(data_.find('\n', pos_), data_.size());
    }

    const std::string& path_;
    std::string_view data_;
    std::size_t pos_ = 0;
    std::size_t line_ = 1;
    std::string_view token_;
    std::size_t token_line_ = 1;
};

enum class ply_type { int8, uint8, int16, uint16, int32, uint32, float32, float64 };

bool parse_ply_type(std::string_view s, ply_type& t) {
    static const struct {
        const char* name;
        ply_type type;
    } names[] = {{"char", ply_type::int8},     {"int8", ply_type::int8},       {"uchar", ply_type::uint8},
                 {"uint8", ply_type::uint8},   {"short", ply_type::int16},     {"int16", ply_type::int16},
                 {"ushort", ply_type::uint16}, {"uint16", ply_type::uint16},   {"int", ply_type::int32},
                 {"int32", ply_type::int32},   {"uint", ply_type::uint32},     {"uint32", ply_type::uint32},
                 {"float", ply_type::float32}, {"float32", ply_type::float32}, {"double", ply_type::float64},
                 {"float64", ply_type::float64}};
    for (const auto& n : names) {
        if (s == n.name) {
            t = n.type;
            return true;
        }
    }
    return false;
}

std::size_t ply_size(ply_type t) {
    switch (t) {
        case ply_type::int8:
        case ply_type::uint8: return 1;
        case ply_type::int16:
        case ply_type::uint16: return 2;
        case ply_type::int32:
        case ply_type::uint32:
        case ply_type::float32: return 4;
        case ply_type::float64: return 8;
    }
    return 0;
}

bool ply_is_integer(ply_type t) { return t != ply_type::float32 && t != ply_type::float64; }

double ply_load_binary(ply_type t, const char* p) {
    switch (t) {
        case ply_type::int8: return static_cast<double>(static_cast<std::int8_t>(*p));
        case ply_type::uint8: return static_cast<double>(static_cast<std::uint8_t>(*p));
        case ply_type::int16: return load_le<std::int16_t>(p);
        case ply_type::uint16: return load_le<std::uint16_t>(p);
        case ply_type::int32: return load_le<std::int32_t>(p);
        case ply_type::uint32: return load_le<std::uint32_t>(p);
        case ply_type::float32: return static_cast<double>(load_le<float>(p));
        case ply_type::float64: return load_le<double>(p);
    }
    return 0.0;
}

struct PlyProperty {
    std::string name;
    bool is_list = false;
    ply_type count_type = ply_type::uint8;
    ply_type type = ply_type::float32;
};

struct PlyElement {
    std::string name;
    std::size_t count = 0;
    std::vector<PlyProperty> properties;
};

class PlyParser {
public:
    PlyParser(const std::string& path, std::string_view data) : path_(path), data_(data) {}

    Mesh parse() {
        parse_header();
        Mesh mesh;
        for (const PlyElement& e : elements_) {
            if (e.name == "vertex") {
                read_vertices(e, mesh);
            } else if (e.name == "face") {
                read_faces(e, mesh);
            } else {
                skip_element(e);
            }
        }
        for (std::size_t f = 0; f < mesh.triangles.size(); ++f)
            for (int k = 0; k < 3; ++k) check_index(mesh.triangles[f][k], mesh.points.size());
        for (std::size_t f = 0; f < mesh.quads.size(); ++f)
            for (int k = 0; k < 4; ++k) check_index(mesh.quads[f][k], mesh.points.size());
        return mesh;
    }

private:
    [[noreturn]] void fail(const std::string& what) const {
        std::string where;
        if (in_header_ || ascii_) {
            where = " line " + std::to_string(line_);
        } else {
            where = " byte " + std::to_string(pos_);
        }
        throw input_error("cannot read PLY '" + path_ + "'" + where + ": " + what);
    }

    void check_index(unsigned i, std::size_t n) const {
        if (i >= n) {
            throw input_error("cannot read PLY '" + path_ + "': face refers to vertex " + std::to_string(i) +
                              " but the file has only " + std::to_string(n) + " vertices");
        }
    }

    std::string_view next_line() {
        if (pos_ >= data_.size()) fail("file ends before the header/data is complete");
        std::size_t end = data_.find('\n', pos_);
        if (end == std::string_view::npos) end = data_.size();
        std::string_view line = data_.substr(pos_, end - pos_);
        pos_ = std::min(end + 1, data_.size());
        ++line_;
        if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
        return line;
    }

    static std::vector<std::string_view> split(std::string_view line) {
        std::vector<std::string_view> out;
        std::size_t i = 0;
        while (i < line.size()) {
            while (i < line.size() && is_space(line[i])) ++i;
            const std::size_t start = i;
            while (i < line.size() && !is_space(line[i])) ++i;
            if (i > start) out.push_back(line.substr(start, i - start));
        }
        return out;
    }

    void parse_header() {
        in_header_ = true;
        if (next_line() != "ply") fail("not a PLY file (first line must be 'ply')");
        bool have_format = false;
        for (;;) {
            const std::vector<std::string_view> w = split(next_line());
            if (w.empty()) continue;
            if (w[0] == "end_header") break;
            if (w[0] == "comment" || w[0] == "obj_info") continue;
            if (w[0] == "format") {
                if (w.size() < 2) fail("format line without a format");
                if (w[1] == "ascii") {
                    ascii_ = true;
                } else if (w[1] == "binary_little_endian") {
                    ascii_ = false;
                } else {
                    fail("format '" + std::string(w[1]) +
                         "' is not supported (ascii and binary_little_endian are); convert the file first");
                }
                have_format = true;
            } else if (w[0] == "element") {
                if (w.size() != 3) fail("element line must be 'element NAME COUNT'");
                PlyElement e;
                e.name = std::string(w[1]);
                unsigned long long count = 0;
                const auto r = std::from_chars(w[2].data(), w[2].data() + w[2].size(), count);
                if (r.ec != std::errc() || r.ptr != w[2].data() + w[2].size())
                    fail("element count '" + std::string(w[2]) + "' is not a non-negative integer");
                e.count = static_cast<std::size_t>(count);
                elements_.push_back(std::move(e));
            } else if (w[0] == "property") {
                if (elements_.empty()) fail("property before any element");
                PlyProperty p;
                if (w.size() == 5 && w[1] == "list") {
                    p.is_list = true;
                    if (!parse_ply_type(w[2], p.count_type) || !ply_is_integer(p.count_type))
                        fail("list count type '" + std::string(w[2]) + "' is not an integer type");
                    if (!parse_ply_type(w[3], p.type)) fail("unknown property type '" + std::string(w[3]) + "'");
                    p.name = std::string(w[4]);
                } else if (w.size() == 3) {
                    if (!parse_ply_type(w[1], p.type)) fail("unknown property type '" + std::string(w[1]) + "'");
                    p.name = std::string(w[2]);
                } else {
                    fail("property line must be 'property TYPE NAME' or 'property list CTYPE TYPE NAME'");
                }
                elements_.back().properties.push_back(std::move(p));
            } else {
                fail("unexpected header line starting with '" + std::string(w[0]) + "'");
            }
        }
        if (!have_format) fail("header has no format line");
        in_header_ = false;
    }

    // ---- value access, ascii or binary ----
    std::vector<std::string_view> words_;
    std::size_t word_ = 0;

    void begin_record() {
        if (!ascii_) return;
        do {
            words_ = split(next_line());
        } while (words_.empty() && pos_ < data_.size());
        word_ = 0;
    }

    void end_record() {
        if (ascii_ && word_ != words_.size()) fail("more values on the line than the header declares");
    }

    double value(ply_type t) {
        if (ascii_) {
            if (word_ >= words_.size()) fail("fewer values on the line than the header declares");
            const std::string_view s = words_[word_++];
            double v = 0.0;
            if (read_number(s, v) != std::errc()) fail("'" + std::string(s) + "' is not a number");
            return v;
        }
        const std::size_t n = ply_size(t);
        if (data_.size() - pos_ < n) fail("file ends in the middle of the data (truncated?)");
        const double v = ply_load_binary(t, data_.data() + pos_);
        pos_ += n;
        return v;
    }

    std::size_t list_count(ply_type t) {
        const double c = value(t);
        if (!(c >= 0.0) || c != std::floor(c) || c > 1e9) fail("invalid list length");
        return static_cast<std::size_t>(c);
    }

    void read_vertices(const PlyElement& e, Mesh& mesh) {
        int xyz[3] = {-1, -1, -1};
        for (std::size_t i = 0; i < e.properties.size(); ++i) {
            const PlyProperty& p = e.properties[i];
            if (p.is_list) continue;
            if (p.name == "x") xyz[0] = static_cast<int>(i);
            if (p.name == "y") xyz[1] = static_cast<int>(i);
            if (p.name == "z") xyz[2] = static_cast<int>(i);
        }
        if (xyz[0] < 0 || xyz[1] < 0 || xyz[2] < 0) fail("vertex element lacks x, y or z properties");
        guard_count(e, 1);
        mesh.points.resize(e.count);
        for (std::size_t v = 0; v < e.count; ++v) {
            begin_record();
            for (std::size_t i = 0; i < e.properties.size(); ++i) {
                const PlyProperty& p = e.properties[i];
                if (p.is_list) {
                    const std::size_t n = list_count(p.count_type);
                    for (std::size_t k = 0; k < n; ++k) value(p.type);
                    continue;
                }
                const double x = value(p.type);
                for (int k = 0; k < 3; ++k)
                    if (xyz[k] == static_cast<int>(i)) mesh.points[v][k] = x;
            }
            end_record();
        }
    }

    void read_faces(const PlyElement& e, Mesh& mesh) {
        int list = -1;
        for (std::size_t i = 0; i < e.properties.size(); ++i) {
            const PlyProperty& p = e.properties[i];
            if (p.is_list && (p.name == "vertex_indices" || p.name == "vertex_index")) list = static_cast<int>(i);
        }
        if (list < 0) fail("face element lacks a 'vertex_indices' list property");
        if (!ply_is_integer(e.properties[static_cast<std::size_t>(list)].type))
            fail("face vertex_indices must have an integer type");
        guard_count(e, 1);
        std::vector<unsigned> face;
        mesh.triangles.reserve(e.count);
        for (std::size_t f = 0; f < e.count; ++f) {
            begin_record();
            for (std::size_t i = 0; i < e.properties.size(); ++i) {
                const PlyProperty& p = e.properties[i];
                if (!p.is_list) {
                    value(p.type);
                    continue;
                }
                const std::size_t n = list_count(p.count_type);
                if (static_cast<int>(i) != list) {
                    for (std::size_t k = 0; k < n; ++k) value(p.type);
                    continue;
                }
                if (n < 3) fail("face has " + std::to_string(n) + " vertices, needs at least 3");
                face.clear();
                for (std::size_t k = 0; k < n; ++k) {
                    const double idx = value(p.type);
                    if (!(idx >= 0.0) || idx != std::floor(idx) || idx > 4294967295.0)
                        fail("face vertex index " + std::to_string(idx) + " is not a valid index");
                    face.push_back(static_cast<unsigned>(idx));
                }
                add_polygon(mesh, face);
            }
            end_record();
        }
    }

    void skip_element(const PlyElement& e) {
        for (std::size_t r = 0; r < e.count; ++r) {
            begin_record();
            for (const PlyProperty& p : e.properties) {
                const std::size_t n = p.is_list ? list_count(p.count_type) : 1;
                for (std::size_t k = 0; k < n; ++k) value(p.type);
            }
            end_record();
        }
    }

    // A corrupt count must not make us allocate terabytes: every record
    // needs at least min_bytes of input (1 byte, or 2 chars of ASCII).
    void guard_count(const PlyElement& e, std::size_t min_bytes) const {
        const std::size_t remaining = data_.size() - pos_;
        if (e.count > remaining / min_bytes + 1)
            throw input_error("cannot read PLY '" + path_ + "': element '" + e.name + "' declares " +
                              std::to_string(e.count) + " records but only " + std::to_string(remaining) +
                              " bytes of data follow (truncated or corrupt file)");
    }

    const std::string& path_;
    std::string_view data_;
    std::size_t pos_ = 0;
    std::size_t line_ = 0;
    bool ascii_ = false;
    bool in_header_ = false;
    std::vector<PlyElement> elements_;
};

}  // namespace

mesh_format mesh_format_from_path(const std::string& path) {
    const std::size_t slash = path.find_last_of('/');
    const std::size_t dot = path.find_last_of('.');
    const std::string ext =
        (dot == std::string::npos || (slash != std::string::npos && dot < slash)) ? "" : lowercase(path.substr(dot));
    if (ext == ".obj") return mesh_format::obj;
    if (ext == ".ply") return mesh_format::ply;
    if (ext == ".off") return mesh_format::off;
    if (ext == ".stl") return mesh_format::stl;
    throw option_error("cannot tell the mesh format of '" + path +
                       "' from its extension; use .obj, .ply, .off or .stl");
}

void write_mesh(const Mesh& mesh, const std::string& path) {
    const mesh_format format = mesh_format_from_path(path);
    check_face_indices(mesh, path);
    AtomicFileWriter out(path);
    switch (format) {
        case mesh_format::obj: write_obj(mesh, out); break;
        case mesh_format::ply: write_ply(mesh, out, path); break;
        case mesh_format::off: write_off(mesh, out); break;
        case mesh_format::stl: write_stl(mesh, out, path); break;
    }
    out.commit();
}

Mesh read_mesh(const std::string& path) {
    const mesh_format format = mesh_format_from_path(path);
    if (format == mesh_format::stl) {
        throw option_error("cannot read '" + path + "': STL input is not supported (it has no shared vertices); "
                           "use OBJ, PLY or OFF");
    }
    const std::string data = read_whole_file(path);
    if (format == mesh_format::obj) return ObjParser(path, data).parse();
    if (format == mesh_format::ply) return PlyParser(path, data).parse();
    return OffParser(path, data).parse();
}

}  // namespace pqdc
