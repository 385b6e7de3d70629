// STL: binary writing (float facets, quads as two triangles); binary and
// ASCII reading, with corners of identical coordinates merged into shared
// vertices so measuring tools see the mesh's topology.
#include "io/mesh_io_internal.hpp"

#include "pqdc/exceptions.hpp"

#include <array>
#include <cctype>
#include <cmath>
#include <limits>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

namespace pqdc {
namespace io {
namespace {

constexpr std::size_t kHeaderBytes = 84, kFacetBytes = 50;

struct KeyHash {
    std::size_t operator()(const std::array<std::uint64_t, 3>& k) const {
        std::uint64_t h = 0xcbf29ce484222325ull;
        for (std::uint64_t v : k) h = (h ^ v) * 0x100000001b3ull;
        return std::size_t(h ^ (h >> 32));
    }
};

/// Gives each distinct position one index, in order of first appearance.
class VertexWelder {
public:
    explicit VertexWelder(Mesh& mesh) : mesh_(mesh) {}
    unsigned index(const openvdb::Vec3d& p) {
        std::array<std::uint64_t, 3> key;
        for (int k = 0; k < 3; ++k) {
            const double v = p[k] == 0.0 ? 0.0 : p[k];  // -0 and +0 are one position
            std::memcpy(&key[k], &v, 8);
        }
        const auto [it, added] = ids_.try_emplace(key, unsigned(mesh_.points.size()));
        if (added) mesh_.points.push_back(p);
        return it->second;
    }

private:
    Mesh& mesh_;
    std::unordered_map<std::array<std::uint64_t, 3>, unsigned, KeyHash> ids_;
};

void add_triangle(Mesh& mesh, VertexWelder& welder, const openvdb::Vec3d* corner, const std::string& path,
                  std::size_t facet) {
    for (int c = 0; c < 3; ++c)
        for (int k = 0; k < 3; ++k)
            if (!std::isfinite(corner[c][k]))
                throw input_error("cannot read STL '" + path + "': facet " + std::to_string(facet) +
                                  " has a non-finite coordinate");
    mesh.triangles.emplace_back(welder.index(corner[0]), welder.index(corner[1]), welder.index(corner[2]));
}

Mesh read_binary(const std::string& path, std::string_view data, std::size_t facets) {
    Mesh mesh;
    VertexWelder welder(mesh);
    mesh.triangles.reserve(facets);
    for (std::size_t f = 0; f < facets; ++f) {
        const char* rec = data.data() + kHeaderBytes + kFacetBytes * f + 12;  // skip the facet normal
        openvdb::Vec3d corner[3];
        for (int c = 0; c < 3; ++c)
            for (int k = 0; k < 3; ++k) corner[c][k] = double(load_le<float>(rec + 12 * c + 4 * k));
        add_triangle(mesh, welder, corner, path, f);
    }
    return mesh;
}

/// Whether `word` is `keyword`, ignoring ASCII case (some exporters write
/// "SOLID" and "VERTEX").
bool same_word(std::string_view word, std::string_view keyword) {
    if (word.size() != keyword.size()) return false;
    for (std::size_t i = 0; i < word.size(); ++i)
        if (std::tolower(static_cast<unsigned char>(word[i])) != keyword[i]) return false;
    return true;
}

/// Whether the file starts, after white space, with "solid" in any case:
/// an ASCII STL (a binary one of the right size was recognized before).
bool starts_ascii(std::string_view data) {
    std::size_t i = 0;
    while (i < data.size() && (is_space(data[i]) || data[i] == '\n')) ++i;
    return same_word(data.substr(i, 5), "solid");
}

// "solid ... facet normal ... outer loop vertex x y z (x3) endloop endfacet ... endsolid".
Mesh read_ascii(const std::string& path, std::string_view data) {
    Mesh mesh;
    VertexWelder welder(mesh);
    std::size_t pos = 0, line = 1, corners = 0;
    openvdb::Vec3d corner[3];
    auto word = [&]() -> std::string_view {
        while (pos < data.size() && (is_space(data[pos]) || data[pos] == '\n')) line += data[pos++] == '\n';
        const std::size_t start = pos;
        while (pos < data.size() && !is_space(data[pos]) && data[pos] != '\n') ++pos;
        return data.substr(start, pos - start);
    };
    bool in_solid = false;  // between "solid" and "endsolid" (a file may hold several solids)
    for (std::string_view w = word(); !w.empty(); w = word()) {
        if (same_word(w, "solid")) in_solid = true;
        if (same_word(w, "endsolid")) in_solid = false;
        if (!same_word(w, "vertex")) continue;
        for (int k = 0; k < 3; ++k) {
            const std::string_view t = word();
            double v = 0;
            if (read_number(t, v) != std::errc() || !std::isfinite(v))
                throw input_error("cannot read STL '" + path + "' line " + std::to_string(line) +
                                  ": expected a finite vertex coordinate, found '" + std::string(t) + "'");
            corner[corners][k] = v;
        }
        if (++corners == 3) {
            add_triangle(mesh, welder, corner, path, mesh.triangles.size());
            corners = 0;
        }
    }
    if (corners != 0)
        throw input_error("cannot read STL '" + path + "': the last facet has " + std::to_string(corners) +
                          " vertices (truncated file?)");
    if (in_solid)  // cut after a whole facet: the facets read are only part of the mesh
        throw input_error("cannot read STL '" + path + "': it ends before 'endsolid' (truncated file?)");
    return mesh;
}

}  // namespace

std::string stl_header(const MeshCounts& counts, const std::string& target) {
    const std::uint64_t triangle_count = counts.triangles + 2 * counts.quads;
    if (triangle_count > std::numeric_limits<std::uint32_t>::max()) {
        throw input_error("cannot write '" + target + "': " + std::to_string(triangle_count) +
                          " triangles exceed binary STL's 32-bit count; write PLY or OBJ instead");
    }
    std::string header(kHeaderBytes, '\0');
    const char title[] = "binary STL written by pqdc";
    std::memcpy(&header[0], title, sizeof title - 1);
    store_le(&header[80], static_cast<std::uint32_t>(triangle_count));
    return header;
}

void stl_facets(const openvdb::Vec3d* points, const unsigned* idx, std::size_t count, int arity,
                AtomicFileWriter& out) {
    auto emit = [&](unsigned a, unsigned b, unsigned c) {
        const openvdb::Vec3d& pa = points[a];
        const openvdb::Vec3d& pb = points[b];
        const openvdb::Vec3d& pc = points[c];
        openvdb::Vec3d n = (pb - pa).cross(pc - pa);
        const double len = n.length();
        n = len > 0.0 ? n / len : openvdb::Vec3d(0.0);
        char* dst = out.reserve(kFacetBytes);
        const openvdb::Vec3d* vs[4] = {&n, &pa, &pb, &pc};
        for (int v = 0; v < 4; ++v)
            for (int k = 0; k < 3; ++k) store_le(dst + 12 * v + 4 * k, static_cast<float>((*vs[v])[k]));
        store_le(dst + 48, std::uint16_t(0));
    };
    for (std::size_t f = 0; f < count; ++f, idx += arity) {
        emit(idx[0], idx[1], idx[2]);
        if (arity == 4) emit(idx[0], idx[2], idx[3]);
    }
}

void write_stl(const Mesh& mesh, AtomicFileWriter& out) {
    out.append(stl_header({mesh.points.size(), mesh.triangles.size(), mesh.quads.size(), false}, out.display_name()));
    stl_facets(mesh.points.data(), triangle_indices(mesh), mesh.triangles.size(), 3, out);
    stl_facets(mesh.points.data(), quad_indices(mesh), mesh.quads.size(), 4, out);
}

std::optional<std::uint64_t> stl_face_count(std::string_view head, std::uint64_t file_size) {
    if (head.size() < kHeaderBytes) return std::nullopt;
    const std::uint64_t facets = load_le<std::uint32_t>(head.data() + 80);
    if (file_size != kHeaderBytes + kFacetBytes * facets) return std::nullopt;  // ASCII, or not an STL file
    return facets;
}

Mesh read_stl(const std::string& path, std::string_view data) {
    // Binary STL headers may start with "solid" too: the size decides.
    if (data.size() >= kHeaderBytes) {
        const std::size_t facets = load_le<std::uint32_t>(data.data() + 80);
        if (data.size() == kHeaderBytes + kFacetBytes * facets) return read_binary(path, data, facets);
    }
    if (starts_ascii(data)) return read_ascii(path, data);
    if (data.size() < kHeaderBytes)
        throw input_error("cannot read STL '" + path + "': " + std::to_string(data.size()) +
                          " bytes is shorter than a binary STL header (84 bytes) and the file does not start "
                          "with 'solid'");
    const std::size_t facets = load_le<std::uint32_t>(data.data() + 80);
    throw input_error("cannot read STL '" + path + "': its header declares " + std::to_string(facets) +
                      " triangles (" + std::to_string(kHeaderBytes + kFacetBytes * facets) + " bytes) but the file has " +
                      std::to_string(data.size()) + " bytes (truncated or not an STL file)");
}

}  // namespace io
}  // namespace pqdc
