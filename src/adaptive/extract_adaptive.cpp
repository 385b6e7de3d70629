// Adaptive extraction: Hermite data on the finest lattice, bottom-up octree
// simplification with probabilistic quadrics, then the dual grid and
// marching cubes of adaptive_dual.cpp. See include/pqdc/adaptive.hpp.
#include "adaptive/octree.hpp"
#include "lattice/value_block.hpp"

#include "pqdc/exceptions.hpp"

#include <openvdb/tools/Interpolation.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>

namespace pqdc {

using namespace adaptive_detail;
using openvdb::Coord;
using openvdb::Vec3d;

void validate(const AdaptiveOptions& options) {
    const ExtractOptions& b = options.base;
    if (!(b.sigma_n >= 0))
        throw option_error("AdaptiveOptions::base.sigma_n must be >= 0 (or infinity), got " +
                           std::to_string(b.sigma_n));
    if (!std::isfinite(b.isovalue))
        throw option_error("AdaptiveOptions::base.isovalue must be finite");
    if (!(b.pseudo_inverse_cutoff >= 0 && b.pseudo_inverse_cutoff < 1))
        throw option_error("AdaptiveOptions::base.pseudo_inverse_cutoff must be in [0, 1), got " +
                           std::to_string(b.pseudo_inverse_cutoff));
    if (!(options.max_error_voxels >= 0))
        throw option_error("AdaptiveOptions::max_error_voxels (--max-error) must be >= 0 voxels, got " +
                           std::to_string(options.max_error_voxels));
    const int s = options.max_cell_size_voxels;
    if (s < 1 || s > (1 << kMaxLevel) || (s & (s - 1)) != 0)
        throw option_error("AdaptiveOptions::max_cell_size_voxels (--max-cell-size) must be a power of two "
                           "in [1, 4096], got " + std::to_string(s));
}

namespace {

using clock_type = std::chrono::steady_clock;

std::string coord_string(const Coord& c) {
    return "(" + std::to_string(c.x()) + ", " + std::to_string(c.y()) + ", " + std::to_string(c.z()) + ")";
}
double seconds_since(clock_type::time_point t0) {
    return std::chrono::duration<double>(clock_type::now() - t0).count();
}

void report_progress(const AdaptiveOptions& options, double fraction) {
    if (options.base.progress && !options.base.progress(fraction))
        throw cancelled_error("adaptive extraction cancelled by the progress callback");
}

// ------------------------------------------------------------ Hermite data

/// The lattice values around one 8^3 block: points B-1 .. B+9 (for central
/// differences at B .. B+8), their activity, and a cache of edge crossings.
struct BlockScratch {
    static constexpr int N = 11;
    detail::DenseBlock dense;  // lattice points block - 1 .. block + 9
    detail::DenseBlock wide;   // block - 2 .. block + 10, for crossings with kMargin == 2
    struct Crossing {
        Vec3d point;   // relative to the block origin
        Vec3d normal;  // unit, index space; zero when degenerate
        std::uint32_t stamp = 0;
    };
    Crossing cache[3 * 9 * 9 * 9];
    std::uint32_t stamp = 0;

    /// Signed value (inside negative) at block point (i, j, k), i, j, k in [-1, 9].
    double g(int i, int j, int k) const { return dense.value[std::size_t(dense.index(i + 1, j + 1, k + 1))]; }
    bool active(int i, int j, int k) const { return dense.on(i + 1, j + 1, k + 1); }
};

using detail::root_on_unit_interval;  // shared with the uniform extractor (lattice/value_block.hpp)

/// Grids: crossing by linear interpolation of the lattice values, normal from
/// central differences at the two lattice points, interpolated linearly.
// kMargin: lattice points of margin around the block the crossing needs
// (2: BlockScratch::wide is filled for it).
struct LinearCrossings {
    static constexpr int kMargin = 1;
    void operator()(const BlockScratch& s, const Coord&, int axis, int i, int j, int k, Vec3d& p,
                    Vec3d& n) const {
        const int a[3] = {i, j, k};
        int b[3] = {i, j, k};
        b[axis] += 1;
        const double ga = s.g(a[0], a[1], a[2]);
        const double gb = s.g(b[0], b[1], b[2]);
        const double t = ga / (ga - gb);
        p = Vec3d(i, j, k);
        p[axis] += t;
        auto grad = [&](const int* c) {
            Vec3d r;
            for (int d = 0; d < 3; ++d) {
                int lo[3] = {c[0], c[1], c[2]}, hi[3] = {c[0], c[1], c[2]};
                lo[d] -= 1;
                hi[d] += 1;
                r[d] = 0.5 * (s.g(hi[0], hi[1], hi[2]) -
                              s.g(lo[0], lo[1], lo[2]));
            }
            return r;
        };
        n = grad(a) * (1 - t) + grad(b) * t;
    }
};

/// Grids with GridNormals::sharp: the uniform extractor's sharp_crossing.
struct SharpCrossings {
    static constexpr int kMargin = 2;
    void operator()(const BlockScratch& s, const Coord&, int axis, int i, int j, int k, Vec3d& p,
                    Vec3d& n) const {
        const detail::Crossing c = detail::sharp_crossing(s.wide, i + 2, j + 2, k + 2, axis);
        p = Vec3d(i, j, k);
        p[axis] += c.t;
        n = Vec3d(c.normal.x, c.normal.y, c.normal.z);
    }
};

/// Procedural fields: crossing by root finding on the exact field, normal
/// from the analytic gradient (mapped to index space).
struct ExactCrossings {
    static constexpr int kMargin = 1;
    const ScalarField* field;
    const openvdb::math::Transform* xform;

