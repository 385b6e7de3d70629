// Uniform dual contouring with probabilistic plane quadrics.
//
// Pipeline (every stage is leaf-parallel and deterministic: per-leaf counts,
// an exclusive prefix sum, then each leaf fills its own slice of
// preallocated arrays, so the output never depends on thread scheduling):
//   A. classify: a "cell tree" (Int64) gets an active voxel for every lattice
//      cell whose 8 corners are active and of mixed sign; its value is the
//      corner sign configuration.
//   B. vertices: per cell-tree leaf, fetch the values around it once, compute
//      each crossing edge's Hermite sample once, sum the plane quadrics of
//      every surface patch in cell-local coordinates and solve. The cell value
//      becomes (index of its first vertex << 8) | configuration.
//   C. faces: each cell owns the three lattice edges leaving its minimum
//      corner; a crossing owned edge whose four cells are all in the cell tree
//      becomes one quad (or two triangles).

#include "pqdc/extract.hpp"

#include "lattice/front_end.hpp"
#include "lattice/value_block.hpp"
#include "lattice/cube.hpp"
#include "pqdc/exceptions.hpp"
#include "pqdc/quadric.hpp"

#include <openvdb/tools/Prune.h>
#include <openvdb/tree/LeafManager.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <new>
#include <optional>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

