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
// with one counting sort by row for all levels, then a short sort per row.

#include "decimate_internal.hpp"
#include "memory/huge_pages.hpp"

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

void triangle_boxes(const std::vector<vec>& pos, const std::vector<Tri>& tris, std::vector<FloatBox>& boxes) {
    detail::reserve_large(boxes, tris.size());
    boxes.resize(tris.size());
    parallel_ranges(tris.size(), 4096, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i)
            boxes[i] = float_box(triangle_box(pos[tris[i][0]], pos[tris[i][1]], pos[tris[i][2]]));
    });
}

inline bool TriangleGrid::Level::fits(const FloatBox& b, const vec& lo) const {
    const double l[3] = {lo.x, lo.y, lo.z};
    for (int k = 0; k < 3; ++k)
        if ((double(b.hi[k]) - l[k]) * inv_h - (double(b.lo[k]) - l[k]) * inv_h > kFit) return false;
    return true;
}

void TriangleGrid::build(std::vector<FloatBox>& boxes) {
    boxes_.swap(boxes);
    active_.clear();
    const std::size_t n = boxes_.size();
    if (n == 0) return;
    // The cell size from the listed quantile of the boxes' extents, over a
    // sample of them on large inputs (any size works; this one keeps most
    // boxes on the finest level).
    const std::size_t stride = n > 65536 ? 8 : 1;
    auto corner = [](const float* c) { return vec{c[0], c[1], c[2]}; };
    vec lo = corner(boxes_[0].lo), hi = corner(boxes_[0].hi);
    scratch_extent_.clear();
    for (std::size_t i = 0; i < n; ++i) {
        const FloatBox& b = boxes_[i];
        lo = component_min(lo, corner(b.lo));
        hi = component_max(hi, corner(b.hi));
        if (i % stride == 0)
            scratch_extent_.push_back(std::max({double(b.hi[0]) - b.lo[0], double(b.hi[1]) - b.lo[1], double(b.hi[2]) - b.lo[2]}));
    }
    lo_ = lo;
    const double span = std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z});
    const auto q = scratch_extent_.begin() + std::ptrdiff_t(double(scratch_extent_.size() - 1) * kListedQuantile);
    std::nth_element(scratch_extent_.begin(), q, scratch_extent_.end());
    double h = std::max(*q / kFit * 1.001, span / (kMaxCells - 2));
    if (!(h > 0)) h = span > 0 ? span : 1;
    // Coordinates beyond float's range make infinite float boxes: then one
    // cell holds every box (cell() takes NaN to 0), and queries scan them all.
    if (!std::isfinite(span)) h = std::numeric_limits<double>::infinity();

    // The candidate levels, finest first. Rows are a dense table: a level
    // is coarsened rather than let the table outgrow the boxes (sparse or
    // very elongated inputs). The levels keep their tables from build to
    // build: fresh ones cost more in page faults than filling them.
    levels_.resize(kMaxLevels);
    for (Level& level : levels_) {
        auto count = [&](double extent) {
            const double cells = std::floor(extent / h) + 1;
            return std::uint32_t(cells >= 1 ? std::min(cells, kMaxCells) : 1.0);  // NaN (inf / inf) -> 1
        };
        while (double(count(hi.x - lo.x)) * double(count(hi.y - lo.y)) > 4.0 * double(n) + 65536.0) h *= 2;
        level.inv_h = 1 / h;
        level.nx = count(hi.x - lo.x);
        level.ny = count(hi.y - lo.y);
        level.nz = count(hi.z - lo.z);
        h *= kLevelGrowth;
    }
    // Each box to the finest level it fits (the last one takes any box),
    // with its cell there.
    detail::reserve_large(scratch_level_, n);
    detail::reserve_large(scratch_row_, n);
    detail::reserve_large(scratch_z_, n);
    scratch_level_.resize(n);
    scratch_row_.resize(n);
    scratch_z_.resize(n);
    parallel_ranges(n, 4096, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
            std::uint8_t l = 0;
            while (l + 1 < kMaxLevels && !levels_[l].fits(boxes_[i], lo_)) ++l;
            scratch_level_[i] = l;
            const Level& level = levels_[l];
            const vec p = corner(boxes_[i].lo);
            scratch_row_[i] = level.cell(p.x, lo_.x, level.nx) * level.ny + level.cell(p.y, lo_.y, level.ny);
            scratch_z_[i] = level.cell(p.z, lo_.z, level.nz);
        }
    });
    fill_levels();
}

