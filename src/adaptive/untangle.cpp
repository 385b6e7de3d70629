#include "adaptive/untangle.hpp"

#include "adaptive/repair.hpp"
#include "lattice/untangle.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <string>
#include <utility>

namespace pqdc::adaptive_detail {
namespace {

constexpr std::int64_t kLimit = std::int64_t(1) << kCoordBits;

/// The finest code of the cell at index-space origin `cell`; false outside the frame.
bool finest_code(const Octree& frame, std::int64_t x, std::int64_t y, std::int64_t z, std::uint64_t& code) {
    x -= frame.offset.x();
    y -= frame.offset.y();
    z -= frame.offset.z();
    if (x < 0 || y < 0 || z < 0 || x >= kLimit || y >= kLimit || z >= kLimit) return false;
    code = morton(std::uint32_t(x), std::uint32_t(y), std::uint32_t(z));
    return true;
}

/// Index-space points to world space; faces reversed when the map mirrors.
void map_to_world(const detail::LatticeTransform& xf, Mesh& mesh) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mesh.points.size(), 4096),
                      [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) mesh.points[i] = xf.to_world(mesh.points[i]);
    });
    if (!xf.mirrored) return;
    for (auto& t : mesh.triangles) std::swap(t[1], t[2]);
    for (auto& q : mesh.quads) std::swap(q[1], q[3]);
}

bool finite(const openvdb::Vec3d& p) { return std::isfinite(p.x()) && std::isfinite(p.y()) && std::isfinite(p.z()); }

/// The finest cell holding an index-space point (finite, inside the frame).
openvdb::Coord cell_of(const openvdb::Vec3d& p) {
    return openvdb::Coord(int(std::floor(p.x())), int(std::floor(p.y())), int(std::floor(p.z())));
}

}  // namespace

bool PinnedCells::covers(int level, std::uint64_t code) const {
    const std::uint64_t first = code << (3 * level), end = (code + 1) << (3 * level);
    const auto it = std::lower_bound(codes_.begin(), codes_.end(), first);
    return it != codes_.end() && *it < end;
}

bool PinnedCells::pinned(const Octree& frame, const openvdb::Coord& cell) const {
    std::uint64_t code;
    return finest_code(frame, cell.x(), cell.y(), cell.z(), code) &&
           std::binary_search(codes_.begin(), codes_.end(), code);
}

std::size_t PinnedCells::pin_around(const Octree& frame, const std::vector<openvdb::Vec3d>& corners) {
    std::vector<std::uint64_t> fresh;
    for (const openvdb::Vec3d& p : corners) {
        if (!finite(p)) continue;
        // A corner on a cell face belongs to the cells on both sides; the
        // one-voxel margin covers them.
        const openvdb::Coord c = cell_of(p);
        for (int dz = -1; dz <= 1; ++dz)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    std::uint64_t code;
                    if (finest_code(frame, std::int64_t(c.x()) + dx, std::int64_t(c.y()) + dy,
                                    std::int64_t(c.z()) + dz, code))
                        fresh.push_back(code);
                }
    }
    std::sort(fresh.begin(), fresh.end());
    fresh.erase(std::unique(fresh.begin(), fresh.end()), fresh.end());
    const std::size_t before = codes_.size();
    std::vector<std::uint64_t> merged;
    merged.reserve(before + fresh.size());
    std::set_union(codes_.begin(), codes_.end(), fresh.begin(), fresh.end(), std::back_inserter(merged));
    codes_.swap(merged);
    return codes_.size() - before;
}

