#include "scale/stream_scratch.hpp"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

namespace pqdc::detail {
namespace {

void read_at(int fd, void* out, std::uint64_t bytes, std::uint64_t at, const std::string& what) {
    char* p = static_cast<char*>(out);
    while (bytes > 0) {
        const ssize_t got = ::pread(fd, p, std::size_t(bytes), off_t(at));
        if (got < 0 && errno == EINTR) continue;
        if (got <= 0)
            throw io_error("cannot read back the scratch file of " + what + ": " +
                           (got < 0 ? std::strerror(errno) : std::string("it ended early")));
        p += got;
        at += std::uint64_t(got);
        bytes -= std::uint64_t(got);
    }
}

}  // namespace

StreamScratch::StreamScratch(const std::string& target, bool quads)
    : arity_(quads ? 4 : 3), vertices_(target, AtomicFileWriter::Scratch{}), faces_(target, AtomicFileWriter::Scratch{}) {}

void StreamScratch::add_brick(const std::vector<ScratchVertex>& vertices, const std::vector<std::uint32_t>& face_indices,
                              std::vector<ForeignCorner> foreign) {
    vertices_.append(vertices.data(), vertices.size() * sizeof(ScratchVertex));
    faces_.append(face_indices.data(), face_indices.size() * sizeof(std::uint32_t));
    const std::uint64_t n = vertex_first_.back() + vertices.size();
    vertex_first_.push_back(n);
    used_.resize((n + 63) / 64, 0);
    auto next = foreign.begin();
    for (std::size_t i = 0; i < face_indices.size(); ++i) {
        if (next != foreign.end() && next->position == i) {
            (next++)->position += index_first_.back();
            continue;
        }
        const std::uint32_t v = face_indices[i];
        used_[v >> 6] |= std::uint64_t(1) << (v & 63);
    }
    index_first_.push_back(index_first_.back() + face_indices.size());
    foreign_.insert(foreign_.end(), foreign.begin(), foreign.end());
}

void StreamScratch::mark_used(std::uint64_t v) {
    v -= first_global_;
    used_[v >> 6] |= std::uint64_t(1) << (v & 63);
}

void StreamScratch::mark_unused(std::uint64_t v) {
    v -= first_global_;
    used_[v >> 6] &= ~(std::uint64_t(1) << (v & 63));
}

std::uint64_t StreamScratch::used_count() const {
    std::uint64_t n = 0;
    for (std::uint64_t word : used_) n += std::uint64_t(__builtin_popcountll(word));
    return n;
}

void StreamScratch::read_vertices(std::size_t brick, std::vector<ScratchVertex>& out) {
    out.resize(vertex_first_[brick + 1] - vertex_first_[brick]);
    read_at(vertices_.flushed_descriptor(), out.data(), out.size() * sizeof(ScratchVertex),
            vertex_first_[brick] * sizeof(ScratchVertex), "vertices");
}

void StreamScratch::read_faces(std::size_t brick, std::vector<std::uint32_t>& out) {
    const std::uint64_t first = index_first_[brick];
    out.resize(index_first_[brick + 1] - first);
    read_at(faces_.flushed_descriptor(), out.data(), out.size() * sizeof(std::uint32_t),
            first * sizeof(std::uint32_t), "faces");
    if (first_global_ != 0)
        for (std::uint32_t& v : out) v += std::uint32_t(first_global_);
    auto it = std::lower_bound(foreign_.begin(), foreign_.end(), first,
                               [](const ForeignCorner& c, std::uint64_t at) { return c.position < at; });
    for (; it != foreign_.end() && it->position < index_first_[brick + 1]; ++it)
        out[it->position - first] = std::uint32_t(it->vertex);
}

}  // namespace pqdc::detail
