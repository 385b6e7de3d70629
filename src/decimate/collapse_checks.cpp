// Safety checks of one edge collapse, all evaluated on the mesh as it was at
// the start of the pass (the scheduler makes the collapses of a pass
// independent, so each check stays valid when the others are applied).
//
// Link condition: Dey, Edelsbrunner, Guha & Nekhayev, "Topology Preserving
// Edge Contraction" (1999): for an interior edge a-b of a closed 2-manifold,
// the contraction preserves the topology iff the common neighbours of a and
// b are exactly the two vertices opposite the edge. Together with "no vertex
// drops below valence 3" (which rules out collapsing a tetrahedron) this
// keeps a closed manifold closed, manifold and of the same genus.
// Normal flips and the quality bound follow pmp-library's decimation.cpp
// (normal deviation, aspect ratio) with the quality measure of
// 4 sqrt(3) area / sum of squared sides.
// Self-intersection: the created faces are tested with the exact predicates
// of exact_predicates.hpp against every live triangle whose grid cells meet
// their bounding box, and against each other.

#include "decimate_internal.hpp"
#include "exact_predicates.hpp"

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cmath>

namespace pqdc::decimate_detail {
namespace {

constexpr std::size_t kMaxValence = 64;  // larger fans are refused (never met on sane meshes)
constexpr int kCellBits = 21;
constexpr double kCellLimit = double(1u << kCellBits) - 2;
constexpr std::uint64_t kMaxCellsPerFace = 64;

struct Box {
    vec lo{}, hi{};
    void add(const vec& p) {
        lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
        hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
    }
    bool meets(const Box& o) const {
        return lo.x <= o.hi.x && o.lo.x <= hi.x && lo.y <= o.hi.y && o.lo.y <= hi.y && lo.z <= o.hi.z && o.lo.z <= hi.z;
    }
};

Box box_of(const vec p[3]) {
    Box b{p[0], p[0]};
    b.add(p[1]);
    b.add(p[2]);
    return b;
}

double quality(const vec& p, const vec& q, const vec& r, double* normal_len = nullptr) {
    const vec n = cross(q - p, r - p);
    const double len = length(n);
    if (normal_len) *normal_len = len;
    const double sides = length_sqr(q - p) + length_sqr(r - q) + length_sqr(p - r);
    return sides > 0 ? 2 * std::sqrt(3.0) * len / sides : 0.0;
}

std::uint64_t hash(std::uint64_t k) {  // splitmix64 finalizer
    k ^= k >> 30;
    k *= 0xbf58476d1ce4e5b9ULL;
    k ^= k >> 27;
    k *= 0x94d049bb133111ebULL;
    return k ^ (k >> 31);
}

bool contains(const Tri& t, std::uint32_t v) { return t[0] == v || t[1] == v || t[2] == v; }

}  // namespace

// ------------------------------------------------------------ TriangleGrid

std::vector<BoxPair> triangle_boxes(const std::vector<vec>& pos, const std::vector<Tri>& tris) {
    std::vector<BoxPair> boxes(tris.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, tris.size(), 4096), [&](const auto& r) {
        for (std::size_t i = r.begin(); i < r.end(); ++i) {
            const vec p[3] = {pos[tris[i][0]], pos[tris[i][1]], pos[tris[i][2]]};
            const Box b = box_of(p);
            boxes[i] = {b.lo, b.hi};
        }
    });
    return boxes;
}