/// Entries of every level sorted by (row, z, id): one counting sort by row
/// (in id order, so stable), then each row's few entries by z.
void TriangleGrid::fill_levels() {
    const std::size_t n = boxes_.size();
    std::size_t used[kMaxLevels] = {};
    for (std::uint8_t l : scratch_level_) ++used[l];
    for (int l = 0; l < kMaxLevels; ++l) {
        if (used[l] == 0) continue;
        active_.push_back(std::uint8_t(l));
        Level& level = levels_[std::size_t(l)];
        // Counted at row + 2 and advanced at row + 1 while filling, so that
        // afterwards row_begin[r] is where row r begins.
        detail::reserve_large(level.row_begin, std::size_t(level.nx) * level.ny + 2);
        detail::reserve_large(level.z, used[l]);
        detail::reserve_large(level.id, used[l]);
        level.row_begin.assign(std::size_t(level.nx) * level.ny + 2, 0);
        level.z.resize(used[l]);
        level.id.resize(used[l]);
    }
    for (std::size_t i = 0; i < n; ++i) ++levels_[scratch_level_[i]].row_begin[scratch_row_[i] + 2];
    for (std::uint8_t l : active_) {
        std::vector<std::uint32_t>& rb = levels_[l].row_begin;
        for (std::size_t r = 2; r < rb.size(); ++r) rb[r] += rb[r - 1];
    }
    for (std::size_t i = 0; i < n; ++i) {
        Level& level = levels_[scratch_level_[i]];
        const std::uint32_t e = level.row_begin[scratch_row_[i] + 1]++;
        level.z[e] = scratch_z_[i];
        level.id[e] = std::uint32_t(i);
    }
    for (std::uint8_t l : active_) sort_rows_by_z(levels_[l]);
}

/// Each row by (z, id); rows are short (a column of cells crosses a surface
/// a few times), so insertion sort, except for long ones.
void TriangleGrid::sort_rows_by_z(Level& level) {
    std::uint32_t* z = level.z.data();
    std::uint32_t* id = level.id.data();
    const std::size_t rows = level.row_begin.size() - 2;
    for (std::size_t r = 0; r < rows; ++r) {
        const std::uint32_t begin = level.row_begin[r], end = level.row_begin[r + 1];
        if (end - begin > 32) {
            scratch_keys_.clear();
            for (std::uint32_t e = begin; e < end; ++e) scratch_keys_.push_back(std::uint64_t(z[e]) << 32 | id[e]);
            std::sort(scratch_keys_.begin(), scratch_keys_.end());
            for (std::uint32_t e = begin; e < end; ++e) {
                z[e] = std::uint32_t(scratch_keys_[e - begin] >> 32);
                id[e] = std::uint32_t(scratch_keys_[e - begin]);
            }
            continue;
        }
        for (std::uint32_t e = begin + 1; e < end; ++e) {
            const std::uint32_t ze = z[e], ie = id[e];
            std::uint32_t k = e;
            for (; k > begin && z[k - 1] > ze; --k) {
                z[k] = z[k - 1];
                id[k] = id[k - 1];
            }
            z[k] = ze;
            id[k] = ie;
        }
    }
}

void TriangleGrid::query(const vec& lo, const vec& hi, std::vector<std::uint32_t>& out) const {
    out.clear();
    const FloatBox q = float_box({lo, hi});  // rounded outwards too: still every box that meets lo-hi
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
