#include "uniform/gather.hpp"

#include "pqdc/exceptions.hpp"

#include <algorithm>
#include <string>

namespace pqdc::detail {

void gather_vertices(LeafResults& r, const ExtractOptions& options, const Progress& progress, CellTree& cells,
                     std::vector<CellLeaf*>& leaves, std::vector<std::uint64_t>& first, Mesh& mesh) {
    const std::size_t n = r.cells.size();
    leaves.assign(n, nullptr);
    {
        openvdb::tree::ValueAccessor<CellTree, false> acc(cells);
        for (std::size_t i = 0; i < n; ++i)
            if (r.cells[i]) {
                leaves[i] = r.cells[i].get();
                acc.addLeaf(r.cells[i].release());
            }
    }
    first.assign(n + 1, 0);
    for (std::size_t i = 0; i < n; ++i) first[i + 1] = first[i] + r.points[i].size();
    const std::uint64_t nverts = first.back();
    if (nverts >= (std::uint64_t(1) << 32))
        throw resource_error("the mesh would have " + std::to_string(nverts) +
                             " vertices, more than 32-bit face indices can address; mesh the volume in parts");
    check_memory(double(nverts) * double(2 * sizeof(openvdb::Vec3d) + 2 * 3 * sizeof(openvdb::Vec3I)), options, "mesh");
    reserve_large(mesh.points, nverts);
    mesh.points.resize(nverts);
    parallel_chunks(n, progress, 0.45, 0.46, [&](std::size_t i) {
        std::copy(r.points[i].begin(), r.points[i].end(), mesh.points.begin() + std::ptrdiff_t(first[i]));
        std::vector<openvdb::Vec3d>().swap(r.points[i]);
    });
}

}  // namespace pqdc::detail
