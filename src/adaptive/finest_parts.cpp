#include "adaptive/finest_parts.hpp"

#include "scale/part_bytes.hpp"

#include <cstdint>
#include <type_traits>
#include <vector>

namespace pqdc::adaptive_detail {
namespace {

constexpr std::uint64_t kMagic = 0x314E494643445150ull;  // "PQDCFIN1" read as a native u64
constexpr const char* kWhat = "the adaptive finest level";

/// Writes v's elements and frees v: the part holds them now.
template <class T>
void put_array(detail::PartWriter& w, std::vector<T>& v) {
    w.put_array(v);
    std::vector<T>().swap(v);
}

}  // namespace

std::string encode_finest_part(Level& cells, const FinestCounters& counters) {
    std::string out;
    detail::PartWriter w(out);
    w.put(kMagic);
    for (const auto* c : {&counters.crossings, &counters.degenerate, &counters.clamped, &counters.fallback})
        w.put(std::uint64_t(c->load()));
    const std::size_t n = cells.size();
    w.put(std::uint64_t(n));
    put_array(w, cells.code);
    put_array(w, cells.flags);
    put_array(w, cells.quadrics);
    put_array(w, cells.vertex);
    return out;
}

void decode_finest_part(const std::string& part, Level& cells, FinestCounters& counters) {
    detail::PartReader r(part, kWhat);
    if (r.get<std::uint64_t>() != kMagic) r.malformed("the ranks differ in byte order or format");
    for (auto* c : {&counters.crossings, &counters.degenerate, &counters.clamped, &counters.fallback})
        *c += r.get<std::uint64_t>();
    const auto n = r.get<std::uint64_t>();
    if (n > r.left()) r.malformed("it counts more cells than it holds");
    r.append_array(std::size_t(n), cells.code);
    r.append_array(std::size_t(n), cells.flags);
    r.append_array(std::size_t(n), cells.quadrics);
    r.append_array(std::size_t(n), cells.vertex);
    if (!r.done()) r.malformed("bytes follow its last cell");
}

}  // namespace pqdc::adaptive_detail