    void operator()(const BlockScratch& s, const Coord& block, int axis, int i, int j, int k,
                    Vec3d& p, Vec3d& n) const {
        const Vec3d a = block.asVec3d() + Vec3d(i, j, k);
        Vec3d e(0.0);
        e[axis] = 1;
        const double fa = field->value(xform->indexToWorld(a));
        const double fb = field->value(xform->indexToWorld(a + e));
        double t;
        if ((fa < 0) != (fb < 0)) {
            t = root_on_unit_interval([&](double u) { return field->value(xform->indexToWorld(a + e * u)); },
                                      fa, fb, 1e-7);
        } else {  // float rounding of the lattice disagreed with the exact field
            int b[3] = {i, j, k};
            b[axis] += 1;
            const double ga = s.g(i, j, k);
            const double gb = s.g(b[0], b[1], b[2]);
            t = ga / (ga - gb);
        }
        p = Vec3d(i, j, k);
        p[axis] += t;
        const Vec3d gw = field->gradient(xform->indexToWorld(block.asVec3d() + p));
        n = xform->baseMap()->applyJT(gw);
    }
};

struct SurfaceCell {
    std::uint64_t code;
    std::uint8_t flags;
    CellQuadrics q;
    Vec3d vertex;  // index space
};

struct Counters {
    std::atomic<std::uint64_t> crossings{0}, degenerate{0}, clamped{0}, fallback{0};
    std::atomic<std::uint64_t> merges{0}, refused_error{0}, refused_topology{0}, refused_containment{0},
        refused_balance{0};
};

/// The vertex of a cell of edge `size` voxels: minimizer of the
/// probabilistic quadric classical + (sigma_n^2 / size) points, in the
/// cell's local coordinates.
Vec3d solve_vertex(const CellQuadrics& q, double size, const ExtractOptions& o, bool& fallback) {
    fallback = false;
    const double count = q.points.count;
    const vec3<double> mass = q.points.sum / count;
    if (o.sigma_n == 0) {
        const auto r = minimizer_pseudo_inverse(q.classical, mass, o.pseudo_inverse_cutoff);
        return Vec3d(r.point.x, r.point.y, r.point.z);
    }
    if (std::isinf(o.sigma_n)) return Vec3d(mass.x, mass.y, mass.z);
    const double vn = o.sigma_n * o.sigma_n / size;
    const auto x = minimizer_positive_definite(q.classical + q.points.as_quadric() * vn);
    if (!x) {
        fallback = true;
        return Vec3d(mass.x, mass.y, mass.z);
    }
    return Vec3d(x->x, x->y, x->z);
}

/// The surface cells of one 8^3 block: with `out`, their Hermite data and
/// vertices are appended to it; without, they are only counted (the first of
/// the two passes that size the finest level exactly). Returns the count.
template <class GridT, class Crossings>
std::size_t process_block(const Coord& block, typename GridT::ConstAccessor& acc, const detail::Signing& signing,
                          const Crossings& crossings, const AdaptiveOptions& options, const Coord& offset,
                          BlockScratch& s, std::vector<SurfaceCell>* out, Counters& counters) {
    // Most candidate blocks of a narrow band lie on one side of the surface:
    // decide that from the source values before converting any.
    if (!detail::corners_may_cross(acc, block, signing)) return 0;
    detail::fetch_block(acc, block - Coord(1), BlockScratch::N, signing, s.dense);
    if constexpr (Crossings::kMargin == 2)
        if (out) detail::fetch_block(acc, block - Coord(2), BlockScratch::N + 2, signing, s.wide);
    std::size_t count = 0;
    if (++s.stamp == 0) {
        for (auto& c : s.cache) c.stamp = 0;
        s.stamp = 1;
    }
    std::uint64_t n_crossings = 0, n_degenerate = 0, n_clamped = 0, n_fallback = 0;
    const auto& in_row = s.dense.inside_row;
    for (int i = 0; i < 8; ++i)
        for (int j = 0; j < 8; ++j) {
            // Cells (i, j, 0..7) whose corners are not all on one side, 8 at a
            // time from the inside bits (block point p sits at bit p + 1).
            const unsigned all = unsigned(in_row[i + 1][j + 1] & in_row[i + 2][j + 1] & in_row[i + 1][j + 2] &
                                          in_row[i + 2][j + 2]),
                           any = unsigned(in_row[i + 1][j + 1] | in_row[i + 2][j + 1] | in_row[i + 1][j + 2] |
                                          in_row[i + 2][j + 2]);
            unsigned crossed = (((any | (any >> 1)) & ~(all & (all >> 1))) >> 1) & 0xffu;
            while (crossed) {
                const int k = __builtin_ctz(crossed);
                crossed &= crossed - 1;
                // A cell takes part when a corner is active and all are finite
                // (the domain of extract()).
                unsigned mask = 0;
                bool any_active = false, finite = true;
                for (int c = 0; c < 8; ++c) {
                    const int ci = i + (c & 1), cj = j + (c >> 1 & 1), ck = k + (c >> 2 & 1);
                    const double v = s.g(ci, cj, ck);
                    any_active = any_active || s.active(ci, cj, ck);
                    finite = finite && std::isfinite(v);
                    if (v < 0) mask |= 1u << c;
                }
                if (!any_active || !finite || mask == 0 || mask == 255) continue;
                ++count;
                if (!out) continue;
                SurfaceCell cell;
                cell.flags = std::uint8_t(kLeaf | (manifold_configuration(mask) ? kManifold : 0));
                const Vec3d cell_origin(i, j, k);
                for (int e = 0; e < 12; ++e) {
                    const auto ec = edge_corners(e);
                    if ((mask >> ec[0] & 1) == (mask >> ec[1] & 1)) continue;
                    const int axis = e / 4;
                    const int li = i + (ec[0] & 1), lj = j + (ec[0] >> 1 & 1), lk = k + (ec[0] >> 2 & 1);
                    BlockScratch::Crossing& x = s.cache[axis * 729 + li + 9 * (lj + 9 * lk)];
                    if (x.stamp != s.stamp) {
                        Vec3d n;
                        crossings(s, block, axis, li, lj, lk, x.point, n);
                        const double len = n.length();
                        if (std::isfinite(len) && len > 0) {
                            x.normal = n / len;
                        } else {
                            x.normal = Vec3d(0.0);
                            ++n_degenerate;
                        }
                        x.stamp = s.stamp;
                        ++n_crossings;
                    }
                    const Vec3d ql = x.point - cell_origin;
                    const vec3<double> q(ql.x(), ql.y(), ql.z());
                    const vec3<double> n(x.normal.x(), x.normal.y(), x.normal.z());
                    if (n == vec3<double>(0, 0, 0))
                        cell.q.classical += quadricd::point(q);
                    else
                        cell.q.classical += quadricd::plane(q, n);
                    cell.q.points.add(q);
                }
                bool fallback = false;
                Vec3d v = solve_vertex(cell.q, 1.0, options.base, fallback);
                if (fallback) ++n_fallback;
                if (options.base.containment == Containment::clamp_to_cell) {
                    const Vec3d clamped(std::clamp(v.x(), 0.0, 1.0), std::clamp(v.y(), 0.0, 1.0),
                                        std::clamp(v.z(), 0.0, 1.0));
                    if (clamped != v) ++n_clamped;
                    v = clamped;
                }
                const Coord origin = block + Coord(i, j, k);
                cell.vertex = origin.asVec3d() + v;
                const Coord rel = origin - offset;
                cell.code = morton(std::uint32_t(rel.x()), std::uint32_t(rel.y()), std::uint32_t(rel.z()));
                out->push_back(cell);
            }
        }
    counters.crossings += n_crossings;
    counters.degenerate += n_degenerate;
    counters.clamped += n_clamped;
    counters.fallback += n_fallback;
    return count;
}

/// 8^3 blocks that can hold cells with an active corner: every leaf node and
/// the blocks of active tiles that touch the tile's upper faces (a tile is
/// constant inside), each with its lower neighbours (cells whose origin lies
/// one voxel below an active voxel).
template <class GridT>
std::vector<Coord> candidate_blocks(const GridT& grid) {
    std::vector<Coord> seeds;
    for (auto leaf = grid.tree().cbeginLeaf(); leaf; ++leaf) seeds.push_back(leaf->origin());
    auto it = grid.tree().cbeginValueOn();
    it.setMaxDepth(GridT::TreeType::ValueOnCIter::LEAF_DEPTH - 1);  // tiles only: never visit the voxels
    for (; it; ++it) {
        openvdb::CoordBBox box;
        it.getBoundingBox(box);
        const Coord lo = box.min(), hi = box.max();
        for (int z = lo.z(); z <= hi.z(); z += 8)
            for (int y = lo.y(); y <= hi.y(); y += 8)
                for (int x = lo.x(); x <= hi.x(); x += 8)
                    if (x == lo.x() || y == lo.y() || z == lo.z() || x + 8 > hi.x() || y + 8 > hi.y() ||
                        z + 8 > hi.z())
                        seeds.emplace_back(x, y, z);
    }
    std::vector<Coord> blocks;
    blocks.reserve(seeds.size() * 8);
    for (const Coord& b : seeds)
        for (int c = 0; c < 8; ++c) blocks.push_back(b - Coord((c & 1) * 8, (c >> 1 & 1) * 8, (c >> 2 & 1) * 8));
    tbb::parallel_sort(blocks.begin(), blocks.end());
    blocks.erase(std::unique(blocks.begin(), blocks.end()), blocks.end());
    return blocks;
}

std::size_t default_memory_limit() {
    const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
    if (pages <= 0 || page <= 0) return std::numeric_limits<std::size_t>::max();
    return std::size_t(double(pages) * double(page) * 0.8);
}

// ------------------------------------------------------------ octree

/// Ju et al. 2002 §4.2 on the 27 lattice points of a cell of edge 2h:
/// manifold corner configuration, and the middle of every edge, face and of
/// the cube agrees in sign with one of that element's corners.
template <class Accessor>
bool topology_safe(Accessor& acc, const Coord& origin, int h, double sign, double iso) {
    bool in[3][3][3];
    for (int k = 0; k < 3; ++k)
        for (int j = 0; j < 3; ++j)
            for (int i = 0; i < 3; ++i)
                in[i][j][k] = sign * (double(acc.getValue(origin + Coord(i * h, j * h, k * h))) - iso) < 0;
    unsigned mask = 0;
    for (int c = 0; c < 8; ++c)
        if (in[2 * (c & 1)][2 * (c >> 1 & 1)][2 * (c >> 2 & 1)]) mask |= 1u << c;
    if (!manifold_configuration(mask)) return false;
    // Every one of the 19 non-corner points: it agrees with some corner of
    // the smallest element (edge, face, cube) that has it as its middle.
    for (int k = 0; k < 3; ++k)
        for (int j = 0; j < 3; ++j)
            for (int i = 0; i < 3; ++i) {
                if (i != 1 && j != 1 && k != 1) continue;  // a corner
                bool agrees = false;
                for (int ck = (k == 1 ? 0 : k); ck <= (k == 1 ? 2 : k) && !agrees; ck += 2)
                    for (int cj = (j == 1 ? 0 : j); cj <= (j == 1 ? 2 : j) && !agrees; cj += 2)
                        for (int ci = (i == 1 ? 0 : i); ci <= (i == 1 ? 2 : i) && !agrees; ci += 2)
                            agrees = in[ci][cj][ck] == in[i][j][k];
                if (!agrees) return false;
            }
    return true;
}

/// Whether the parent with this code may become a leaf without breaking the
/// 2:1 balance of the octree: none of the 56 cells of the children's level
/// around it is subdivided further (internal_children: sorted codes of the
/// children's level's internal nodes). In a
/// balanced octree every leaf edge holds at most one T-junction, so the
/// degenerate dual cells around it form no fans, whose shared edges would be
/// used by more than two marching-cubes polygons.
bool balanced(const std::vector<std::uint64_t>& internal_children, std::uint64_t parent_code) {
    if (internal_children.empty()) return true;
    const auto p = unmorton(parent_code);
    for (int dz = -1; dz <= 2; ++dz)
        for (int dy = -1; dy <= 2; ++dy)
            for (int dx = -1; dx <= 2; ++dx) {
                if (dx >= 0 && dx <= 1 && dy >= 0 && dy <= 1 && dz >= 0 && dz <= 1) continue;
                const std::int64_t x = 2 * std::int64_t(p[0]) + dx, y = 2 * std::int64_t(p[1]) + dy,
                                   z = 2 * std::int64_t(p[2]) + dz;
                if (x < 0 || y < 0 || z < 0) continue;
                if (std::binary_search(internal_children.begin(), internal_children.end(),
                                       morton(std::uint32_t(x), std::uint32_t(y), std::uint32_t(z))))
                    return false;
            }
    return true;
}

template <class GridT>
Level build_parent_level(const GridT& grid, const FieldSource& field, const Octree& tree, int level,
                         double sign, double iso, const AdaptiveOptions& options, Counters& counters) {
    const Level& cur = tree.levels[level];
    std::vector<std::size_t> starts;
    for (std::size_t i = 0; i < cur.size(); ++i)
        if (i == 0 || (cur.code[i] >> 3) != (cur.code[i - 1] >> 3)) starts.push_back(i);
    const std::size_t groups = starts.size();
    Level next;
    next.code.resize(groups);
    next.flags.assign(groups, 0);
    next.child_mask.resize(groups);
    next.first_child.resize(groups);
    next.quadrics.resize(groups);
    next.vertex.resize(groups);
    std::vector<std::uint64_t> internal_children;
    for (std::size_t i = 0; i < cur.size(); ++i)
        if (!(cur.flags[i] & kLeaf)) internal_children.push_back(cur.code[i]);
    const int h = 1 << level;
    const double size = 2.0 * h;
    const bool merging = options.max_error_voxels > 0;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, groups, 256),
                      [&](const tbb::blocked_range<std::size_t>& r) {
        auto acc = grid.getConstAccessor();
        auto probe = field.probe();
        std::uint64_t merges = 0, refused_error = 0, refused_topology = 0, refused_containment = 0,
                      refused_balance = 0;
        for (std::size_t g = r.begin(); g != r.end(); ++g) {
            const std::size_t i0 = starts[g], i1 = g + 1 < groups ? starts[g + 1] : cur.size();
            const std::uint64_t code = cur.code[i0] >> 3;
            next.code[g] = code;
            next.first_child[g] = std::uint32_t(i0);
            unsigned mask = 0;
            bool children_mergeable = true;
            for (std::size_t i = i0; i < i1; ++i) {
                mask |= 1u << (cur.code[i] & 7);
                children_mergeable = children_mergeable && cur.flags[i] == (kLeaf | kManifold);
            }
            next.child_mask[g] = std::uint8_t(mask);
            if (!merging || !children_mergeable) continue;
            const Coord origin = tree.origin(level + 1, code);
            if (!topology_safe(acc, origin, h, sign, iso)) {
                ++refused_topology;
                continue;
            }
            CellQuadrics sum;
            for (std::size_t i = i0; i < i1; ++i) {
                const unsigned o = unsigned(cur.code[i] & 7);
                const vec3<double> off(-double((o & 1) * h), -double((o >> 1 & 1) * h),
                                       -double((o >> 2 & 1) * h));
                sum.classical += cur.quadrics[i].classical.relative_to(off);
                sum.points += cur.quadrics[i].points.relative_to(off);
            }
            bool fallback = false;
            const Vec3d x = solve_vertex(sum, size, options.base, fallback);
            const double tol = 1e-9 * size;
            if (fallback || !(x.x() >= -tol && x.y() >= -tol && x.z() >= -tol && x.x() <= size + tol &&
                              x.y() <= size + tol && x.z() <= size + tol)) {
                ++refused_containment;
                continue;
            }
            double error = 0;
            for (std::size_t i = i0; i < i1 && error < options.max_error_voxels; ++i) {
                const unsigned o = unsigned(cur.code[i] & 7);
                const vec3<double> y(x.x() - double((o & 1) * h), x.y() - double((o >> 1 & 1) * h),
                                     x.z() - double((o >> 2 & 1) * h));
                const CellQuadrics& q = cur.quadrics[i];
                error = std::max(error, std::sqrt(std::max(0.0, q.classical(y)) / q.points.count));
            }
            // sigma_n pulls the vertex off weakly sampled features (a box
            // corner seen by one sample of its third face): keep it within
            // half the bound of the classical minimizer, taken with a small
            // cutoff so that such directions count.
            if (options.base.sigma_n > 0 && error < options.max_error_voxels) {
                const vec3<double> xp(x.x(), x.y(), x.z());
                const auto classical = minimizer_pseudo_inverse(sum.classical, xp, 0.01);
                error = std::max(error, 2 * length(classical.point - xp));
            }
            // The planes bound the vertex's distance to the sampled surface
            // only in the mean; check the field itself at the vertex too.
            // Faces will join this vertex to its neighbours' vertices, about
            // twice as far as its children's: their sagitta is about four
            // times the depth of the midpoints towards the children's
            // vertices. Those lie within a cell of the vertex, so the
            // vertex's gradient converts their field values to distances
            // (one probe each instead of seven).
            if (error < options.max_error_voxels) {
                const Vec3d px = origin.asVec3d() + x;
                const double gradient = field_gradient_length(*probe, px);
                error = std::max(error, field_distance_voxels(*probe, px, gradient));
                for (std::size_t i = i0; i < i1 && error < options.max_error_voxels; ++i)
                    error = std::max(error, 4 * field_distance_voxels(*probe, 0.5 * (px + cur.vertex[i]), gradient));
            }
            if (!(error < options.max_error_voxels)) {
                ++refused_error;
                continue;
            }
            if (!balanced(internal_children, code)) {
                ++refused_balance;
                continue;
            }
            next.flags[g] = kLeaf | kManifold;
            next.quadrics[g] = sum;
            next.vertex[g] = origin.asVec3d() + x;
            ++merges;
        }
        counters.merges += merges;
        counters.refused_error += refused_error;
        counters.refused_topology += refused_topology;
        counters.refused_containment += refused_containment;
        counters.refused_balance += refused_balance;
    });
    return next;
}

