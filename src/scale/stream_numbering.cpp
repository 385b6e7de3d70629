#include "scale/stream_numbering.hpp"

#include "pqdc/exceptions.hpp"
#include "ranks/part_bytes.hpp"
#include "ranks/rank_exchange.hpp"

#include <algorithm>
#include <string>

namespace pqdc::detail {
namespace {

constexpr const char* kWhat = "the streamed run's vertex counts";

std::string encode_share(const StreamedCells& mine) {
    std::string bytes;
    PartWriter w(bytes);
    w.put(mine.counts);
    w.put(std::uint64_t(mine.leaf_begin));
    w.put(std::uint64_t(mine.leaf_vertices.size()));
    w.put_array(mine.leaf_vertices);
    return bytes;
}

/// Every rank's vertex counts per leaf into `first` (per candidate leaf,
/// its first vertex's global number; one more entry at the end) and their
/// counters into `counts`.
void read_shares(const std::vector<std::string>& shares, std::vector<std::uint64_t>& first, StreamCounts& counts) {
    std::vector<std::uint32_t> per_leaf;
    for (const std::string& share : shares) {
        PartReader r(share, kWhat);
        counts += r.get<StreamCounts>();
        const auto begin = r.get<std::uint64_t>(), n = r.get<std::uint64_t>();
        if (begin + n + 1 > first.size() || n * sizeof(std::uint32_t) != r.left()) r.malformed("its leaves are out of range");
        per_leaf.clear();
        r.append_array(std::size_t(n), per_leaf);
        for (std::size_t i = 0; i < per_leaf.size(); ++i) first[std::size_t(begin) + i + 1] = per_leaf[i];
    }
    for (std::size_t i = 1; i < first.size(); ++i) first[i] += first[i - 1];
}

void sort_unique(std::vector<std::uint64_t>& v) {
    std::sort(v.begin(), v.end());
    v.erase(std::unique(v.begin(), v.end()), v.end());
}

}  // namespace

StreamNumbering number_streamed(const StreamedCells& mine, std::size_t leaves, StreamScratch& scratch, RankGroup& group) {
    StreamNumbering out;
    std::vector<std::uint64_t> first(leaves + 1, 0);
    read_shares(all_gather(group, encode_share(mine)), first, out.counts);
    out.vertices = first.back();
    if (out.vertices >= (std::uint64_t(1) << 32))
        throw resource_error("the mesh would have " + std::to_string(out.vertices) +
                             " vertices, more than 32-bit face indices can address; mesh the volume in parts");
    if (!mine.leaf_vertices.empty()) scratch.number_from(first[mine.leaf_begin]);

    std::vector<std::uint64_t> seeds;
    seeds.reserve(mine.seeds.size());
    for (const auto& [leaf, v] : mine.seeds) seeds.push_back(first[leaf] + v);
    out.seeds = all_gather_values(group, seeds, kWhat);
    sort_unique(out.seeds);

    std::vector<std::uint64_t> foreign;
    for (ForeignCorner& c : scratch.foreign()) {
        c.vertex = first[std::size_t(c.vertex >> 32)] + (c.vertex & 0xffffffffu);
        foreign.push_back(c.vertex);
    }
    sort_unique(foreign);  // fewer bytes to send
    out.foreign = all_gather_values(group, foreign, kWhat);
    sort_unique(out.foreign);
    const std::uint64_t lo = scratch.first_global(), hi = lo + scratch.vertex_count();
    for (auto it = std::lower_bound(out.foreign.begin(), out.foreign.end(), lo); it != out.foreign.end() && *it < hi; ++it)
        scratch.mark_used(*it);
    return out;
}

}  // namespace pqdc::detail
