// ASCII OFF (Geomview, CGAL).
#include "io/mesh_io_internal.hpp"

#include "pqdc/exceptions.hpp"

#include <algorithm>
#include <cmath>
#include <string>
#include <string_view>
#include <vector>

namespace pqdc {
namespace io {
namespace {

// ASCII OFF as Geomview and CGAL write it: whitespace-separated numbers that
// may break lines anywhere, except that a vertex's extra values (the ST, C and
// N header prefixes) and a face's color run to the end of the line they start
// on. Counts and indices are parsed as numbers and then required to be whole,
// so that "3.5" gets a message saying what is wrong with it.
class OffParser {
public:
    OffParser(const std::string& path, std::string_view data) : path_(path), data_(data) {}

    /// The header: the keyword and the three counts.
    struct Header {
        bool vertex_extras = false;
        std::size_t vertices = 0, faces = 0;
    };

    Header parse_header() {
        if (!advance())
            throw input_error("cannot read OFF '" + path_ + "': the file has no data (empty or only comments)");
        const std::string_view keyword = token_;
        if (keyword.size() < 3 || keyword.substr(keyword.size() - 3) != "OFF")
            fail("not an OFF file (first word '" + std::string(keyword) + "', expected OFF, COFF, NOFF...)");
        const std::string_view prefix = keyword.substr(0, keyword.size() - 3);
        if (prefix.find_first_of("4n") != std::string_view::npos)
            fail("'" + std::string(keyword) + "': only 3D OFF files are supported (no 4OFF/nOFF)");
        if (prefix.find_first_not_of("STCN") != std::string_view::npos)
            fail("not an OFF file (first word '" + std::string(keyword) + "')");
        Header h;
        h.vertex_extras = !prefix.empty();
        next("the vertex count");
        if (token_ == "BINARY") fail("binary OFF is not supported; convert it to ASCII OFF first");
        h.vertices = whole_number("the vertex count");
        h.faces = count("the face count");
        count("the edge count");
        return h;
    }

    /// Where the header ends (after parse_header()).
    std::size_t offset() const { return pos_; }

    Mesh parse() {
        const Header header = parse_header();
        const bool vertex_extras = header.vertex_extras;
        const std::size_t nv = header.vertices, nf = header.faces;

        Mesh mesh;
        // A corrupt count must not allocate gigabytes before the data runs
        // out: every vertex takes at least 6 characters, every face 8.
        mesh.points.reserve(std::min(nv, data_.size() / 6));
        mesh.triangles.reserve(std::min(nf, data_.size() / 8));
        for (std::size_t v = 0; v < nv; ++v) {
            openvdb::Vec3d p;
            p[0] = coordinate();
            const std::size_t vertex_line = token_line_;
            p[1] = coordinate();
            p[2] = coordinate();
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

    /// A vertex coordinate: NaN and infinities too, as the OBJ and PLY
    /// readers take them and write_mesh writes them (pqdc-measure counts them).
    double coordinate() {
        next("a vertex coordinate");
        double v = 0.0;
        if (read_number(token_, v) != std::errc()) fail("expected a vertex coordinate, found '" + std::string(token_) + "'");
        return v;
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
        if (v < 0 || v != std::floor(v))
            fail(std::string("expected ") + what + " (a whole number >= 0), found '" + std::string(token_) + "'");
        if (v > 1e9)
            fail(std::string(what) + " " + std::string(token_) + " is more than the 1e9 this reader takes; is the "
                 "header right?");
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

// "N i0 i1 ...\n", indices from 0.
void append_face_line(AtomicFileWriter& out, const unsigned* idx, int n) {
    constexpr std::size_t kFaceMax = 2 + 4 * 12 + 2;
    char* const begin = out.reserve(kFaceMax);
    char* cur = begin;
    *cur++ = char('0' + n);
    for (int k = 0; k < n; ++k) {
        *cur++ = ' ';
        cur = std::to_chars(cur, begin + kFaceMax, static_cast<std::uint64_t>(idx[k])).ptr;
    }
    *cur++ = '\n';
    out.advance(static_cast<std::size_t>(cur - begin));
}

}  // namespace

// No comment line: several small OFF readers in the wild expect the counts
// right after "OFF".
std::string off_header(const MeshCounts& counts) {
    return "OFF\n" + std::to_string(counts.points) + " " + std::to_string(counts.triangles + counts.quads) + " 0\n";
}

void off_points(const openvdb::Vec3d* p, std::size_t count, VertexPrecision precision, AtomicFileWriter& out) {
    for (std::size_t i = 0; i < count; ++i) append_point_line(out, "", p[i], precision);
}

void off_faces(const unsigned* idx, std::size_t count, int arity, AtomicFileWriter& out) {
    for (std::size_t f = 0; f < count; ++f, idx += arity) append_face_line(out, idx, arity);
}

void write_off(const Mesh& mesh, AtomicFileWriter& out, const MeshWriteOptions& options) {
    out.append(off_header({mesh.points.size(), mesh.triangles.size(), mesh.quads.size(), false}));
    off_points(mesh.points.data(), mesh.points.size(), options.precision, out);
    off_faces(triangle_indices(mesh), mesh.triangles.size(), 3, out);
    off_faces(quad_indices(mesh), mesh.quads.size(), 4, out);
}

std::optional<std::uint64_t> off_face_count(std::string_view head, std::uint64_t file_size) {
    const std::string path;
    OffParser parser(path, head);
    try {
        const auto header = parser.parse_header();
        // Every vertex takes at least 6 characters ("0 0 0" and a separator),
        // every face 8 ("3 0 1 2" and one), but the last needs no separator.
        const std::uint64_t least = 6 * std::uint64_t(header.vertices) + 8 * std::uint64_t(header.faces);
        if (least > file_size - parser.offset() + 1) return std::nullopt;
        return header.faces;
    } catch (const input_error&) {
        return std::nullopt;  // read_off() gives the message
    }
}

Mesh read_off(const std::string& path, std::string_view data) { return OffParser(path, data).parse(); }

}  // namespace io
}  // namespace pqdc
