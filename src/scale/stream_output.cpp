#include "scale/stream_output.hpp"

namespace pqdc::detail {
namespace {

/// Index of vertex v among the used vertices (a rank over the used bits).
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

}  // namespace

void write_streamed(StreamScratch& scratch, const std::vector<MovedVertex>& moved, MeshStreamWriter& out,
                             const std::function<void(Mesh&)>& each_piece, const ProgressSpan& progress) {
    const UsedRank ranks(scratch.used());
    std::vector<ScratchVertex> vs;
    std::vector<std::uint32_t> faces;
    auto next_move = moved.begin();
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
            if (ranks.used(v)) piece.points.push_back(p);
        }
        scratch.read_faces(b, faces);
        if (n == 3) piece.triangles.reserve(faces.size() / 3);
        else piece.quads.reserve(faces.size() / 4);
        for (std::size_t f = 0; f < faces.size(); f += std::size_t(n)) {
            unsigned q[4];
            for (int k = 0; k < n; ++k) q[k] = unsigned(ranks.rank(faces[f + std::size_t(k)]));
            if (n == 3) piece.triangles.emplace_back(q[0], q[1], q[2]);
            else piece.quads.emplace_back(q[0], q[1], q[2], q[3]);
        }
        if (each_piece) each_piece(piece);
        out.append(piece);
        progress.report(double(b + 1) / double(scratch.bricks()));
    }
}

}  // namespace pqdc::detail