TriangleGrid::TriangleGrid(std::vector<BoxPair> boxes_in) : boxes_(std::move(boxes_in)) {
    const std::vector<BoxPair>& boxes = boxes_;
    ids_ = boxes.size();
    if (boxes.empty()) return;
    Box all{boxes[0][0], boxes[0][1]};
    double extent_sum = 0;
    for (const BoxPair& b : boxes) {
        all.add(b[0]);
        all.add(b[1]);
        extent_sum += std::max({b[1].x - b[0].x, b[1].y - b[0].y, b[1].z - b[0].z});
    }
    const double span = std::max({all.hi.x - all.lo.x, all.hi.y - all.lo.y, all.hi.z - all.lo.z});
    // Cells a little larger than a typical face: most faces touch 1-8 cells.
    double h = 2.0 * extent_sum / double(boxes.size());
    h = std::max(h, span / kCellLimit);
    if (!(h > 0)) h = 1;
    lo_ = all.lo;
    inv_h_ = 1 / h;
    // Counting sort of (cell, face) entries by hashed bucket: two linear
    // passes, faces in ascending order within a bucket, no comparison sort.
    const std::uint64_t mask = (1u << kCellBits) - 1;
    std::vector<std::array<std::uint64_t, 2>> corner(boxes.size());  // cell keys of each box's corners
    for (std::size_t i = 0; i < boxes.size(); ++i) corner[i] = {key(boxes[i][0]), key(boxes[i][1])};
    auto each_cell = [&](std::size_t i, auto&& f) {
        const std::uint64_t k0 = corner[i][0], k1 = corner[i][1];
        for (std::uint64_t x = k0 >> (2 * kCellBits); x <= (k1 >> (2 * kCellBits)); ++x)
            for (std::uint64_t y = (k0 >> kCellBits) & mask; y <= ((k1 >> kCellBits) & mask); ++y)
                for (std::uint64_t z = k0 & mask; z <= (k1 & mask); ++z) f((x << (2 * kCellBits)) | (y << kCellBits) | z);
    };
    // Faces much larger than the cells (a flat CAD side among small faces)
    // are kept in one list that every query returns, instead of in
    // thousands of cells each.
    std::vector<std::uint8_t> listed(boxes.size(), 1);
    std::size_t total = 0;
    for (std::size_t i = 0; i < boxes.size(); ++i) {
        const std::uint64_t k0 = corner[i][0], k1 = corner[i][1];
        const std::uint64_t cells = ((k1 >> (2 * kCellBits)) - (k0 >> (2 * kCellBits)) + 1) *
                                    (((k1 >> kCellBits) & mask) - ((k0 >> kCellBits) & mask) + 1) *
                                    ((k1 & mask) - (k0 & mask) + 1);
        if (cells > kMaxCellsPerFace) {
            oversize_.push_back(std::uint32_t(i));
            listed[i] = 0;
        } else {
            total += cells;
        }
    }
    // Dense cell table (z fastest, so a query reads one contiguous run of
    // entries per x-y row) when the lattice is not much larger than the
    // entry count; hashed buckets otherwise (sparse or elongated inputs).
    const std::uint64_t kmax = key(all.hi);
    dims_ = {(kmax >> (2 * kCellBits)) + 1, ((kmax >> kCellBits) & mask) + 1, (kmax & mask) + 1};
    const double cells = double(dims_[0]) * double(dims_[1]) * double(dims_[2]);
    dense_ = cells <= std::max(4.0 * double(total), 65536.0);
    std::size_t size = 16;
    if (dense_) {
        size = std::size_t(cells);
    } else {
        while (size < total) size *= 2;
    }
    mask_ = size - 1;
    bucket_begin_.assign(size + 1, 0);
    for (std::size_t i = 0; i < boxes.size(); ++i)
        if (listed[i]) each_cell(i, [&](std::uint64_t k) { ++bucket_begin_[bucket(k) + 1]; });
    for (std::size_t b = 0; b < size; ++b) bucket_begin_[b + 1] += bucket_begin_[b];
    entries_.resize(total);
    std::vector<std::uint32_t> fill(bucket_begin_.begin(), bucket_begin_.end() - 1);
    for (std::size_t i = 0; i < boxes.size(); ++i)
        if (listed[i]) each_cell(i, [&](std::uint64_t k) { entries_[fill[bucket(k)]++] = {k, corner[i][0], std::uint32_t(i)}; });
}

std::uint64_t TriangleGrid::bucket(std::uint64_t k) const {
    if (!dense_) return hash(k) & mask_;
    const std::uint64_t mask = (1u << kCellBits) - 1;
    return ((k >> (2 * kCellBits)) * dims_[1] + ((k >> kCellBits) & mask)) * dims_[2] + (k & mask);
}

std::uint64_t TriangleGrid::key(const vec& p) const {
    auto cell = [&](double v, double lo) {
        const double c = std::floor((v - lo) * inv_h_);
        return c >= 0 ? std::uint64_t(std::min(c, kCellLimit)) : std::uint64_t(0);  // NaN -> 0
    };
    return (cell(p.x, lo_.x) << (2 * kCellBits)) | (cell(p.y, lo_.y) << kCellBits) | cell(p.z, lo_.z);
}

