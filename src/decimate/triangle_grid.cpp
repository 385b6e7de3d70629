// TriangleGrid: a loose, multi-level grid over bounding boxes, rebuilt once
// per decimation pass (the faces move everywhere in a pass, so updating it
// would cost more than building it).
//
// Each box is listed exactly once: in the cell of its lower corner, at the
// finest level whose cells are larger than the box along every axis. A
// query therefore reports each box at most once with no stamps, and scans
// its own cell range widened by one cell downwards (a box listed in the cell
// below can reach up into the range, never further). Cells are kept per
// (x, y) row, sorted by z, so a query reads one contiguous run per row.
// Compared with listing a box in every cell it touches (the former grid:
// 1-8 entries of 24 bytes per face), this stores 8 bytes per face and builds
// with two counting sorts per level.

#include "decimate_internal.hpp"

#include <algorithm>
#include <cmath>

namespace pqdc::decimate_detail {
namespace {

constexpr double kFit = 0.999;            // a box fits a level when it spans at most this many cells
constexpr double kMaxCells = 1 << 21;     // per axis, so cell indices stay far inside 32 bits
constexpr double kLevelGrowth = 4;        // cell size ratio between levels
constexpr int kMaxLevels = 24;            // 4^24 > 2^21 x 2^21: the last level always fits every box
constexpr double kListedQuantile = 0.99;  // the finest level holds at least this share of the boxes

}  // namespace

void triangle_boxes(const std::vector<vec>& pos, const std::vector<Tri>& tris, std::vector<BoxPair>& boxes) {
    boxes.resize(tris.size());
    parallel_ranges(tris.size(), 4096, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i)
            boxes[i] = triangle_box(pos[tris[i][0]], pos[tris[i][1]], pos[tris[i][2]]);
    });
}

inline bool TriangleGrid::Level::fits(const BoxPair& b, const vec& lo) const {
    return (b[1].x - lo.x) * inv_h - (b[0].x - lo.x) * inv_h <= kFit &&
           (b[1].y - lo.y) * inv_h - (b[0].y - lo.y) * inv_h <= kFit &&
           (b[1].z - lo.z) * inv_h - (b[0].z - lo.z) * inv_h <= kFit;
}

void TriangleGrid::build(std::vector<BoxPair>& boxes) {
    boxes_.swap(boxes);
    active_.clear();
    const std::size_t n = boxes_.size();
    if (n == 0) return;
    vec lo = boxes_[0][0], hi = boxes_[0][1];
    scratch_extent_.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
        const BoxPair& b = boxes_[i];
        lo = component_min(lo, b[0]);
        hi = component_max(hi, b[1]);
        scratch_extent_[i] = std::max({b[1].x - b[0].x, b[1].y - b[0].y, b[1].z - b[0].z});
    }
    lo_ = lo;
    const double span = std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z});
    const auto q = scratch_extent_.begin() + std::ptrdiff_t(double(n - 1) * kListedQuantile);
    std::nth_element(scratch_extent_.begin(), q, scratch_extent_.end());
    double h = std::max(*q / kFit * 1.001, span / (kMaxCells - 2));
    if (!(h > 0)) h = span > 0 ? span : 1;

    // The candidate levels, finest first. Rows are a dense table: a level
    // is coarsened rather than let the table outgrow the boxes (sparse or
    // very elongated inputs). The levels keep their tables from build to
    // build: fresh ones cost more in page faults than filling them.
    levels_.resize(kMaxLevels);
    for (Level& level : levels_) {
        auto count = [&](double extent) {
            return std::uint32_t(std::min(std::floor(extent / h) + 1, kMaxCells));
        };
        while (double(count(hi.x - lo.x)) * double(count(hi.y - lo.y)) > 4.0 * double(n) + 65536.0) h *= 2;
        level.inv_h = 1 / h;
        level.nx = count(hi.x - lo.x);
        level.ny = count(hi.y - lo.y);
        level.nz = count(hi.z - lo.z);
        h *= kLevelGrowth;
    }
    // Each box to the finest level it fits (the last one takes any box).
    scratch_level_.resize(n);
    parallel_ranges(n, 4096, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
            std::uint8_t l = 0;
            while (l + 1 < kMaxLevels && !levels_[l].fits(boxes_[i], lo_)) ++l;
            scratch_level_[i] = l;
        }
    });
    std::size_t used[kMaxLevels] = {};
    for (std::uint8_t l : scratch_level_) ++used[l];
    for (int l = 0; l < kMaxLevels; ++l)
        if (used[l] > 0) {
            active_.push_back(std::uint8_t(l));
            fill_level(std::uint8_t(l));
        }
}