std::vector<openvdb::Vec3d> pinned_safe_positions(const Octree& frame, const PinnedCells& pinned,
                                                  const std::vector<openvdb::Vec3d>& index_points, const Mesh& mesh,
                                                  const detail::LatticeTransform& xf) {
    const std::size_t n = mesh.points.size();
    std::vector<openvdb::Vec3d> center(n);  // index space
    std::vector<std::uint8_t> movable(n, 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t v = r.begin(); v != r.end(); ++v) {
            const openvdb::Vec3d& p = index_points[v];
            center[v] = p;
            if (!finite(p)) continue;
            const openvdb::Coord cell = cell_of(p);
            if (!pinned.pinned(frame, cell)) continue;
            center[v] = cell.asVec3d() + openvdb::Vec3d(0.5);
            movable[v] = 1;
        }
    });
    // Vertices sharing a cell (copies where the surface folds through one
    // leaf vertex) would share its center: each is pulled half way towards
    // the mean center of its own neighbours instead, the uniform extractor's
    // rule for cells with several patches.
    std::vector<std::uint32_t> order;
    for (std::uint32_t v = 0; v < n; ++v)
        if (movable[v]) order.push_back(v);
    std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) {
        const openvdb::Vec3d &p = center[a], &q = center[b];
        if (p.x() != q.x()) return p.x() < q.x();
        if (p.y() != q.y()) return p.y() < q.y();
        if (p.z() != q.z()) return p.z() < q.z();
        return a < b;
    });
    std::vector<std::uint8_t> shared(n, 0);
    for (std::size_t i = 1; i < order.size(); ++i)
        if (center[order[i]] == center[order[i - 1]]) shared[order[i]] = shared[order[i - 1]] = 1;
    std::vector<openvdb::Vec3d> sum(n, openvdb::Vec3d(0.0));
    std::vector<int> count(n, 0);
    auto visit = [&](const std::uint32_t* f, int k) {
        for (int i = 0; i < k; ++i) {
            if (!shared[f[i]]) continue;
            for (int j = 0; j < k; ++j)
                if (center[f[j]] != center[f[i]]) {
                    sum[f[i]] += center[f[j]];
                    ++count[f[i]];
                }
        }
    };
    for_each_face(mesh, visit);
    std::vector<openvdb::Vec3d> safe(mesh.points);
    for (std::size_t v = 0; v < n; ++v) {
        if (!movable[v]) continue;
        openvdb::Vec3d c = center[v];
        if (shared[v] && count[v]) c += (sum[v] / double(count[v]) - c) * 0.5;
        safe[v] = xf.to_world(c);
    }
    return safe;
}

void take_rebuild_counters(AdaptiveStats round, AdaptiveStats& stats) {
    round.stages = std::move(stats.stages);
    round.untangle_found = stats.untangle_found;
    round.untangle_rounds = stats.untangle_rounds;
    round.untangle_flips_dropped = stats.untangle_flips_dropped;
    round.bridges_found = stats.bridges_found;
    round.bridge_pinned_cells = stats.bridge_pinned_cells;
    stats = std::move(round);
}

namespace {

/// The state of one untangle stage: the mesh in world space and in index
/// space, the rebuilds' progress range, and the stats that a rebuild resets.
class Repair {
public:
    Repair(Mesh& mesh, const Rebuild& rebuild, const detail::LatticeTransform& xf, const Octree& frame,
           const detail::Progress& progress, detail::UntangleSettings& checking, AdaptiveStats& stats)
        : mesh_(mesh), rebuild_(rebuild), xf_(xf), frame_(frame), progress_(progress), checking_(checking),
          stats_(stats) {}

    /// Maps the mesh (index space) to world space and checks it.
    detail::OffendingCorners map_and_check() {
        index_points_ = mesh_.points;
        map_to_world(xf_, mesh_);
        return detail::find_offending_corners(mesh_, checking_);
    }

    /// Rebuilds report in a shrinking tail of the range from here on; later
    /// checks stay where the last rebuild ended (cancellation points).
    void start_rebuilds() {
        checking_.progress = [this](double) {
            progress_.report(from_);
            return true;
        };
    }

    /// Builds the mesh again (take_rebuild_counters; one more round) and checks it.
    detail::OffendingCorners rebuild(const PinnedCells& pinned, const ShapeLimits& shape) {
        const double to = from_ + (1.0 - from_) / 2;
        AdaptiveStats round;
        mesh_ = rebuild_(pinned, shape, detail::ProgressSpan(progress_, from_, to), round);
        from_ = to;
        take_rebuild_counters(std::move(round), stats_);
        ++stats_.untangle_rounds;
        return map_and_check();
    }

    /// Steps 1 and 2 from the mesh with these offending corners, rebuilding
    /// with the shape steps `shape`, and again from step 1 with the corners
    /// step 2 left offending while that pins new cells, starting from the
    /// cells already `pinned`. Whether it ended free of self-intersections.
    bool refine_and_move(detail::OffendingCorners found, const ShapeLimits& shape, PinnedCells pinned) {
        while (refine(pinned, found, shape)) {
            // Step 2.
            const std::vector<openvdb::Vec3d> safe = pinned_safe_positions(frame_, pinned, index_points_, mesh_, xf_);
            moves = {};
            const bool untangled = detail::untangle(mesh_, safe, xf_.transform->voxelSize()[0], checking_, moves);
            stats_.untangle_moved = moves.moved_vertices;
            stats_.untangle_snapped = moves.snapped_vertices;
            stats_.untangle_rounds += moves.rounds;
            if (untangled) return true;
            // Corners outside the pinned cells (step 2 moves only vertices in
            // them) can keep a pair crossed: on the noisy CSG part at 96
            // cells, 2 pairs sent the run to the uniform fallback.
            found = detail::find_offending_corners(mesh_, checking_);
            if (pinned.pin_around(frame_, unpinned_corners(pinned, found)) == 0) return false;
            found = rebuild(pinned, shape);
        }
        return true;
    }