void TriangleGrid::query(const vec& lo, const vec& hi, std::vector<std::uint32_t>& out) const {
    out.clear();
    const Box q{lo, hi};
    for (std::uint32_t id : oversize_)
        if (Box{boxes_[id][0], boxes_[id][1]}.meets(q)) out.push_back(id);
    if (entries_.empty()) return;
    // A face in several cells is reported only from the cell holding the
    // lowest corner of its box's overlap with the query box: once, without
    // stamps or sorting. Floor is monotone, so that cell is in both ranges
    // and its coordinates are the larger of the two boxes' first cells'.
    const std::uint64_t k0 = key(lo), k1 = key(hi);
    const std::uint64_t mask = (1u << kCellBits) - 1;
    const std::uint64_t qx = k0 >> (2 * kCellBits), qy = (k0 >> kCellBits) & mask, qz = k0 & mask;
    auto report = [&](const Entry& en, std::uint64_t x, std::uint64_t y, std::uint64_t z) {
        const std::uint64_t f = en.first_cell;
        if (std::max(f >> (2 * kCellBits), qx) != x || std::max((f >> kCellBits) & mask, qy) != y ||
            std::max(f & mask, qz) != z)
            return;
        const BoxPair& b = boxes_[en.id];
        if (Box{b[0], b[1]}.meets(q)) out.push_back(en.id);
    };
    const std::uint64_t z0 = k0 & mask, z1 = k1 & mask;
    for (std::uint64_t x = k0 >> (2 * kCellBits); x <= (k1 >> (2 * kCellBits)); ++x)
        for (std::uint64_t y = (k0 >> kCellBits) & mask; y <= ((k1 >> kCellBits) & mask); ++y) {
            const std::uint64_t row = (x << (2 * kCellBits)) | (y << kCellBits);
            if (dense_) {
                const std::uint32_t e0 = bucket_begin_[bucket(row | z0)], e1 = bucket_begin_[bucket(row | z1) + 1];
                for (std::uint32_t e = e0; e < e1; ++e) report(entries_[e], x, y, entries_[e].cell & mask);
                continue;
            }
            for (std::uint64_t z = z0; z <= z1; ++z) {
                const std::uint64_t k = row | z;
                const std::uint64_t b = hash(k) & mask_;
                for (std::uint32_t e = bucket_begin_[b]; e < bucket_begin_[b + 1]; ++e)
                    if (entries_[e].cell == k) report(entries_[e], x, y, z);
            }
        }
}

// ------------------------------------------------------------------ checks

bool link_condition_holds(const WorkMesh& m, std::uint32_t a, std::uint32_t b) {
    const std::size_t na = m.fan_size(a), nb = m.fan_size(b);
    if (na > kMaxValence || nb > kMaxValence || na + nb < 7) return false;  // merged valence na + nb - 4 >= 3
    std::uint32_t ring_a[kMaxValence], opposite[2];
    std::size_t ra = 0, shared_faces = 0;
    for (std::size_t i = 0; i < na; ++i) {
        const Tri& t = m.tris[m.fan_of(a)[i]];
        for (int k = 0; k < 3; ++k)
            if (t[k] == a) ring_a[ra++] = t[(k + 1) % 3];  // closed fan: each neighbour once
        if (contains(t, b)) {
            if (shared_faces == 2) return false;
            for (int k = 0; k < 3; ++k)
                if (t[k] != a && t[k] != b) opposite[shared_faces] = t[k];
            ++shared_faces;
        }
    }
    if (shared_faces != 2 || opposite[0] == opposite[1]) return false;
    if (m.fan_size(opposite[0]) < 4 || m.fan_size(opposite[1]) < 4) return false;
    std::size_t common = 0;
    for (std::size_t i = 0; i < nb; ++i) {
        const Tri& t = m.tris[m.fan_of(b)[i]];
        for (int k = 0; k < 3; ++k) {
            if (t[k] != b) continue;
            const std::uint32_t w = t[(k + 1) % 3];
            if (std::find(ring_a, ring_a + ra, w) != ring_a + ra) {
                if (w != opposite[0] && w != opposite[1]) return false;
                ++common;
            }
        }
    }
    return common == 2;
}

Verdict check_shape(const WorkMesh& m, const Candidate& c, const CheckLimits& lim) {
    double worst_old = 1, worst_new = 1;
    for (std::uint32_t v : {c.a, c.b}) {
        for (std::size_t i = 0; i < m.fan_size(v); ++i) {
            const Tri& t = m.tris[m.fan_of(v)[i]];
            const vec p[3] = {m.pos[t[0]], m.pos[t[1]], m.pos[t[2]]};
            double old_len;
            worst_old = std::min(worst_old, quality(p[0], p[1], p[2], &old_len));
            if (contains(t, c.a) && contains(t, c.b)) continue;
            vec q[3] = {p[0], p[1], p[2]};
            for (int k = 0; k < 3; ++k)
                if (t[k] == v) q[k] = c.x;
            double new_len;
            worst_new = std::min(worst_new, quality(q[0], q[1], q[2], &new_len));
            const vec n0 = cross(p[1] - p[0], p[2] - p[0]), n1 = cross(q[1] - q[0], q[2] - q[0]);
            if (!(new_len > 0) || !(dot(n0, n1) >= lim.min_cos_normal_change * old_len * new_len))
                return Verdict::flip;
        }
    }
    if (worst_new < std::min(lim.min_quality, worst_old)) return Verdict::quality;
    return Verdict::ok;
}