template <class GridT>
class GridField final : public FieldSource {
public:
    GridField(const GridT& grid, double sign, double iso) : grid_(grid), sign_(sign), iso_(iso) {}
    std::unique_ptr<FieldProbe> probe() const override {
        return std::make_unique<Probe>(grid_, sign_, iso_);
    }

private:
    struct Probe final : FieldProbe {
        Probe(const GridT& g, double s, double i) : acc(g.getConstAccessor()), sign(s), iso(i) {}
        double value(const Vec3d& p) override {
            return sign * (double(openvdb::tools::BoxSampler::sample(acc, p)) - iso);
        }
        typename GridT::ConstAccessor acc;
        double sign, iso;
    };
    const GridT& grid_;
    double sign_, iso_;
};

class ProceduralField final : public FieldSource {
public:
    ProceduralField(const ScalarField& f, const openvdb::math::Transform& xf) : f_(f), xf_(xf) {}
    std::unique_ptr<FieldProbe> probe() const override { return std::make_unique<Probe>(f_, xf_); }

private:
    struct Probe final : FieldProbe {
        Probe(const ScalarField& f, const openvdb::math::Transform& xf) : f(f), xf(xf) {}
        double value(const Vec3d& p) override { return f.value(xf.indexToWorld(p)); }
        const ScalarField& f;
        const openvdb::math::Transform& xf;
    };
    const ScalarField& f_;
    const openvdb::math::Transform& xf_;
};

