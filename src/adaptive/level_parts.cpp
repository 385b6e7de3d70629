#include "adaptive/level_parts.hpp"

#include "ranks/part_bytes.hpp"

#include <cstdint>
#include <type_traits>
#include <vector>

namespace pqdc::adaptive_detail {
namespace {

constexpr std::uint64_t kMagic = 0x31574F4C43445150ull;  // "PQDCLOW1" read as a native u64
constexpr const char* kWhat = "the adaptive octree's lower levels";

/// Writes v's elements and frees v: the part holds them now.
template <class T>
void put_array(detail::PartWriter& w, std::vector<T>& v) {
    w.put_array(v);
    std::vector<T>().swap(v);
}

}  // namespace

std::string encode_levels_part(std::vector<Level>& levels, const FinestCounters& finest, const MergeCounters& merges) {
    std::string out;
    detail::PartWriter w(out);
    w.put(kMagic);
    for (const auto* c : counter_fields(finest)) w.put(std::uint64_t(c->load()));
    for (const auto* c : counter_fields(merges)) w.put(std::uint64_t(c->load()));
    w.put(std::uint64_t(levels.size()));
    for (std::size_t level = 0; level < levels.size(); ++level) {
        Level& lv = levels[level];
        w.put(std::uint64_t(lv.size()));
        put_array(w, lv.code);
        put_array(w, lv.flags);
        if (level > 0) put_array(w, lv.child_mask);
        w.put(std::uint64_t(lv.quadrics.size()));
        put_array(w, lv.quadrics);
        put_array(w, lv.vertex);
        lv = Level{};
    }
    return out;
}

void decode_levels_part(const std::string& part, std::vector<Level>& levels, FinestCounters& finest,
                        MergeCounters& merges) {
    detail::PartReader r(part, kWhat);
    if (r.get<std::uint64_t>() != kMagic) r.malformed("the ranks differ in byte order or format");
    for (auto* c : counter_fields(finest)) *c += r.get<std::uint64_t>();
    for (auto* c : counter_fields(merges)) *c += r.get<std::uint64_t>();
    if (r.get<std::uint64_t>() != levels.size()) r.malformed("it holds another number of levels");
    for (std::size_t level = 0; level < levels.size(); ++level) {
        Level& lv = levels[level];
        const auto n = r.get<std::uint64_t>();
        if (n > r.left()) r.malformed("it counts more nodes than it holds");
        r.append_array(std::size_t(n), lv.code);
        r.append_array(std::size_t(n), lv.flags);
        if (level > 0) r.append_array(std::size_t(n), lv.child_mask);
        const auto q = r.get<std::uint64_t>();
        if (q != 0 && q != n) r.malformed("its quadrics are not one per node");
        r.append_array(std::size_t(q), lv.quadrics);
        r.append_array(std::size_t(n), lv.vertex);
        if (level > 0) lv.first_child.resize(lv.size());
    }
    if (!r.done()) r.malformed("bytes follow its last level");
}

}  // namespace pqdc::adaptive_detail
