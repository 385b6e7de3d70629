#include "scale/stream_output.hpp"

#include "ranks/part_bytes.hpp"
#include "ranks/rank_exchange.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace pqdc::detail {
namespace {

/// Index of vertex v (of this rank's) among its used vertices (a rank over the used bits).
class UsedRank {
public:
    explicit UsedRank(const std::vector<std::uint64_t>& used) : used_(used), before_(used.size() + 1, 0) {
        for (std::size_t w = 0; w < used.size(); ++w) before_[w + 1] = before_[w] + std::uint64_t(__builtin_popcountll(used[w]));
    }
    bool used(std::uint64_t v) const { return (used_[v >> 6] >> (v & 63)) & 1; }
    std::uint64_t rank(std::uint64_t v) const {
        const std::uint64_t below = used_[v >> 6] & ((std::uint64_t(1) << (v & 63)) - 1);
        return before_[v >> 6] + std::uint64_t(__builtin_popcountll(below));
    }

private:
    const std::vector<std::uint64_t>& used_;
    std::vector<std::uint64_t> before_;
};

constexpr const char* kPieces = "the streamed run's pieces";

std::string encode(const Mesh& piece) {
    std::string bytes;
    PartWriter w(bytes);
    w.put(std::uint64_t(piece.points.size()));
    w.put(std::uint64_t(piece.triangles.size()));
    w.put(std::uint64_t(piece.quads.size()));
    w.put_array(piece.points);
    w.put_array(piece.triangles);
    w.put_array(piece.quads);
    return bytes;
}

Mesh decode(const std::string& bytes) {
    PartReader r(bytes, kPieces);
    const auto points = std::size_t(r.get<std::uint64_t>()), triangles = std::size_t(r.get<std::uint64_t>()),
               quads = std::size_t(r.get<std::uint64_t>());
    Mesh piece;
    r.append_array(points, piece.points);
    r.append_array(triangles, piece.triangles);
    r.append_array(quads, piece.quads);
    if (!r.done()) r.malformed("its sizes disagree");
    return piece;
}

}  // namespace

UsedNumbering number_used(const StreamScratch& scratch, const std::vector<std::uint64_t>& foreign, RankGroup& group) {
    UsedNumbering out;
    const std::vector<std::uint64_t> used =
        all_gather_values(group, std::vector<std::uint64_t>{scratch.used_count()}, kPieces);
    for (int r = 0; r < group.size(); ++r) {
        if (r == group.rank()) out.first = out.total;
        out.total += used[std::size_t(r)];
    }
    const UsedRank ranks(scratch.used());
    const std::uint64_t lo = scratch.first_global(), hi = lo + scratch.vertex_count();
    std::vector<std::uint64_t> mine;
    for (auto it = std::lower_bound(foreign.begin(), foreign.end(), lo); it != foreign.end() && *it < hi; ++it)
        mine.push_back(ranks.used(*it - lo) ? out.first + ranks.rank(*it - lo) : kUnusedVertex);
    out.foreign = all_gather_values(group, mine, kPieces);
    if (out.foreign.size() != foreign.size())
        throw std::logic_error("internal error: the ranks numbered " + std::to_string(out.foreign.size()) + " of " +
                               std::to_string(foreign.size()) + " vertices used across rank boundaries");
    return out;
}

void write_streamed(StreamScratch& scratch, const UsedNumbering& numbers, const std::vector<std::uint64_t>& foreign,
                    const std::vector<MovedVertex>& moved, RankGroup& group, PieceParts parts, MeshStreamWriter& out,
                    const std::function<void(Mesh&)>& each_piece, const ProgressSpan& progress) {
    const UsedRank ranks(scratch.used());
    const std::uint64_t lo = scratch.first_global(), hi = lo + scratch.vertex_count();
    // kUnusedVertex for a vertex no longer used (a removed component's).
    auto final_number = [&](std::uint64_t v) -> std::uint64_t {
        if (v >= lo && v < hi) return ranks.used(v - lo) ? numbers.first + ranks.rank(v - lo) : kUnusedVertex;
        const auto it = std::lower_bound(foreign.begin(), foreign.end(), v);
        if (it == foreign.end() || *it != v) throw std::logic_error("internal error: a face uses another rank's vertex the exchange missed");
        return numbers.foreign[std::size_t(it - foreign.begin())];
    };
    const bool root = group.rank() == 0;
    // STL's facets need every corner in one place: its pieces always go to rank 0.
    const bool in_place = parts == PieceParts::each_rank_its_writer && out.format() != MeshFormat::stl;
    auto deliver = [&](Mesh& piece) {
        if (!root && !in_place) return group.send_to_root(encode(piece));
        if (each_piece) each_piece(piece);
        out.append(piece);
    };
    std::vector<ScratchVertex> vs;
    std::vector<std::uint32_t> faces;
    auto next_move = std::lower_bound(moved.begin(), moved.end(), lo,
                                      [](const MovedVertex& m, std::uint64_t v) { return m.first < v; });
    const int n = scratch.arity();
    for (std::size_t b = 0; b < scratch.bricks(); ++b) {
        Mesh piece;
        scratch.read_vertices(b, vs);
        const std::uint64_t first = scratch.first_vertex(b);
        piece.points.reserve(vs.size());
        for (std::size_t i = 0; i < vs.size(); ++i) {
            const std::uint64_t v = first + i;
            openvdb::Vec3d p = vs[i].position;
            if (next_move != moved.end() && next_move->first == v) p = (next_move++)->second;
            if (ranks.used(v - lo)) piece.points.push_back(p);
        }
        scratch.read_faces(b, faces);
        if (n == 3) piece.triangles.reserve(faces.size() / 3);
        else piece.quads.reserve(faces.size() / 4);
        for (std::size_t f = 0; f < faces.size(); f += std::size_t(n)) {
            // A face at an unused vertex is a removed component's
            // (scale/stream_components.hpp): dropped. Its unused corner
            // may be another rank's (a triangle of a quad split across a
            // rank boundary need not hold its cell's own vertex).
            std::uint64_t q[4];
            bool removed = false;
            for (int k = 0; k < n; ++k) {
                q[k] = final_number(faces[f + std::size_t(k)]);
                removed = removed || q[k] == kUnusedVertex;
            }
            if (removed) continue;
            if (n == 3) piece.triangles.emplace_back(unsigned(q[0]), unsigned(q[1]), unsigned(q[2]));
            else piece.quads.emplace_back(unsigned(q[0]), unsigned(q[1]), unsigned(q[2]), unsigned(q[3]));
        }
        deliver(piece);
        progress.report(double(b + 1) / double(scratch.bricks()));
    }
    if (in_place) return;
    if (!root) return group.send_to_root(std::string());  // the end of this rank's pieces
    for (int r = 1; r < group.size(); ++r)
        for (std::string bytes = group.receive_from(r); !bytes.empty(); bytes = group.receive_from(r)) {
            Mesh piece = decode(bytes);
            deliver(piece);
        }
}

}  // namespace pqdc::detail