namespace pqdc {

void validate(const ExtractOptions& o) {
    if (std::isnan(o.sigma_n) || o.sigma_n < 0)
        throw option_error("sigma_n must be >= 0 (or inf for the mass point), got " + std::to_string(o.sigma_n));
    if (!std::isfinite(o.isovalue))
        throw option_error("isovalue must be a finite number, got " + std::to_string(o.isovalue));
    if (!(o.pseudo_inverse_cutoff >= 0 && o.pseudo_inverse_cutoff < 1))
        throw option_error("pseudo_inverse_cutoff must be in [0, 1), got " +
                           std::to_string(o.pseudo_inverse_cutoff));
}

namespace detail {

std::size_t default_memory_limit() {
    const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
    if (pages <= 0 || page <= 0) return std::numeric_limits<std::size_t>::max();
    return std::size_t(double(pages) * double(page) * 0.8);
}

void check_memory(std::size_t needed, const ExtractOptions& options, const char* what) {
    const std::size_t limit = options.memory_limit_bytes ? options.memory_limit_bytes : default_memory_limit();
    if (needed > limit) {
        std::ostringstream s;
        s << "the " << what << " would need about " << (needed >> 20) << " MiB, more than the "
          << (limit >> 20)
          << " MiB allowed; mesh a smaller region or a coarser grid, or raise the memory limit";
        throw resource_error(s.str());
    }
}

LatticeTransform check_transform(const openvdb::math::Transform& xf, const std::string& grid_name) {
    const auto map = xf.baseMap();
    bool similarity = map->isLinear();
    openvdb::Mat3d m;
    if (similarity) {
        try {
            const openvdb::Mat4d full = map->getAffineMap()->getMat4();
            m = full.getMat3();
            for (int i = 0; i < 4; ++i)
                for (int j = 0; j < 4; ++j)
                    if (!std::isfinite(full(i, j))) similarity = false;
        } catch (const std::exception&) {
            // OpenVDB refuses to build maps it cannot invert (tiny voxels).
            throw input_error("grid '" + grid_name + "' has a transform OpenVDB cannot invert (voxel size " +
                              std::to_string(xf.voxelSize()[0]) +
                              "); rescale the grid to a voxel size OpenVDB supports (about 1e-4 or more)");
        }
    }
    if (similarity) {
        // OpenVDB's hasUniformScale() judges det against an absolute
        // tolerance and rejects small voxels; test M^T M = s^2 I relatively.
        const openvdb::Mat3d mtm = m.transpose() * m;
        const double s2 = (mtm(0, 0) + mtm(1, 1) + mtm(2, 2)) / 3.0;
        similarity = s2 > 0 && std::isfinite(s2);
        for (int i = 0; i < 3 && similarity; ++i)
            for (int j = 0; j < 3; ++j)
                if (std::abs(mtm(i, j) - (i == j ? s2 : 0.0)) > 1e-5 * s2) similarity = false;  // OpenVDB maps carry ~1e-6 rounding
    }
    if (!similarity) {
        throw input_error("grid '" + grid_name + "' has a " + map->type() +
                          " transform with non-uniform scale, shear, perspective or non-finite entries; pqdc needs cubic voxels "
                          "(resample the grid, e.g. with openvdb::tools::resampleToMatch)");
    }
    LatticeTransform t;
    t.transform = &xf;
    t.mirrored = m.det() < 0;
    return t;
}

namespace {

// Cell value layout: bits 0-7 corner signs, 8-13 faces whose ambiguity is
// resolved by cutting off outside corners (see join_face), 14-24 the cell's
// first vertex within its leaf's list, 25+ the leaf's index.
using CellTree = openvdb::Int64Tree;
using CellLeaf = CellTree::LeafNodeType;
constexpr int kLeafDim = int(CellLeaf::DIM);
constexpr int kLocalShift = 14;
constexpr int kLeafShift = 25;
static_assert(CellLeaf::SIZE * 4 <= (1 << (kLeafShift - kLocalShift)), "local vertex index must fit");

int group_of_edge(const EdgeGroups* plain, std::int64_t value, int edge) {
    const auto joined = std::uint8_t((value >> 8) & 63);
    if (joined == 0) return plain[value & 255].group[edge];
    return edge_groups(std::uint8_t(value & 255), joined).group[edge];
}

class Progress {
public:
    Progress(const ExtractOptions& o) : callback_(o.progress) {}
    void report(double fraction) const {
        if (callback_ && !callback_(std::min(1.0, std::max(0.0, fraction))))
            throw cancelled_error("extraction cancelled by the caller");
    }
    bool enabled() const { return bool(callback_); }

private:
    const std::function<bool(double)>& callback_;
};

/// Runs body(i) for i in [0, n) in parallel, in chunks, reporting progress
/// from the calling thread between chunks (also the cancellation point).
template <class Body>
void parallel_chunks(std::size_t n, const Progress& progress, double from, double to, const Body& body) {
    const std::size_t chunk = progress.enabled() ? std::max<std::size_t>(256, n / 64) : std::max<std::size_t>(n, 1);
    for (std::size_t start = 0; start < n; start += chunk) {
        const std::size_t end = std::min(n, start + chunk);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(start, end), [&](const tbb::blocked_range<std::size_t>& r) {
            for (std::size_t i = r.begin(); i != r.end(); ++i) body(i);
        });
        progress.report(from + (to - from) * double(end) / double(n));
    }
}

/// Sign configuration of the cell at block point (x, y, z). A cell takes part
/// (domain) when at least one corner is active and no corner is NaN.
std::uint8_t cell_config(const DenseBlock& b, int x, int y, int z, bool& domain) {
    std::uint8_t config = 0;
    unsigned on = 0, nan = 0;
    for (int c = 0; c < 8; ++c) {
        const int cx = x + (c & 1), cy = y + ((c >> 1) & 1), cz = z + ((c >> 2) & 1);
        config |= std::uint8_t(((b.inside_row[cx][cy] >> cz) & 1) << c);
        on |= (b.active_row[cx][cy] >> cz) & 1;
        nan |= (b.nan_row[cx][cy] >> cz) & 1;
    }
    domain = on && !nan;
    return config;
}

struct StageCounters {
    std::uint64_t degenerate = 0;
    std::uint64_t clamped = 0;
    std::uint64_t fallback = 0;
    std::uint64_t multi = 0;
};

/// The cell-tree leaves that may hold a cell with an active corner: the leaf
/// of every source leaf and its seven lower neighbours (a cell's corners lie
/// at or above its minimum corner), and likewise along the boundary shell of
/// active tiles, whose interior is one constant and holds no crossing. The
/// cells themselves are classified from the values in classify_and_place.
template <class TreeT>
openvdb::MaskTree::Ptr candidate_leaves(const TreeT& src, const ExtractOptions& options) {
    // Topology only (64-byte leaves): cell leaves are allocated later, and
    // only where a cell is crossed.
    auto cells = std::make_shared<openvdb::MaskTree>(false);
    constexpr int L = kLeafDim;
    auto touch_with_lower = [&](const openvdb::Coord& origin) {
        for (int n = 0; n < 8; ++n)
            cells->touchLeaf(origin - openvdb::Coord(n & 1 ? L : 0, n & 2 ? L : 0, n & 4 ? L : 0));
    };
    std::uint64_t leaves = src.leafCount();
    std::vector<openvdb::CoordBBox> tiles;
    auto tile_it = src.cbeginValueOn();
    tile_it.setMaxDepth(TreeT::ValueOnCIter::LEAF_DEPTH - 1);  // tiles only: never visit the voxels
    for (auto& it = tile_it; it; ++it) {
        if (it.isVoxelValue()) continue;
        openvdb::CoordBBox box;
        it.getBoundingBox(box);
        tiles.push_back(box);
        const std::uint64_t side = std::uint64_t(box.dim().x() / L) + 1;
        leaves += 6 * side * side;
    }
    // Touching lower neighbours at most doubles the leaves of a band or shell.
    check_memory(leaves * 2 * (sizeof(CellLeaf) + CellLeaf::SIZE * sizeof(std::int64_t)), options,
                 "cell classification");
    for (auto it = src.cbeginLeaf(); it; ++it) touch_with_lower(it->origin());
    for (const auto& box : tiles) {
        const openvdb::Coord lo = box.min(), hi = box.max();
        for (int a = 0; a < 3; ++a) {
            const int b = (a + 1) % 3, c = (a + 2) % 3;
            for (int side : {lo[a], hi[a]})
                for (int i = lo[b]; i <= hi[b]; i += L)
                    for (int j = lo[c]; j <= hi[c]; j += L) {
                        openvdb::Coord p;
                        p[a] = side;
                        p[b] = i;
                        p[c] = j;
                        touch_with_lower(p & ~(L - 1));
                    }
        }
    }
    return cells;
}

struct GroupSum {
    quadric<double> q;
    mass_point<double> mp;
};

/// Bit e set: edge e of the configuration joins corners of different sides.
constexpr std::array<std::uint16_t, 256> make_crossing_edges() {
    std::array<std::uint16_t, 256> t{};
    for (int c = 0; c < 256; ++c)
        for (int e = 0; e < 12; ++e)
            if (((c >> edge_start_corner(e)) ^ (c >> edge_end_corner(e))) & 1) t[c] |= std::uint16_t(1u << e);
    return t;
}
constexpr std::array<std::uint16_t, 256> kCrossingEdges = make_crossing_edges();
constexpr int kEdgeStart[12] = {edge_start_corner(0), edge_start_corner(1), edge_start_corner(2),  edge_start_corner(3),
                                edge_start_corner(4), edge_start_corner(5), edge_start_corner(6),  edge_start_corner(7),
                                edge_start_corner(8), edge_start_corner(9), edge_start_corner(10), edge_start_corner(11)};

openvdb::Vec3d solve_vertex(const GroupSum& g, const ExtractOptions& o, StageCounters& n) {
    // The mass point (three divisions) only where it is the answer or the start.
    auto mass_or_center = [&g] {
        const std::optional<vec3<double>> mass = g.mp.point();
        return mass ? *mass : vec3<double>{0.5, 0.5, 0.5};
    };
    vec3<double> x;
    if (std::isinf(o.sigma_n)) {
        x = mass_or_center();  // mass point limit
    } else if (o.sigma_n == 0.0) {
        x = minimizer_pseudo_inverse(g.q, mass_or_center(), o.pseudo_inverse_cutoff).point;
    } else if (const auto s = minimizer_positive_definite(g.q)) {
        x = *s;
    } else {
        x = mass_or_center();
        ++n.fallback;
    }
    if (!is_finite(x)) {
        const std::optional<vec3<double>> mass = g.mp.point();
        x = mass ? *mass : vec3<double>{0.5, 0.5, 0.5};
        ++n.fallback;
    }
    if (o.containment == Containment::clamp_to_cell) {
        // Keep a hair inside so vertices of neighbouring cells never coincide.
        constexpr double lo = 1e-4, hi = 1.0 - 1e-4;
        bool outside = false;
        for (int a = 0; a < 3; ++a) {
            if (x[a] < 0.0 || x[a] > 1.0) outside = true;
            x[a] = std::min(hi, std::max(lo, x[a]));
        }
        if (outside) ++n.clamped;
    }
    return {x.x, x.y, x.z};
}

/// Stages A and B in one pass per cell-tree leaf, so the leaf's values are
/// fetched once: classify the candidate cells (configuration and face
/// ambiguity choices), then compute each crossing edge's Hermite sample once
/// and solve every surface patch's quadric in cell-local coordinates. Each
/// leaf's vertices go to its own list; the lists are concatenated in leaf
/// order afterwards, so the order never depends on scheduling.
template <class TreeT, class Oracle>
void classify_and_place(const TreeT& src, const Signing& signing, const Oracle& oracle,
                        const LatticeTransform& xf, const std::vector<openvdb::Coord>& leaves,
                        const ExtractOptions& options, const Progress& progress,
                        std::vector<std::unique_ptr<CellLeaf>>& cell_leaves,
                        std::vector<std::vector<openvdb::Vec3d>>& leaf_points, std::vector<std::uint32_t>& leaf_faces,
                        std::vector<std::uint32_t>& leaf_incidences, ExtractStats& stats) {
    constexpr int E = kLeafDim + 1;  // edge start points cached per leaf: [0, 8]^3
    // Not registered with the tree (the tree is const here): cheap to create.
    using Accessor = openvdb::tree::ValueAccessor<const TreeT, /*IsSafe=*/false>;
    struct Scratch {
        DenseBlock block;
        DenseBlock wide;  // Oracle::kMargin == 2: the same points with two of margin, for its stencils
        std::vector<Crossing> crossing = std::vector<Crossing>(E * E * E * 3);
        std::vector<std::uint32_t> stamp = std::vector<std::uint32_t>(E * E * E * 3, 0);
        std::uint32_t generation = 0;
        StageCounters counters;
        std::uint64_t non_finite = 0;
        std::uint64_t cells = 0;
        std::optional<Accessor> acc;  // kept across leaves: neighbouring leaves share nodes
    };
    const double sigma_n = std::isinf(options.sigma_n) ? 0.0 : options.sigma_n;
    tbb::enumerable_thread_specific<Scratch> scratch;
    parallel_chunks(leaves.size(), progress, 0.0, 0.8, [&](std::size_t li) {
        const openvdb::Coord origin = leaves[li];
        CellLeaf* leaf = nullptr;  // allocated at the first crossed cell
        Scratch& s = scratch.local();
        DenseBlock& b = s.block;
        if (!s.acc) s.acc.emplace(src);
        const Accessor& acc = *s.acc;
        if (!corners_may_cross(acc, origin, signing)) return;
        // One point below (lower neighbours, gradient stencil), two above
        // (corners, upper neighbours, gradient stencil).
        fetch_block(acc, origin - openvdb::Coord(1), kLeafDim + 3, signing, b);
        constexpr int D = kLeafDim + 3;
        unsigned block_all = 0xffffu, block_any = 0, block_nan = 0;
        for (int x = 0; x < D; ++x)
            for (int y = 0; y < D; ++y) {
                block_all &= b.inside_row[x][y];
                block_any |= b.inside_row[x][y];
                block_nan |= b.nan_row[x][y];
            }
        const unsigned full = (1u << D) - 1;
        if (((block_all & full) == full || (block_any & full) == 0) && !block_nan)
            return;  // one sign everywhere: no cell here is crossed (the leaf keeps no active value)
        if constexpr (Oracle::kMargin == 2) fetch_block(acc, origin - openvdb::Coord(2), kLeafDim + 5, signing, s.wide);
        const DenseBlock& hermite_block = Oracle::kMargin == 2 ? s.wide : b;
        for (int x = 1; x <= kLeafDim; ++x)
            for (int y = 1; y <= kLeafDim; ++y)  // active NaN points owned by this leaf, each counted once
                s.non_finite += unsigned(__builtin_popcount(unsigned(b.nan_row[x][y] & b.active_row[x][y]) & 0x1feu));
        if (++s.generation == 0) {
            std::fill(s.stamp.begin(), s.stamp.end(), 0u);
            s.generation = 1;
        }
        const auto& in_row = b.inside_row;
        const auto& on_row = b.active_row;
        const auto& nan_row = b.nan_row;
        std::vector<openvdb::Vec3d>& points = leaf_points[li];
        // usable[x + 1][y + 1] bit z + 1: cell (x, y, z) has an active corner
        // and no NaN corner, for x, y, z in [-1, 7] (this leaf's cells and its
        // lower neighbours', which decide whether an owned edge gets a face).
        std::uint16_t usable_row[kLeafDim + 1][kLeafDim + 1];
        for (int X = 0; X <= kLeafDim; ++X)
            for (int Y = 0; Y <= kLeafDim; ++Y) {
                const unsigned on = on_row[X][Y] | on_row[X + 1][Y] | on_row[X][Y + 1] | on_row[X + 1][Y + 1];
                const unsigned nan = nan_row[X][Y] | nan_row[X + 1][Y] | nan_row[X][Y + 1] | nan_row[X + 1][Y + 1];
                usable_row[X][Y] = std::uint16_t((on | (on >> 1)) & ~(nan | (nan >> 1)) & 0x1ffu);
            }
        auto usable = [&](int x, int y, int z) { return (usable_row[x + 1][y + 1] >> (z + 1)) & 1; };
        std::uint32_t faces = 0, incidences = 0;
        const EdgeGroups* plain = plain_edge_groups();
        for (int x = 0; x < kLeafDim; ++x)
            for (int y = 0; y < kLeafDim; ++y) {
                // Which cells of this z-row are crossed, have an active corner
                // and no NaN corner: 8 cells at a time.
                auto quad = [&](const std::uint16_t(&r)[DenseBlock::kMaxDim][DenseBlock::kMaxDim], bool conj) {
                    const int X = x + 1, Y = y + 1;
                    return conj ? std::uint16_t(r[X][Y] & r[X + 1][Y] & r[X][Y + 1] & r[X + 1][Y + 1])
                                : std::uint16_t(r[X][Y] | r[X + 1][Y] | r[X][Y + 1] | r[X + 1][Y + 1]);
                };
                const std::uint16_t in_all = quad(in_row, true), in_any = quad(in_row, false);
                const unsigned crossed = unsigned(in_any | (in_any >> 1)) & ~unsigned(in_all & (in_all >> 1));
                unsigned cells_in_row = ((crossed & usable_row[x + 1][y + 1]) >> 1) & 0xffu;  // bit z: cell (x, y, z)
                while (cells_in_row) {
                    const int z = __builtin_ctz(cells_in_row);
                    cells_in_row &= cells_in_row - 1;
                    const openvdb::Coord local(x, y, z);
                    const openvdb::Coord l = local + openvdb::Coord(1);
                    // Corner c = dx + 2 dy + 4 dz: row (dx, dy) gives bits c and c + 4.
                    auto two = [&](int dx, int dy) {
                        const unsigned r = unsigned(in_row[l.x() + dx][l.y() + dy]) >> l.z();
                        return ((r & 1u) | ((r & 2u) << 3)) << (dx + 2 * dy);
                    };
                    const std::uint8_t config = std::uint8_t(two(0, 0) | two(1, 0) | two(0, 1) | two(1, 1));
                    // Owned edges (from the minimum corner) that cross get a face
                    // when the three other cells around them take part.
                    for (int axis = 0; axis < 3; ++axis) {
                        if (((config >> (1 << axis)) ^ config) & 1) {
                            const int u = (axis + 1) % 3, v = (axis + 2) % 3;
                            int cu[3] = {x, y, z}, cv[3] = {x, y, z}, cuv[3] = {x, y, z};
                            cu[u] -= 1;
                            cv[v] -= 1;
                            cuv[u] -= 1;
                            cuv[v] -= 1;
                            if (usable(cu[0], cu[1], cu[2]) && usable(cv[0], cv[1], cv[2]) &&
                                usable(cuv[0], cuv[1], cuv[2]))
                                ++faces;
                        }
                    }
                    ++s.cells;
                    incidences += std::uint32_t(__builtin_popcount(kCrossingEdges[config]));
                    std::uint8_t joined = 0;
                    for (unsigned tunnels = tunnel_faces(config); tunnels; tunnels &= tunnels - 1) {
                        const int face = __builtin_ctz(tunnels);
                        const int axis = face >> 1, side = face & 1;
                        openvdb::Coord n = l;
                        n[axis] += side ? 1 : -1;
                        bool ndomain;
                        const std::uint8_t nconfig = cell_config(b, n.x(), n.y(), n.z(), ndomain);
                        if (ndomain && (side ? join_face(config, nconfig, axis) : join_face(nconfig, config, axis)))
                            joined |= std::uint8_t(1u << face);
                    }
                    const EdgeGroups groups = joined ? edge_groups(config, joined) : plain[config];
                    // Only the patches there are, not four zeroed sums.
                    alignas(GroupSum) unsigned char sum_storage[4 * sizeof(GroupSum)];
                    GroupSum* sums = reinterpret_cast<GroupSum*>(sum_storage);
                    for (int g = 0; g < groups.count; ++g) new (&sums[g]) GroupSum();
                    for (unsigned edges = kCrossingEdges[config]; edges; edges &= edges - 1) {
                        const int e = __builtin_ctz(edges);
                        const int g = groups.group[e];
                        const int corner = kEdgeStart[e], axis = e >> 2;
                        const int ex = local.x() + (corner & 1), ey = local.y() + ((corner >> 1) & 1),
                                  ez = local.z() + ((corner >> 2) & 1);
                        const int key = ((ex * E + ey) * E + ez) * 3 + axis;
                        if (s.stamp[key] != s.generation) {
                            s.stamp[key] = s.generation;
                            constexpr int m = Oracle::kMargin;
                            s.crossing[key] = oracle(hermite_block, ex + m, ey + m, ez + m, axis);
                            const bool owned = ex < kLeafDim && ey < kLeafDim && ez < kLeafDim;
                            if (owned && s.crossing[key].normal == vec3<double>{0, 0, 0}) ++s.counters.degenerate;
                        }
                        const Crossing& c = s.crossing[key];
                        vec3<double> p{double(corner & 1), double((corner >> 1) & 1), double((corner >> 2) & 1)};
                        p[axis] += c.t;
                        sums[g].q += quadric<double>::probabilistic_plane<quadric_terms::a_b>(p, c.normal, 0.0, sigma_n);
                        sums[g].mp.add(p);
                    }
                    if (groups.count > 1) ++s.counters.multi;
                    const openvdb::Coord cell = origin + local;
                    const openvdb::Vec3d cell_min = cell.asVec3d();
                    const std::int64_t first = std::int64_t(points.size());
                    for (int g = 0; g < groups.count; ++g)
                        points.push_back(xf.to_world(cell_min + solve_vertex(sums[g], options, s.counters)));
                    if (!leaf) {
                        cell_leaves[li] = std::make_unique<CellLeaf>(origin, std::int64_t(0), false);
                        leaf = cell_leaves[li].get();
                    }
                    leaf->setValueOn(CellLeaf::coordToOffset(cell),
                                     std::int64_t(config) | (std::int64_t(joined) << 8) | (first << kLocalShift) |
                                         (std::int64_t(li) << kLeafShift));
                }
            }
        leaf_faces[li] = faces;
        leaf_incidences[li] = incidences;
    });
    for (const Scratch& s : scratch) {
        stats.degenerate_normals += s.counters.degenerate;
        stats.clamped_vertices += s.counters.clamped;
        stats.fallback_vertices += s.counters.fallback;
        stats.multi_vertex_cells += s.counters.multi;
        stats.non_finite_values += s.non_finite;
        stats.active_cells += s.cells;
    }
}

/// Stage C.
void build_faces(const CellTree& cells, const std::vector<CellLeaf*>& leaves,
                 const std::vector<std::uint64_t>& leaf_first, const std::vector<std::uint32_t>& leaf_faces,
                 const std::vector<std::uint32_t>& leaf_incidences, const LatticeTransform& xf,
                 const ExtractOptions& options, const Progress& progress, Mesh& mesh, ExtractStats& stats) {
    const EdgeGroups* plain = plain_edge_groups();
    const bool flip = xf.mirrored;
    std::vector<std::uint64_t> first(leaves.size() + 1, 0);
    std::vector<std::uint64_t> open(leaves.size(), 0);

    // visit(leaf, emit) calls emit(v0, v1, v2, v3) for each face, in a fixed order.
    auto visit = [&](std::size_t li, auto&& emit) {
        openvdb::tree::ValueAccessor<const CellTree, /*IsSafe=*/false> acc(cells);
        const CellLeaf& leaf = *leaves[li];
        for (auto it = leaf.cbeginValueOn(); it; ++it) {
            const std::int64_t value = *it;
            const std::uint8_t config = std::uint8_t(value & 255);
            const bool inside0 = config & 1;
            const openvdb::Coord c = it.getCoord();
            for (int axis = 0; axis < 3; ++axis) {
                if (inside0 == bool((config >> (1 << axis)) & 1)) continue;
                const int u = (axis + 1) % 3, v = (axis + 2) % 3;
                openvdb::Coord cu = c, cv = c, cuv = c;
                cu[u] -= 1;
                cv[v] -= 1;
                cuv[u] -= 1;
                cuv[v] -= 1;
                std::int64_t vu, vv, vuv;
                // Most neighbours live in the same leaf: skip the accessor for them.
                auto probe = [&](const openvdb::Coord& p, std::int64_t& out) {
                    if ((p & ~(kLeafDim - 1)) == leaf.origin())
                        return leaf.probeValue(p, out);
                    return acc.probeValue(p, out);
                };
                if (!probe(cu, vu) || !probe(cv, vv) || !probe(cuv, vuv)) continue;
                auto vertex = [&](std::int64_t cellvalue, int edge) {
                    const std::uint64_t v = std::uint64_t(cellvalue);
                    return openvdb::Index32(leaf_first[v >> kLeafShift] +
                                            ((v >> kLocalShift) & ((1u << (kLeafShift - kLocalShift)) - 1)) +
                                            std::uint64_t(group_of_edge(plain, cellvalue, edge)));
                };
                // Edge ids of this lattice edge as seen from each of the four cells.
                const int e = 4 * axis;
                openvdb::Index32 q[4] = {vertex(vuv, e + 3), vertex(vv, e + 2), vertex(value, e), vertex(vu, e + 1)};
                // Counter-clockwise seen from +axis; reversed when inside lies at the far end.
                if (!inside0 != flip) std::swap(q[1], q[3]);
                // Outward is +axis when the inside lies at the edge's start.
                emit(q, axis, inside0);
            }
        }
    };

    // Crossings without a face: each is counted by the first of its four
    // cells (owner, -u, -v, -u-v) that exists, whether or not that is the owner.
    auto count_open = [&](std::size_t li) -> std::uint64_t {
        if (!leaves[li]) return 0;
        openvdb::tree::ValueAccessor<const CellTree, /*IsSafe=*/false> acc(cells);
        std::uint64_t n = 0;
        const CellLeaf& leaf = *leaves[li];
        for (auto it = leaf.cbeginValueOn(); it; ++it) {
            const std::uint8_t config = std::uint8_t(*it & 255);
            for (int e = 0; e < 12; ++e) {
                const int c0 = edge_start_corner(e), c1 = edge_end_corner(e);
                if (((config >> c0) & 1) == ((config >> c1) & 1)) continue;
                const int axis = e >> 2, u = (axis + 1) % 3, v = (axis + 2) % 3;
                openvdb::Coord owner = it.getCoord();
                owner[u] += e & 1;
                owner[v] += (e >> 1) & 1;
                bool present[4];
                int self = -1;
                for (int k = 0; k < 4; ++k) {
                    openvdb::Coord cell = owner;
                    cell[u] -= k & 1;
                    cell[v] -= (k >> 1) & 1;
                    if (cell == it.getCoord()) {
                        present[k] = true;
                        self = k;
                    } else {
                        present[k] = acc.isValueOn(cell);
                    }
                }
                const bool all = present[0] && present[1] && present[2] && present[3];
                int first_present = 0;
                while (!present[first_present]) ++first_present;
                if (!all && first_present == self) ++n;
            }
        }
        return n;
    };
    // Faces and (cell, crossing edge) incidences per leaf were counted during
    // classification (same test as the probes below, on the value block), so
    // there is no counting pass. Exactly 4 incidences per face when every
    // crossing has its four cells, the common case that needs no more work.
    std::uint64_t total_incidences = 0;
    for (std::size_t i = 0; i < leaves.size(); ++i) {
        first[i + 1] = first[i] + leaf_faces[i];
        total_incidences += leaf_incidences[i];
    }
    const std::uint64_t nquads = first.back();
    const bool has_open = total_incidences != 4 * nquads;
    if (has_open) {
        tbb::parallel_for(std::size_t(0), leaves.size(), [&](std::size_t li) { open[li] = count_open(li); });
        for (auto b : open) stats.boundary_crossings += b;
    }
    stats.crossing_edges = nquads + stats.boundary_crossings;
    progress.report(0.85);

    const bool tris = options.faces == FaceType::triangles;
    openvdb::Vec3d axis_world[3];
    for (int a = 0; a < 3; ++a) {
        openvdb::Vec3d e(0.0);
        e[a] = 1.0;
        axis_world[a] = xf.to_world(e) - xf.to_world(openvdb::Vec3d(0.0));
    }
    check_memory(nquads * (tris ? 2 * sizeof(openvdb::Vec3I) : sizeof(openvdb::Vec4I)), options, "face list");
    if (tris) mesh.triangles.resize(2 * nquads);
    else mesh.quads.resize(nquads);
    parallel_chunks(leaves.size(), progress, 0.85, 1.0, [&](std::size_t li) {
        if (first[li + 1] == first[li]) return;
        std::uint64_t k = first[li];
        visit(li, [&](const openvdb::Index32* q, int axis, bool plus) {
            if (!tris) {
                mesh.quads[k++] = openvdb::Vec4I(q[0], q[1], q[2], q[3]);
                return;
            }
            const auto& P = mesh.points;
            const openvdb::Vec3d out = plus ? axis_world[axis] : -axis_world[axis];
            const double out_len = axis_world[axis].length();
            // Per triangle: cosine of its normal to the outward axis, and its
            // shape quality 2 area / (longest side)^2 (a smooth stand-in for
            // the minimum angle: both vanish together, one sqrt instead of
            // three).
            struct Tri {
                double facing, quality;
            };
            auto tri = [&](unsigned a, unsigned b, unsigned c) {
                const openvdb::Vec3d ab = P[b] - P[a], bc = P[c] - P[b], ca = P[a] - P[c];
                const openvdb::Vec3d n = ab.cross(-ca);
                const double len = n.length();
                const double longest = std::max({ab.lengthSqr(), bc.lengthSqr(), ca.lengthSqr()});
                if (!(len > 0.0)) return Tri{-1.0, 0.0};
                return Tri{n.dot(out) / (len * out_len), len / longest};
            };
            const Tri ac1 = tri(q[0], q[1], q[2]), ac2 = tri(q[0], q[2], q[3]);
            const Tri bd1 = tri(q[0], q[1], q[3]), bd2 = tri(q[1], q[2], q[3]);
            // Prefer a split whose triangles both face the way the surface
            // crosses this edge (no fold-over); among those, the better shape.
            const double ac_facing = std::min(ac1.facing, ac2.facing), bd_facing = std::min(bd1.facing, bd2.facing);
            const bool use_bd = (ac_facing <= 0.0 || bd_facing <= 0.0)
                                    ? bd_facing > ac_facing
                                    : std::min(bd1.quality, bd2.quality) > std::min(ac1.quality, ac2.quality);
            if (use_bd) {
                mesh.triangles[2 * k] = openvdb::Vec3I(q[0], q[1], q[3]);
                mesh.triangles[2 * k + 1] = openvdb::Vec3I(q[1], q[2], q[3]);
            } else {
                mesh.triangles[2 * k] = openvdb::Vec3I(q[0], q[1], q[2]);
                mesh.triangles[2 * k + 1] = openvdb::Vec3I(q[0], q[2], q[3]);
            }
            ++k;
        });
    });
    stats.quads = tris ? 0 : nquads;
    stats.triangles = tris ? 2 * nquads : 0;

    if (has_open) {
        // A cell whose crossings all lack a neighbour got a vertex no face
        // uses; drop such vertices, keeping the order of the others.
        std::vector<std::uint8_t> used(mesh.points.size(), 0);
        for (const auto& t : mesh.triangles) used[t[0]] = used[t[1]] = used[t[2]] = 1;
        for (const auto& q : mesh.quads) used[q[0]] = used[q[1]] = used[q[2]] = used[q[3]] = 1;
        std::vector<openvdb::Index32> remap(mesh.points.size());
        openvdb::Index32 kept = 0;
        for (std::size_t i = 0; i < mesh.points.size(); ++i) {
            remap[i] = kept;
            if (used[i]) mesh.points[kept++] = mesh.points[i];
        }
        if (kept != mesh.points.size()) {
            mesh.points.resize(kept);
            mesh.points.shrink_to_fit();
            tbb::parallel_for(std::size_t(0), mesh.triangles.size(), [&](std::size_t i) {
                for (int j = 0; j < 3; ++j) mesh.triangles[i][j] = remap[mesh.triangles[i][j]];
            });
            tbb::parallel_for(std::size_t(0), mesh.quads.size(), [&](std::size_t i) {
                for (int j = 0; j < 4; ++j) mesh.quads[i][j] = remap[mesh.quads[i][j]];
            });
            stats.vertices = kept;
        }
    }
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

template <class TreeT, class Oracle>
Mesh extract_tree(const TreeT& tree, const Signing& signing, const Oracle& oracle, const LatticeTransform& xf,
                  const ExtractOptions& options, ExtractStats* stats_out) {
    validate(options);
    const Progress progress(options);
    ExtractStats stats;
    const auto t0 = std::chrono::steady_clock::now();
    std::vector<openvdb::Coord> origins;
    {
        const openvdb::MaskTree::Ptr candidates = candidate_leaves(tree, options);
        std::vector<const openvdb::MaskTree::LeafNodeType*> mask_leaves;
        mask_leaves.reserve(candidates->leafCount());
        candidates->getNodes(mask_leaves);
        origins.reserve(mask_leaves.size());
        for (const auto* l : mask_leaves) origins.push_back(l->origin());
    }
    if (origins.size() >= (std::size_t(1) << (63 - kLeafShift)))
        throw resource_error("the volume has too many leaf nodes to mesh in one piece; mesh it in parts");
    stats.seconds_classify = seconds_since(t0);

    const auto t1 = std::chrono::steady_clock::now();
    std::vector<std::vector<openvdb::Vec3d>> leaf_points(origins.size());
    std::vector<std::uint32_t> leaf_faces(origins.size(), 0), leaf_incidences(origins.size(), 0);
    std::vector<std::unique_ptr<CellLeaf>> cell_leaves(origins.size());
    classify_and_place(tree, signing, oracle, xf, origins, options, progress, cell_leaves, leaf_points, leaf_faces,
                       leaf_incidences, stats);
    // Leaves keep their candidate index (vertex offsets, face order).
    auto cells = std::make_shared<CellTree>(std::int64_t(0));
    std::vector<CellLeaf*> leaves(origins.size(), nullptr);
    {
        openvdb::tree::ValueAccessor<CellTree, false> acc(*cells);
        for (std::size_t i = 0; i < origins.size(); ++i)
            if (cell_leaves[i]) {
                leaves[i] = cell_leaves[i].get();
                acc.addLeaf(cell_leaves[i].release());
            }
    }
    std::vector<std::uint64_t> first(leaves.size() + 1, 0);
    for (std::size_t i = 0; i < leaves.size(); ++i) first[i + 1] = first[i] + leaf_points[i].size();
    const std::uint64_t nverts = first.back();
    if (nverts >= (std::uint64_t(1) << 32))
        throw resource_error("the mesh would have " + std::to_string(nverts) +
                             " vertices, more than 32-bit face indices can address; mesh the volume in parts");
    check_memory(nverts * (2 * sizeof(openvdb::Vec3d) + 2 * 3 * sizeof(openvdb::Vec3I)), options, "mesh");
    Mesh mesh;
    mesh.points.resize(nverts);
    tbb::parallel_for(std::size_t(0), leaves.size(), [&](std::size_t i) {
        std::copy(leaf_points[i].begin(), leaf_points[i].end(), mesh.points.begin() + std::ptrdiff_t(first[i]));
        std::vector<openvdb::Vec3d>().swap(leaf_points[i]);
    });
    stats.vertices = nverts;
    stats.seconds_vertices = seconds_since(t1);

    const auto t2 = std::chrono::steady_clock::now();
    build_faces(*cells, leaves, first, leaf_faces, leaf_incidences, xf, options, progress, mesh, stats);
    stats.seconds_faces = seconds_since(t2);
    stats.seconds_total = seconds_since(t0);
    if (stats_out) *stats_out = stats;
    return mesh;
}

namespace {

// kMargin: lattice points of the block below a leaf's first cell that the
// oracle's stencils need (1: central differences; 2: ENO).
struct LinearOracle {
    static constexpr int kMargin = 1;
    Crossing operator()(const DenseBlock& b, int x, int y, int z, int axis) const {
        return linear_crossing(b, x, y, z, axis);
    }
};

struct SharpOracle {
    static constexpr int kMargin = 2;
    Crossing operator()(const DenseBlock& b, int x, int y, int z, int axis) const {
        return sharp_crossing(b, x, y, z, axis);
    }
};

/// Crossings by root finding on the exact field along the edge; normals from
/// the analytic gradient, mapped to index space.
struct ExactOracle {
    static constexpr int kMargin = 1;
    const ScalarField& field;
    const openvdb::math::Transform& xf;

    Crossing operator()(const DenseBlock& b, int x, int y, int z, int axis) const {
        const openvdb::Coord p0 = b.min + openvdb::Coord(x, y, z);
        openvdb::Vec3d i0 = p0.asVec3d(), i1 = i0;
        i1[axis] += 1.0;
        const openvdb::Vec3d w0 = xf.indexToWorld(i0), w1 = xf.indexToWorld(i1);
        double f0 = field.value(w0), f1 = field.value(w1);
        Crossing c;
        if ((f0 < 0) != (f1 < 0) && std::isfinite(f0) && std::isfinite(f1)) {
            c.t = root_on_unit_interval([&](double t) { return field.value(w0 + (w1 - w0) * t); }, f0, f1, 1e-12);
        } else {
            // The float samples disagree with the exact field near a tangency;
            // stay consistent with the sampled signs.
            c.t = linear_crossing(b, x, y, z, axis).t;
        }
        const openvdb::Vec3d w = w0 + (w1 - w0) * c.t;
        const openvdb::Vec3d g = xf.baseMap()->applyJT(field.gradient(w));
        c.normal = normalized_or_zero({g.x(), g.y(), g.z()});
        return c;
    }
};

template <class GridT>
Mesh extract_grid(const GridT& grid, const ExtractOptions& options, ExtractStats* stats) {
    validate(options);
    const LatticeTransform xf = check_transform(grid.transform(), grid.getName());
    Signing signing;
    signing.isovalue = options.isovalue;
    Interior interior = options.interior;
    if (interior == Interior::automatic)
        interior = grid.getGridClass() == openvdb::GRID_FOG_VOLUME ? Interior::above_isovalue : Interior::below_isovalue;
    signing.sign = interior == Interior::above_isovalue ? -1.0 : 1.0;
    if (options.normals == GridNormals::sharp)
        return extract_tree(grid.tree(), signing, SharpOracle{}, xf, options, stats);
    return extract_tree(grid.tree(), signing, LinearOracle{}, xf, options, stats);
}

}  // namespace
}  // namespace detail

Mesh extract(const openvdb::FloatGrid& grid, const ExtractOptions& options, ExtractStats* stats) {
    return detail::extract_grid(grid, options, stats);
}

Mesh extract(const openvdb::DoubleGrid& grid, const ExtractOptions& options, ExtractStats* stats) {
    return detail::extract_grid(grid, options, stats);
}

Mesh extract(const openvdb::GridBase& grid, const ExtractOptions& options, ExtractStats* stats) {
    if (const auto* f = dynamic_cast<const openvdb::FloatGrid*>(&grid)) return extract(*f, options, stats);
    if (const auto* d = dynamic_cast<const openvdb::DoubleGrid*>(&grid)) return extract(*d, options, stats);
    throw input_error("grid '" + grid.getName() + "' holds " + grid.valueType() +
                      " values; pqdc meshes scalar float or double grids (convert it, or pick another grid with --grid)");
}

Mesh extract(const ScalarField& field, const ProceduralSampling& sampling, const ExtractOptions& options,
             ExtractStats* stats) {
    validate(options);
    const openvdb::FloatGrid::Ptr grid = sample_field(field, sampling);
    const detail::LatticeTransform xf = detail::check_transform(grid->transform(), "procedural");
    detail::Signing signing;  // sampled values are f itself: inside negative, surface at 0
    return detail::extract_tree(grid->tree(), signing, detail::ExactOracle{field, grid->transform()}, xf, options,
                                stats);
}

}  // namespace pqdc
