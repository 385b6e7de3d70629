// The collectives a streamed run builds from pqdc::RankGroup's three
// primitives, and the group of one process a single-process streamed run
// passes, so that one code path serves pqdc and pqdc-mpi (scale/
// stream_numbering.hpp, stream_untangle.hpp, stream_output.hpp).
#pragma once

#include "pqdc/distributed.hpp"
#include "ranks/part_bytes.hpp"

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace pqdc::detail {

/// A rank group of one: rank 0 of 1. Gathers and broadcasts return the
/// caller's own value; there is nobody to send to.
class SoloRank : public RankGroup {
public:
    int rank() const override { return 0; }
    int size() const override { return 1; }
    std::vector<std::string> gather_at_root(std::string part) override { return {std::move(part)}; }
    std::string broadcast_from_root(std::string value) override { return value; }
    void send_to_root(std::string) override { throw std::logic_error("internal error: rank 0 of 1 sent a message"); }
    std::string receive_from(int) override { throw std::logic_error("internal error: rank 0 of 1 waited for a message"); }
};

/// The bytes of a vector of trivially copyable values, and back.
template <class T>
std::string bytes_of(const std::vector<T>& values) {
    std::string bytes;
    PartWriter(bytes).put_array(values);
    return bytes;
}

template <class T>
std::vector<T> values_of(const std::string& bytes, const char* what) {
    PartReader r(bytes, what);
    if (bytes.size() % sizeof(T) != 0) r.malformed("its size is not a whole number of records");
    std::vector<T> out;
    r.append_array(bytes.size() / sizeof(T), out);
    return out;
}

/// Collective: every rank's `part`, in rank order, on every rank.
inline std::vector<std::string> all_gather(RankGroup& group, std::string part) {
    std::vector<std::string> parts = group.gather_at_root(std::move(part));
    std::string joined;
    if (group.rank() == 0) {
        if (parts.size() != std::size_t(group.size()))
            throw std::logic_error("internal error: the rank group gathered " + std::to_string(parts.size()) +
                                   " parts from " + std::to_string(group.size()) + " ranks");
        PartWriter w(joined);
        for (const std::string& p : parts) w.put(std::uint64_t(p.size()));
        for (const std::string& p : parts) w.put_bytes(p.data(), p.size());
    }
    if (group.size() == 1) return parts;
    const std::string all = group.broadcast_from_root(std::move(joined));
    PartReader r(all, "an exchange of the streamed run");
    std::vector<std::uint64_t> sizes(std::size_t(group.size()));
    for (std::uint64_t& s : sizes) s = r.get<std::uint64_t>();
    std::vector<std::string> out(sizes.size());
    for (std::size_t k = 0; k < sizes.size(); ++k) {
        if (sizes[k] > r.left()) r.malformed("it ends early");
        out[k].resize(std::size_t(sizes[k]));
        r.get_bytes(out[k].data(), out[k].size());
    }
    return out;
}

/// Collective: every rank's values of type T, concatenated in rank order, on every rank.
template <class T>
std::vector<T> all_gather_values(RankGroup& group, const std::vector<T>& mine, const char* what) {
    std::vector<T> out;
    for (const std::string& part : all_gather(group, bytes_of(mine))) {
        const std::vector<T> v = values_of<T>(part, what);
        out.insert(out.end(), v.begin(), v.end());
    }
    return out;
}

}  // namespace pqdc::detail