    double from() const { return from_; }
    detail::UntangleCounters moves;  ///< of the last step 2

private:
    /// The offending corners not in pinned cells, index space. Corners
    /// already in pinned cells are in finest leaves: refining around them
    /// again changes little, so they are left to step 2.
    std::vector<openvdb::Vec3d> unpinned_corners(const PinnedCells& pinned, const detail::OffendingCorners& found) const {
        std::vector<openvdb::Vec3d> corners;
        for (std::uint32_t v : found.vertices) {
            const openvdb::Vec3d& p = index_points_[v];
            if (finite(p) && !pinned.pinned(frame_, cell_of(p))) corners.push_back(p);
        }
        return corners;
    }

    /// Step 1: pins the cells around the offending corners and rebuilds
    /// while that pins new cells. False when the mesh came out free of
    /// self-intersections (nothing left for step 2).
    bool refine(PinnedCells& pinned, detail::OffendingCorners& found, const ShapeLimits& shape) {
        while (!found.none() && pinned.pin_around(frame_, unpinned_corners(pinned, found)) > 0)
            found = rebuild(pinned, shape);
        stats_.untangle_pinned_cells = pinned.size();
        return !found.none();
    }

    Mesh& mesh_;
    std::vector<openvdb::Vec3d> index_points_;
    const Rebuild& rebuild_;
    const detail::LatticeTransform& xf_;
    const Octree& frame_;
    const detail::Progress& progress_;
    detail::UntangleSettings& checking_;
    AdaptiveStats& stats_;
    double from_ = 0.95;
};

/// Whether a point of `mesh` (world space) lies 2^20 voxels or more from
/// the origin, where float's spacing is too coarse for the untangle stage's
/// guarantee (lattice/untangle.cpp's warning).
bool beyond_float_reach(const Mesh& mesh, const detail::LatticeTransform& xf) {
    const openvdb::Vec3d voxel = xf.transform->voxelSize();
    const double reach = double(1 << 20) * std::min({voxel[0], voxel[1], voxel[2]});
    for (const openvdb::Vec3d& p : mesh.points)
        if (std::max({std::fabs(p[0]), std::fabs(p[1]), std::fabs(p[2])}) >= reach) return true;
    return false;
}

}  // namespace

Mesh untangle_adaptive(Mesh mesh, const Rebuild& rebuild, const detail::LatticeTransform& xf, const Octree& frame,
                       const ExtractOptions& options, const PinnedCells& pinned, const UniformFallback& fallback,
                       const detail::Progress& progress, AdaptiveStats& stats) {
    detail::UntangleSettings checking;
    checking.stored = options.stored_precision;
    const detail::ProgressSpan check_span(progress, 0.85, 0.95);
    checking.progress = [&check_span](double f) {
        check_span.report(f);
        return true;
    };
    Repair repair(mesh, rebuild, xf, frame, progress, checking, stats);
    const detail::OffendingCorners found = repair.map_and_check();
    stats.untangle_found = found.pairs + found.degenerate;
    if (found.none()) return mesh;
    repair.start_rebuilds();
    if (repair.refine_and_move(found, ShapeLimits{}, pinned)) return mesh;
    if (stats.angle_flips > 0 || stats.relaxed_vertices > 0) {
        // Once more from the start without the shape steps (relaxation and
        // angle flips): the path of refinements then is the one of the
        // marching-cubes triangles that steps 1 and 2 were designed and
        // measured for.
        stats.untangle_flips_dropped = true;
        const detail::OffendingCorners again = repair.rebuild(pinned, ShapeLimits::none());
        stats.untangle_found = again.pairs + again.degenerate;
        if (repair.refine_and_move(again, ShapeLimits::none(), pinned)) return mesh;
    }
    const detail::UntangleCounters& moves = repair.moves;
    const double from = repair.from();
    // Step 3.
    stats.untangle_unresolved = moves.unresolved;
    ExtractStats uniform;
    mesh = fallback(uniform, from);
    stats.vertices = uniform.vertices;
    stats.triangles = uniform.triangles;
    stats.quads = uniform.quads;
    stats.untangle_fallback = true;
    // Beyond 2^20 voxels from the origin float's spacing is the cause (the
    // uniform mesh's own warning then says so), not the adaptive repair.
    const bool float_spacing =
        options.stored_precision == VertexPrecision::float32 && beyond_float_reach(mesh, xf);
    stats.warnings.push_back("the adaptive mesh kept " + std::to_string(moves.unresolved) +
                             " self-intersections after refinement and repair; the output is the uniform mesh "
                             "(same options without --adaptive)" +
                             (float_spacing ? std::string() : "; please report the input"));
    // The output is the uniform mesh: its warnings are the output's.
    for (std::string& w : uniform.warnings) stats.warnings.push_back(std::move(w));
    return mesh;
}

}  // namespace pqdc::adaptive_detail