template <class GridT, class Crossings>
Mesh run(const GridT& grid, double sign, double iso, const Crossings& crossings, const FieldSource& field,
         const AdaptiveOptions& options, AdaptiveStats* stats_out) {
    validate(options);
    const auto t_start = clock_type::now();
    const std::string name = grid.getName().empty() ? std::string("(unnamed)") : grid.getName();
    const openvdb::math::Transform& xf = grid.transform();
    if (!xf.isLinear() || !xf.hasUniformScale())
        throw input_error("grid '" + name + "' has a non-linear or non-uniformly scaled transform; "
                          "resample it to a uniform voxel size first");
    AdaptiveStats stats;
    Counters counters;
    report_progress(options, 0.0);

    const int top = [&] {
        int t = 0;
        while ((1 << t) < options.max_cell_size_voxels) ++t;
        return t;
    }();
    const openvdb::CoordBBox bbox = grid.evalActiveVoxelBoundingBox();
    if (bbox.empty()) {
        stats.seconds_total = seconds_since(t_start);
        if (stats_out) *stats_out = stats;
        return Mesh{};
    }
    // One root of margin below the data, so that root neighbours have codes.
    const int root = 1 << top;
    auto floor_to_root = [&](int v) { return int(std::floor(double(v) / root)) * root; };
    Octree tree;
    tree.top = top;
    tree.offset = Coord(floor_to_root(bbox.min().x()), floor_to_root(bbox.min().y()),
                        floor_to_root(bbox.min().z())) - Coord(root);
    const Coord span = bbox.max() - tree.offset + Coord(2 * root + 8);
    if (span.x() >= (1 << kCoordBits) || span.y() >= (1 << kCoordBits) || span.z() >= (1 << kCoordBits))
        throw input_error("grid '" + name + "': active voxels span " + coord_string(bbox.dim()) +
                          " voxels, more than the adaptive extractor's 2^19 per axis; crop the grid");

    // 1. Finest level.
    auto t0 = clock_type::now();
    std::vector<Coord> blocks = candidate_blocks(grid);
    // With an 8-aligned code origin the cells of one 8^3 block occupy one run
    // of 512 codes: blocks in code order, each block's cells in code order,
    // is all cells in code order, without a global sort or a copy.
    const bool block_runs = ((tree.offset.x() | tree.offset.y() | tree.offset.z()) & 7) == 0;
    auto block_code = [&](const Coord& b) {
        const Coord rel = b - tree.offset;
        return morton(std::uint32_t(rel.x()), std::uint32_t(rel.y()), std::uint32_t(rel.z()));
    };
    if (block_runs)
        tbb::parallel_sort(blocks.begin(), blocks.end(),
                           [&](const Coord& a, const Coord& b) { return block_code(a) < block_code(b); });
    detail::Signing signing;
    signing.isovalue = iso;
    signing.sign = sign;
    // Count, prefix sum, fill: the finest level is written once, in place,
    // at its exact size (growing per-block record lists and copying them
    // cost as much memory again and most of this stage's page faults).
    std::vector<std::size_t> block_start(blocks.size() + 1, 0);
    {
        Counters ignored;
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, blocks.size(), 4),
                          [&](const tbb::blocked_range<std::size_t>& r) {
            auto acc = grid.getConstAccessor();
            auto scratch = std::make_unique<BlockScratch>();
            for (std::size_t b = r.begin(); b != r.end(); ++b)
                block_start[b + 1] = process_block<GridT>(blocks[b], acc, signing, crossings, options, tree.offset,
                                                          *scratch, nullptr, ignored);
        });
    }
    for (std::size_t b = 0; b < blocks.size(); ++b) block_start[b + 1] += block_start[b];
    const std::size_t n_cells = block_start.back();
    const std::size_t limit =
        options.base.memory_limit_bytes ? options.base.memory_limit_bytes : default_memory_limit();
    // Octree levels (~1.2x the finest level), leaf ids (up to ~1.5 per cell:
    // vertex, value and two flags), dual cells (~4 per leaf: 8 ids and a
    // sign mask) and the mesh.
    const double estimate = double(n_cells) * (1.2 * (sizeof(SurfaceCell) + 16) + 1.5 * 34 + 4 * 33 + 64);
    if (estimate > double(limit))
        throw resource_error("adaptive extraction of grid '" + name + "' needs about " +
                             std::to_string(std::size_t(estimate) >> 20) + " MiB, more than the limit of " +
                             std::to_string(limit >> 20) + " MiB; raise memory_limit_bytes or crop the grid");
    tree.levels.resize(top + 1);
    {
        Level& l0 = tree.levels[0];
        l0.code.resize(n_cells);
        l0.flags.resize(n_cells);
        // child_mask and first_child describe internal nodes: none at level 0.
        l0.quadrics.resize(n_cells);
        l0.vertex.resize(n_cells);
        auto put = [&l0](std::size_t i, const SurfaceCell& c) {
            l0.code[i] = c.code;
            l0.flags[i] = c.flags;
            l0.quadrics[i] = c.q;
            l0.vertex[i] = c.vertex;
        };
        // Cell sizes below 8 voxels: the codes of one block are not one run,
        // so the cells are gathered first and put in code order after.
        std::vector<SurfaceCell> gathered(block_runs ? 0 : n_cells);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, blocks.size(), 4),
                          [&](const tbb::blocked_range<std::size_t>& r) {
            auto acc = grid.getConstAccessor();
            auto scratch = std::make_unique<BlockScratch>();
            std::vector<SurfaceCell> cells;
            cells.reserve(512);
            for (std::size_t b = r.begin(); b != r.end(); ++b) {
                if (block_start[b + 1] == block_start[b]) continue;
                cells.clear();
                process_block<GridT>(blocks[b], acc, signing, crossings, options, tree.offset, *scratch, &cells,
                                     counters);
                if (block_runs) {
                    std::sort(cells.begin(), cells.end(),
                              [](const SurfaceCell& x, const SurfaceCell& y) { return x.code < y.code; });
                    for (std::size_t i = 0; i < cells.size(); ++i) put(block_start[b] + i, cells[i]);
                } else {
                    std::copy(cells.begin(), cells.end(), gathered.begin() + std::ptrdiff_t(block_start[b]));
                }
            }
        });
        if (!block_runs) {
            std::vector<std::pair<std::uint64_t, std::size_t>> order(n_cells);  // (code, index into gathered)
            for (std::size_t i = 0; i < n_cells; ++i) order[i] = {gathered[i].code, i};
            tbb::parallel_sort(order.begin(), order.end());
            tbb::parallel_for(std::size_t(0), n_cells, [&](std::size_t k) { put(k, gathered[order[k].second]); });
        }
    }
    stats.surface_cells = n_cells;
    stats.seconds_hermite = seconds_since(t0);
    report_progress(options, 0.3);

    // 2. Bottom-up simplification.
    t0 = clock_type::now();
    for (int level = 0; level < top; ++level)
        tree.levels[level + 1] = build_parent_level(grid, field, tree, level, sign, iso, options, counters);
    stats.seconds_octree = seconds_since(t0);
    // The quadrics are done with (the vertices are placed); the dual grid
    // and the polygons need only the tree, so give their memory back.
    for (Level& level : tree.levels) std::vector<CellQuadrics>().swap(level.quadrics);
    report_progress(options, 0.45);

    // 3. Dual grid.
    t0 = clock_type::now();
    const LeafNumbering numbering = number_leaves(tree);
    const std::vector<DualCell> dual = generate_dual_cells(tree, numbering);
    stats.seconds_dual = seconds_since(t0);
    report_progress(options, 0.6);

    // 4. Marching cubes on the dual cells.
    t0 = clock_type::now();
    Mesh mesh = polygonize_dual_cells(tree, numbering, dual, field, options.base.faces, stats);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mesh.points.size(), 4096),
                      [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) mesh.points[i] = xf.indexToWorld(mesh.points[i]);
    });
    stats.seconds_polygons = seconds_since(t0);

    stats.crossing_edges = counters.crossings;
    stats.degenerate_normals = counters.degenerate;
    stats.clamped_vertices = counters.clamped;
    stats.fallback_vertices = counters.fallback;
    stats.merges = counters.merges;
    stats.refused_error = counters.refused_error;
    stats.refused_topology = counters.refused_topology;
    stats.refused_containment = counters.refused_containment;
    stats.refused_balance = counters.refused_balance;
    stats.seconds_total = seconds_since(t_start);
    report_progress(options, 1.0);
    if (stats_out) *stats_out = stats;
    return mesh;
}