/// Entries of one level sorted by (row, z, id): a counting sort by z, then a
/// stable one by row, over cells computed in parallel.
void TriangleGrid::fill_level(std::uint8_t l) {
    Level& level = levels_[l];
    const std::size_t n = boxes_.size();
    scratch_row_.resize(n);
    scratch_z_.resize(n);
    parallel_ranges(n, 4096, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
            if (scratch_level_[i] != l) continue;
            const vec& p = boxes_[i][0];
            scratch_row_[i] = level.cell(p.x, lo_.x, level.nx) * level.ny + level.cell(p.y, lo_.y, level.ny);
            scratch_z_[i] = level.cell(p.z, lo_.z, level.nz);
        }
    });
    std::vector<std::uint32_t>& z_begin = scratch_z_begin_;
    z_begin.assign(std::size_t(level.nz) + 1, 0);
    level.row_begin.assign(std::size_t(level.nx) * level.ny + 1, 0);
    std::size_t listed = 0;
    for (std::size_t i = 0; i < n; ++i) {
        if (scratch_level_[i] != l) continue;
        ++z_begin[scratch_z_[i] + 1];
        ++level.row_begin[scratch_row_[i] + 1];
        ++listed;
    }
    for (std::size_t z = 0; z < level.nz; ++z) z_begin[z + 1] += z_begin[z];
    for (std::size_t r = 0; r + 1 < level.row_begin.size(); ++r) level.row_begin[r + 1] += level.row_begin[r];
    scratch_ids_.resize(listed);
    for (std::size_t i = 0; i < n; ++i)
        if (scratch_level_[i] == l) scratch_ids_[z_begin[scratch_z_[i]]++] = std::uint32_t(i);
    level.z.resize(listed);
    level.id.resize(listed);
    std::vector<std::uint32_t>& fill = scratch_fill_;
    fill.assign(level.row_begin.begin(), level.row_begin.end() - 1);
    for (std::uint32_t i : scratch_ids_) {
        const std::uint32_t e = fill[scratch_row_[i]]++;
        level.z[e] = scratch_z_[i];
        level.id[e] = i;
    }
}

void TriangleGrid::query(const vec& lo, const vec& hi, std::vector<std::uint32_t>& out) const {
    out.clear();
    const BoxPair q{lo, hi};
    for (std::uint8_t l : active_) {
        const Level& level = levels_[l];
        auto first = [](std::uint32_t c) { return c > 0 ? c - 1 : 0u; };
        const std::uint32_t x0 = first(level.cell(lo.x, lo_.x, level.nx)), x1 = level.cell(hi.x, lo_.x, level.nx);
        const std::uint32_t y0 = first(level.cell(lo.y, lo_.y, level.ny)), y1 = level.cell(hi.y, lo_.y, level.ny);
        const std::uint32_t z0 = first(level.cell(lo.z, lo_.z, level.nz)), z1 = level.cell(hi.z, lo_.z, level.nz);
        for (std::uint32_t x = x0; x <= x1; ++x)
            for (std::uint32_t y = y0; y <= y1; ++y) {
                const std::size_t row = std::size_t(x) * level.ny + y;
                const std::uint32_t* zs = level.z.data();
                std::uint32_t e = level.row_begin[row];
                const std::uint32_t end = level.row_begin[row + 1];
                if (end - e > 16) e = std::uint32_t(std::lower_bound(zs + e, zs + end, z0) - zs);
                for (; e < end && zs[e] <= z1; ++e)
                    if (zs[e] >= z0 && boxes_meet(boxes_[level.id[e]], q)) out.push_back(level.id[e]);
            }
    }
}

}  // namespace pqdc::decimate_detail
