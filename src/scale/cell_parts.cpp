#include "scale/cell_parts.hpp"

#include "ranks/part_bytes.hpp"

#include <cstdint>

namespace pqdc::detail {
namespace {

// "PQDCPRT1" read as a native u64: another byte order reads it differently.
constexpr std::uint64_t kMagic = 0x3254525043445150ull;  // "PQDCPRT2": 32-bit cell records
using MaskWords = std::uint64_t[CellLeaf::NodeMaskType::WORD_COUNT];
static_assert(CellLeaf::NodeMaskType::WORD_COUNT == 8, "an 8^3 leaf mask is 8 words");

void put_counters(PartWriter& w, const CellCounters& c) {
    for (std::uint64_t v : {c.active_cells, c.degenerate_normals, c.clamped_vertices, c.fallback_vertices,
                            c.multi_vertex_cells, c.non_finite_values})
        w.put(v);
}

CellCounters get_counters(PartReader& r) {
    CellCounters c;
    for (std::uint64_t* v : {&c.active_cells, &c.degenerate_normals, &c.clamped_vertices, &c.fallback_vertices,
                             &c.multi_vertex_cells, &c.non_finite_values})
        *v = r.get<std::uint64_t>();
    return c;
}

void put_leaf(PartWriter& w, const LeafResults& results, std::size_t li) {
    const CellLeaf& leaf = *results.cells[li];
    const std::vector<openvdb::Vec3d>& points = results.points[li];
    w.put(results.faces[li]);
    w.put(results.incidences[li]);
    w.put(std::uint64_t(points.size()));
    w.put_array(points);
    const auto& mask = leaf.getValueMask();
    for (openvdb::Index i = 0; i < CellLeaf::NodeMaskType::WORD_COUNT; ++i) w.put(mask.getWord<std::uint64_t>(i));
    for (auto it = leaf.cbeginValueOn(); it; ++it) w.put(CellValue(*it));
}

void get_leaf(PartReader& r, const openvdb::Coord& origin, LeafResults& results, std::size_t li) {
    results.faces[li] = r.get<std::uint32_t>();
    results.incidences[li] = r.get<std::uint32_t>();
    const auto count = r.get<std::uint64_t>();
    if (count > (std::uint64_t(1) << 32)) r.malformed("a leaf has too many points");
    std::vector<openvdb::Vec3d>& points = results.points[li];
    points.clear();
    r.append_array(std::size_t(count), points);
    auto leaf = std::make_unique<CellLeaf>(origin, CellValue(0), false);
    leaf->setTransientData(openvdb::Index32(li));  // the leaf's index, as the cells stage sets it
    MaskWords words;
    for (std::uint64_t& word : words) word = r.get<std::uint64_t>();
    for (openvdb::Index n = 0; n < CellLeaf::SIZE; ++n)
        if (words[n >> 6] >> (n & 63) & 1) leaf->setValueOn(n, r.get<CellValue>());
    results.cells[li] = std::move(leaf);
}

}  // namespace

std::string encode_cell_part(LeafResults& results, std::size_t begin, std::size_t end, const CellCounters& counters) {
    std::string out;
    PartWriter w(out);
    w.put(kMagic);
    w.put(std::uint64_t(begin));
    w.put(std::uint64_t(end));
    put_counters(w, counters);
    for (std::size_t li = begin; li < end; ++li) {
        const bool present = results.cells[li] != nullptr;
        w.put(std::uint8_t(present));
        if (present) put_leaf(w, results, li);
        results.cells[li].reset();
        std::vector<openvdb::Vec3d>().swap(results.points[li]);
        results.faces[li] = results.incidences[li] = 0;
    }
    return out;
}

CellCounters decode_cell_part(const std::string& part, const std::vector<openvdb::Coord>& origins,
                              LeafResults& results) {
    PartReader r(part, "the cells stage");
    if (r.get<std::uint64_t>() != kMagic) r.malformed("the ranks differ in byte order or format");
    const auto begin = r.get<std::uint64_t>(), end = r.get<std::uint64_t>();
    if (begin > end || end > origins.size() || end > results.cells.size())
        r.malformed("its leaf range is outside the candidate list");
    const CellCounters counters = get_counters(r);
    for (std::size_t li = std::size_t(begin); li < std::size_t(end); ++li) {
        if (results.cells[li]) r.malformed("two ranks sent the same leaf");
        if (r.get<std::uint8_t>()) get_leaf(r, origins[li], results, li);
    }
    if (!r.done()) r.malformed("bytes follow its last leaf");
    return counters;
}

}  // namespace pqdc::detail
