#include "mesh_fields.hpp"

#include <pqdc/exceptions.hpp>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

namespace pqdc::python {
namespace {

/// The 4^3 lattice values around a point's cell (corner c at local 1 + c).
/// The block spans at most 2 leaves per axis: the 8 leaves are probed once
/// and kept while consecutive points (the mesh lists them leaf by leaf) need
/// the same 8, instead of 64 accessor lookups alternating between leaves.
template <class TreeT>
class Neighbourhood {
public:
    explicit Neighbourhood(const TreeT& tree) : acc_(tree) {}

    void fetch(const openvdb::Coord& base, double v[4][4][4]) {
        const openvdb::Coord first = base.offsetBy(-1), leaf0 = first & ~7;
        if (!valid_ || leaf0 != key_) probe(leaf0);
        for (int x = 0; x < 4; ++x)
            for (int y = 0; y < 4; ++y)
                for (int z = 0; z < 4; ++z) {
                    const int gx = first.x() + x - leaf0.x(), gy = first.y() + y - leaf0.y(),
                              gz = first.z() + z - leaf0.z();
                    const int i = (gx >> 3) | ((gy >> 3) << 1) | ((gz >> 3) << 2);
                    v[x][y][z] = double(data_[i] ? data_[i][((gx & 7) << 6) | ((gy & 7) << 3) | (gz & 7)] : tile_[i]);
                }
    }

private:
    using LeafT = typename TreeT::LeafNodeType;
    using ValueT = typename LeafT::ValueType;

    void probe(const openvdb::Coord& leaf0) {
        for (int i = 0; i < 8; ++i) {
            const openvdb::Coord origin = leaf0.offsetBy(i & 1 ? 8 : 0, i & 2 ? 8 : 0, i & 4 ? 8 : 0);
            const LeafT* leaf = acc_.probeConstLeaf(origin);
            data_[i] = leaf ? leaf->buffer().data() : nullptr;
            tile_[i] = leaf ? ValueT(0) : acc_.getValue(origin);
        }
        key_ = leaf0;
        valid_ = true;
    }

    openvdb::tree::ValueAccessor<const TreeT> acc_;
    openvdb::Coord key_;
    bool valid_ = false;
    const ValueT* data_[8];
    ValueT tile_[8];
};

/// Infinite values replaced by finite ones beyond the block's finite range,
/// for the gradient (as the CLI's normals, src/normals/outward_normal.hpp):
/// next to -inf it points away from it.
void finite_stand_ins(double (&v)[4][4][4]) {
    double* const all = &v[0][0][0];
    double range = 0;
    bool any = false;
    for (int i = 0; i < 64; ++i) {
        if (std::isinf(all[i])) any = true;
        else if (std::isfinite(all[i])) range = std::max(range, std::abs(all[i]));
    }
    if (!any) return;
    const double far = std::min(4 * range + 1, 1e30);
    for (int i = 0; i < 64; ++i)
        if (std::isinf(all[i])) all[i] = all[i] < 0 ? -far : far;
}

double difference(double minus, double centre, double plus) {
    const bool m = std::isfinite(minus), p = std::isfinite(plus);
    if (m && p) return 0.5 * (plus - minus);
    if (p) return plus - centre;
    if (m) return centre - minus;
    return 0.0;
}

template <class GridT>
VertexFields sample(const GridT& grid, const std::vector<openvdb::Vec3d>& points, double outward_sign,
                    const openvdb::Mat3d& covector, const std::function<bool(double)>& progress) {
    VertexFields out;
    out.normals.resize(points.size());
    out.values.resize(points.size());
    const std::size_t chunk = std::max<std::size_t>(4096, points.size() / 32);
    for (std::size_t start = 0; start < points.size(); start += chunk) {
        const std::size_t end = std::min(points.size(), start + chunk);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(start, end), [&](const tbb::blocked_range<std::size_t>& r) {
            Neighbourhood<typename GridT::TreeType> around(grid.tree());
            double v[4][4][4];
            for (std::size_t i = r.begin(); i != r.end(); ++i) {
                const openvdb::Vec3d& p = points[i];
                const openvdb::Coord base(int(std::floor(p[0])), int(std::floor(p[1])), int(std::floor(p[2])));
                around.fetch(base, v);
                const double f[3] = {p[0] - base[0], p[1] - base[1], p[2] - base[2]};
                auto weight = [&f](int c) {
                    return (c & 1 ? f[0] : 1 - f[0]) * (c & 2 ? f[1] : 1 - f[1]) * (c & 4 ? f[2] : 1 - f[2]);
                };
                double value = 0.0;  // of the values as stored, infinities too
                for (int c = 0; c < 8; ++c) value += weight(c) * v[1 + (c & 1)][1 + ((c >> 1) & 1)][1 + ((c >> 2) & 1)];
                finite_stand_ins(v);
                openvdb::Vec3d g(0.0);
                for (int c = 0; c < 8; ++c) {
                    const int x = 1 + (c & 1), y = 1 + ((c >> 1) & 1), z = 1 + ((c >> 2) & 1);
                    const double w = weight(c);
                    const double centre = v[x][y][z];
                    g[0] += w * difference(v[x - 1][y][z], centre, v[x + 1][y][z]);
                    g[1] += w * difference(v[x][y - 1][z], centre, v[x][y + 1][z]);
                    g[2] += w * difference(v[x][y][z - 1], centre, v[x][y][z + 1]);
                }
                openvdb::Vec3d n = covector * (g * outward_sign);
                const double len = n.length();
                out.normals[i] = len > 0 && std::isfinite(len) ? n / len : openvdb::Vec3d(0.0);
                out.values[i] = value;
            }
        });
        if (progress && !progress(double(end) / double(points.size())))
            throw cancelled_error("vertex normals cancelled by the caller");
    }
    return out;
}

}  // namespace

VertexFields sample_vertex_fields(const openvdb::GridBase& grid, const std::vector<openvdb::Vec3d>& index_points,
                                  double outward_sign, const openvdb::Mat3d& index_to_world_covector,
                                  const std::function<bool(double)>& progress) {
    if (const auto* f = dynamic_cast<const openvdb::FloatGrid*>(&grid))
        return sample(*f, index_points, outward_sign, index_to_world_covector, progress);
    if (const auto* d = dynamic_cast<const openvdb::DoubleGrid*>(&grid))
        return sample(*d, index_points, outward_sign, index_to_world_covector, progress);
    throw input_error("grid '" + grid.getName() + "' holds " + grid.valueType() +
                      " values; vertex normals need a float or double grid");
}

}  // namespace pqdc::python
