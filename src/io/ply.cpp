// PLY: ascii and binary little-endian reading of any numeric property
// types; binary little-endian writing (float or double x y z [nx ny nz],
// uchar-counted int32 face lists), the layout vdb_tool, MeshLab and
// most PLY readers take.
#include "io/mesh_io_internal.hpp"
#include "memory/huge_pages.hpp"

#include "pqdc/exceptions.hpp"

#include <cmath>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace pqdc {
namespace io {
namespace {

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
            } else if (e.name == "tristrips" && e.count > 0) {  // skipped, it left the mesh without its faces
                throw input_error("cannot read PLY '" + path_ + "': its faces are triangle strips (element "
                                  "'tristrips'), which pqdc does not read; convert them to a 'face' element "
                                  "(e.g. with MeshLab) first");
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

    /// The face element's count (see mesh_file_face_count), from the header
    /// alone; data_ may end after it.
    std::optional<std::uint64_t> announced_faces(std::uint64_t file_size) {
        try {
            parse_header();
        } catch (const input_error&) {
            return std::nullopt;  // parse() gives the message
        }
        // The least bytes the records take: an ascii value is at least a
        // character and a separator; a face's index list holds at least 3
        // indices, other lists may be empty.
        double least = 0;  // no overflow from hostile counts
        std::optional<std::uint64_t> faces;
        for (const PlyElement& e : elements_) {
            std::uint64_t record = 0;
            for (const PlyProperty& p : e.properties) {
                const bool indices = e.name == "face" && p.is_list && (p.name == "vertex_indices" || p.name == "vertex_index");
                const std::uint64_t items = indices ? 3 : 0;
                if (indices) faces = e.count;
                if (ascii_) {
                    record += 2 * ((p.is_list ? 1 : 0) + (p.is_list ? items : 1));
                } else {
                    record += p.is_list ? ply_size(p.count_type) + items * ply_size(p.type) : ply_size(p.type);
                }
            }
            least += double(record) * double(e.count);
        }
        if (least > double(file_size - pos_) + 1) return std::nullopt;
        return faces;
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
        int xyz[3] = {-1, -1, -1}, nxyz[3] = {-1, -1, -1};
        for (std::size_t i = 0; i < e.properties.size(); ++i) {
            const PlyProperty& p = e.properties[i];
            if (p.is_list) continue;
            if (p.name == "x") xyz[0] = static_cast<int>(i);
            if (p.name == "y") xyz[1] = static_cast<int>(i);
            if (p.name == "z") xyz[2] = static_cast<int>(i);
            if (p.name == "nx") nxyz[0] = static_cast<int>(i);
            if (p.name == "ny") nxyz[1] = static_cast<int>(i);
            if (p.name == "nz") nxyz[2] = static_cast<int>(i);
        }
        const bool normals = nxyz[0] >= 0 && nxyz[1] >= 0 && nxyz[2] >= 0;
        if (xyz[0] < 0 || xyz[1] < 0 || xyz[2] < 0) fail("vertex element lacks x, y or z properties");
        guard_count(e, 1);
        detail::reserve_large(mesh.points, e.count);
        mesh.points.resize(e.count);
        if (normals) {
            detail::reserve_large(mesh.normals, e.count);
            mesh.normals.resize(e.count);
        }
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
                for (int k = 0; k < 3; ++k) {
                    if (xyz[k] == static_cast<int>(i)) mesh.points[v][k] = x;
                    if (normals && nxyz[k] == static_cast<int>(i)) mesh.normals[v][k] = x;
                }
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
        detail::reserve_large(mesh.triangles, e.count);
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

template <typename Real>
void write_vertex_records(const openvdb::Vec3d* p, const openvdb::Vec3d* n, std::size_t count,
                          AtomicFileWriter& out) {
    const std::size_t record = (n ? 6 : 3) * sizeof(Real);
    for (std::size_t v = 0; v < count; ++v) {
        char* dst = out.reserve(record);
        for (int k = 0; k < 3; ++k) store_le(dst + k * sizeof(Real), static_cast<Real>(p[v][k]));
        if (n)
            for (int k = 0; k < 3; ++k) store_le(dst + (3 + k) * sizeof(Real), static_cast<Real>(n[v][k]));
    }
}

}  // namespace

std::string ply_header(const MeshCounts& counts, VertexPrecision precision, const std::string& target) {
    constexpr std::uint64_t kMaxIndex = static_cast<std::uint64_t>(std::numeric_limits<std::int32_t>::max());
    if (counts.points > kMaxIndex) {
        throw input_error("cannot write '" + target + "': " + std::to_string(counts.points) +
                          " points exceed PLY's int32 vertex indices; write OBJ instead");
    }
    const std::string type = precision == VertexPrecision::float32 ? "float" : "double";
    std::string header;
    header += "ply\nformat binary_little_endian 1.0\ncomment written by pqdc\n";
    header += "element vertex " + std::to_string(counts.points) + "\n";
    for (const char* axis : {"x", "y", "z"}) header += "property " + type + " " + axis + "\n";
    if (counts.normals)
        for (const char* axis : {"nx", "ny", "nz"}) header += "property " + type + " " + axis + "\n";
    header += "element face " + std::to_string(counts.triangles + counts.quads) + "\n";
    header += "property list uchar int vertex_indices\nend_header\n";
    return header;
}

void ply_vertices(const openvdb::Vec3d* p, const openvdb::Vec3d* n, std::size_t count, VertexPrecision precision,
                  AtomicFileWriter& out) {
    if (precision == VertexPrecision::float32) write_vertex_records<float>(p, n, count, out);
    else write_vertex_records<double>(p, n, count, out);
}

void ply_faces(const unsigned* idx, std::size_t count, int arity, AtomicFileWriter& out) {
    const std::size_t record = 1 + 4 * std::size_t(arity);
    for (std::size_t f = 0; f < count; ++f, idx += arity) {
        char* dst = out.reserve(record);
        dst[0] = char(arity);
        for (int k = 0; k < arity; ++k) store_le(dst + 1 + 4 * k, static_cast<std::int32_t>(idx[k]));
    }
}

void write_ply(const Mesh& mesh, AtomicFileWriter& out, const MeshWriteOptions& options) {
    const MeshCounts counts{mesh.points.size(), mesh.triangles.size(), mesh.quads.size(), !mesh.normals.empty()};
    out.append(ply_header(counts, options.precision, out.display_name()));
    ply_vertices(mesh.points.data(), counts.normals ? mesh.normals.data() : nullptr, mesh.points.size(),
                 options.precision, out);
    ply_faces(triangle_indices(mesh), mesh.triangles.size(), 3, out);
    ply_faces(quad_indices(mesh), mesh.quads.size(), 4, out);
}

std::optional<std::uint64_t> ply_face_count(std::string_view head, std::uint64_t file_size) {
    const std::string path;
    return PlyParser(path, head).announced_faces(file_size);
}

Mesh read_ply(const std::string& path, std::string_view data) { return PlyParser(path, data).parse(); }

}  // namespace io
}  // namespace pqdc