template <class GridT>
Mesh extract_grid(const GridT& grid, const AdaptiveOptions& options, AdaptiveStats* stats) {
    validate(options);
    bool below = true;
    switch (options.base.interior) {
    case Interior::below_isovalue: below = true; break;
    case Interior::above_isovalue: below = false; break;
    case Interior::automatic: below = grid.getGridClass() != openvdb::GRID_FOG_VOLUME; break;
    }
    const double sign = below ? 1.0 : -1.0;
    const GridField<GridT> field(grid, sign, options.base.isovalue);
    if (options.base.normals == GridNormals::sharp)
        return run(grid, sign, options.base.isovalue, SharpCrossings{}, field, options, stats);
    return run(grid, sign, options.base.isovalue, LinearCrossings{}, field, options, stats);
}

}  // namespace

Mesh extract_adaptive(const openvdb::FloatGrid& grid, const AdaptiveOptions& options, AdaptiveStats* stats) {
    return extract_grid(grid, options, stats);
}

Mesh extract_adaptive(const openvdb::DoubleGrid& grid, const AdaptiveOptions& options, AdaptiveStats* stats) {
    return extract_grid(grid, options, stats);
}

Mesh extract_adaptive(const openvdb::GridBase& grid, const AdaptiveOptions& options, AdaptiveStats* stats) {
    if (const auto* f = dynamic_cast<const openvdb::FloatGrid*>(&grid)) return extract_adaptive(*f, options, stats);
    if (const auto* d = dynamic_cast<const openvdb::DoubleGrid*>(&grid)) return extract_adaptive(*d, options, stats);
    throw input_error("grid '" + grid.getName() + "' has value type " + grid.valueType() +
                      "; the adaptive extractor needs a float or double grid");
}

Mesh extract_adaptive(const ScalarField& field, const ProceduralSampling& sampling,
                      const AdaptiveOptions& options, AdaptiveStats* stats) {
    validate(options);
    const openvdb::FloatGrid::Ptr grid = sample_field(field, sampling);
    const ProceduralField exact(field, grid->transform());
    return run(*grid, 1.0, 0.0, ExactCrossings{&field, &grid->transform()}, exact, options, stats);
}

}  // namespace pqdc
