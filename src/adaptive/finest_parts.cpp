#include "adaptive/finest_parts.hpp"

#include "scale/part_bytes.hpp"

#include <cstdint>
#include <type_traits>
#include <vector>

namespace pqdc::adaptive_detail {
namespace {

constexpr std::uint64_t kMagic = 0x314E494643445150ull;  // "PQDCFIN1" read as a native u64
constexpr const char* kWhat = "the adaptive finest level";

template <class T>
void put_array(detail::PartWriter& w, std::vector<T>& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    w.put_bytes(v.data(), v.size() * sizeof(T));
    std::vector<T>().swap(v);
}

template <class T>
void append_array(detail::PartReader& r, std::size_t n, std::vector<T>& v) {
    if (n > r.left() / sizeof(T)) r.malformed("it ends early");
    const std::size_t at = v.size();
    v.resize(at + n);
    r.get_bytes(v.data() + at, n * sizeof(T));
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
    append_array(r, std::size_t(n), cells.code);
    append_array(r, std::size_t(n), cells.flags);
    append_array(r, std::size_t(n), cells.quadrics);
    append_array(r, std::size_t(n), cells.vertex);
    if (!r.done()) r.malformed("bytes follow its last cell");
}

}  // namespace pqdc::adaptive_detail