void new_faces(const WorkMesh& m, const Candidate& c, std::vector<Tri>& out) {
    out.clear();
    for (std::uint32_t v : {c.a, c.b})
        for (std::size_t i = 0; i < m.fan_size(v); ++i) {
            Tri t = m.tris[m.fan_of(v)[i]];
            if (contains(t, c.a) && contains(t, c.b)) continue;
            for (auto& k : t)
                if (k == c.b) k = c.a;
            out.push_back(t);
        }
}

bool faces_intersect(const Tri& t, const vec pt[3], const Tri& u, const vec pu[3]) {
    int ti[3], ui[3], shared = 0;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            if (t[i] == u[j]) {
                ti[shared] = i;
                ui[shared] = j;
                ++shared;
            }
    if (shared == 0) return exact::triangles_intersect(pt, pu);
    if (shared == 3) return true;
    if (shared == 2) {
        const int ta = 3 - ti[0] - ti[1], uc = 3 - ui[0] - ui[1];
        return exact::triangles_overlap_sharing_edge(pt[ti[0]], pt[ti[1]], pt[ta], pu[uc]);
    }
    const int s = ti[0], r = ui[0];
    return exact::triangles_intersect_sharing_vertex(pt[s], pt[(s + 1) % 3], pt[(s + 2) % 3], pu[(r + 1) % 3],
                                                     pu[(r + 2) % 3]);
}

Verdict check_intersection_and_distance(const WorkMesh& m, const TriangleGrid& grid, const Candidate& c,
                                        const CheckLimits& lim, CheckScratch& scratch) {
    std::vector<Tri>& faces = scratch.faces;
    std::vector<std::array<vec, 3>>& fp = scratch.fp;
    std::vector<BoxPair>& fb = scratch.fb;
    new_faces(m, c, faces);
    auto position = [&](std::uint32_t v) { return v == c.a ? c.x : m.pos[v]; };
    fp.resize(faces.size());
    fb.resize(faces.size());
    scratch.planes.clear();
    Box all{c.x, c.x};
    for (std::size_t i = 0; i < faces.size(); ++i) {
        for (int k = 0; k < 3; ++k) fp[i][k] = position(faces[i][k]);
        const Box b = box_of(fp[i].data());
        fb[i] = {b.lo, b.hi};
        all.add(b.lo);
        all.add(b.hi);
        scratch.planes.emplace_back(fp[i].data());
    }
    for (std::size_t i = 0; i < faces.size(); ++i)
        for (std::size_t j = i + 1; j < faces.size(); ++j)
            if (boxes_meet(fb[i], fb[j]) && faces_intersect(faces[i], fp[i].data(), faces[j], fp[j].data()))
                return Verdict::intersection;
    // A face that already crossed one of the faces being replaced was an
    // intersection of the input (none arise otherwise): meeting it again is
    // tolerated, so decimation does not stall around input defects.
    auto crossed_before = [&](const Tri& u, const vec pu[3]) {
        for (std::uint32_t v : {c.a, c.b})
            for (std::size_t k = 0; k < m.fan_size(v); ++k) {
                const Tri& t = m.tris[m.fan_of(v)[k]];
                const vec pt[3] = {m.pos[t[0]], m.pos[t[1]], m.pos[t[2]]};
                if (faces_intersect(t, pt, u, pu)) return true;
            }
        return false;
    };
    grid.query(all.lo, all.hi, scratch.near);
    for (std::uint32_t id : scratch.near) {
        const BoxPair& ub = grid.box(id);
        const Tri& u = m.tris[id];
        if (contains(u, c.a) || contains(u, c.b)) continue;  // replaced by the new faces
        const vec pu[3] = {m.pos[u[0]], m.pos[u[1]], m.pos[u[2]]};
        for (std::size_t i = 0; i < faces.size(); ++i)
            if (boxes_meet(fb[i], ub) && !certainly_apart(scratch.planes[i], faces[i], u, pu) &&
                faces_intersect(faces[i], fp[i].data(), u, pu)) {
                if (crossed_before(u, pu)) break;
                return Verdict::intersection;
            }
    }
    if (lim.input_surface) {
        // The vertex is the bound; the midpoints of its new edges and the
        // new faces' centroids are checked too, so a face cannot cut far
        // across the input between its corners (still a sampled estimate).
        auto far = [&](const vec& p) { return (*lim.input_surface)(openvdb::Vec3d(p.x, p.y, p.z)) > lim.max_distance; };
        if (far(c.x)) return Verdict::distance;
        for (const auto& p : fp) {
            if (far((p[0] + p[1] + p[2]) / 3.0)) return Verdict::distance;
            for (int k = 0; k < 3; ++k)
                if ((p[k] == c.x) && far((p[k] + p[(k + 1) % 3]) * 0.5)) return Verdict::distance;
        }
    }
    return Verdict::ok;
}

}  // namespace pqdc::decimate_detail
