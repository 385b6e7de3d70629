#include "pqdc/brick_store.hpp"

#include "pqdc/exceptions.hpp"
#include "io/atomic_file.hpp"
#include "scale/brick_source.hpp"
#include "scale/bricks.hpp"

#include <openvdb/io/File.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <system_error>
#include <vector>

namespace pqdc {
namespace {

namespace fs = std::filesystem;

constexpr const char* kIndexMagic = "pqdc-brick-store 1";

/// The grid with `tree` in place of its own, keeping name, class, transform and metadata.
template <class GridT>
typename GridT::Ptr with_tree(const GridT& grid, typename GridT::TreeType::Ptr tree) {
    typename GridT::Ptr out = grid.copyWithNewTree();
    out->setTree(tree);
    return out;
}

/// Whether the part `box` (whole level-1 nodes) of the root child `n2`
/// holds anything besides inactive background: a child, or a tile that is
/// active or holds another value.
template <class Node2, class ValueT>
bool holds_data(const Node2& n2, const openvdb::CoordBBox& box, const ValueT& background) {
    constexpr int step = int(Node2::ChildNodeType::DIM);
    for (int x = box.min().x(); x <= box.max().x(); x += step)
        for (int y = box.min().y(); y <= box.max().y(); y += step)
            for (int z = box.min().z(); z <= box.max().z(); z += step) {
                const openvdb::Index n = Node2::coordToOffset(openvdb::Coord(x, y, z));
                if (n2.isChildMaskOn(n) || n2.isValueMaskOn(n) || n2.getTable()[n].getValue() != background)
                    return true;
            }
    return false;
}

template <class GridT>
BrickStoreSummary split(const GridT& grid, const std::string& dir, const BrickOptions& options) {
    using TreeT = typename GridT::TreeType;
    const TreeT& src = grid.tree();
    const openvdb::Coord extent = detail::brick_extent(options.brick_size);
    std::ostringstream index;
    index << kIndexMagic << "\nshell grid.vdb\n";
    BrickStoreSummary summary;
    // The shell: the root's tiles, no nodes below it.
    auto shell = std::make_shared<TreeT>(src.background());
    for (auto it = src.root().cbeginValueAll(); it; ++it)
        shell->addTile(TreeT::RootNodeType::LEVEL, it.getCoord(), *it, it.isValueOn());
    write_grid(*with_tree(grid, shell), (fs::path(dir) / "grid.vdb").string());
    for (auto n2 = src.root().cbeginChildOn(); n2; ++n2) {
        const openvdb::CoordBBox node = n2->getNodeBoundingBox();
        for (int x = node.min().x(); x <= node.max().x(); x += extent.x())
            for (int y = node.min().y(); y <= node.max().y(); y += extent.y())
                for (int z = node.min().z(); z <= node.max().z(); z += extent.z()) {
                    const openvdb::CoordBBox box(openvdb::Coord(x, y, z),
                                                 openvdb::Coord(x, y, z) + extent - openvdb::Coord(1));
                    if (!holds_data(*n2, box, src.background())) continue;
                    auto tree = std::make_shared<TreeT>(src.background());
                    // Inside a root child: no root tile overlaps the box (the shell has them).
                    detail::copy_tree_box(src, box, *tree);
                    char name[32];
                    std::snprintf(name, sizeof name, "brick-%06llu.vdb", static_cast<unsigned long long>(summary.bricks));
                    summary.leaves += tree->leafCount();
                    write_grid(*with_tree(grid, tree), (fs::path(dir) / name).string());
                    ++summary.bricks;
                    index << "brick " << name << " " << x << " " << y << " " << z << " " << box.max().x() << " "
                          << box.max().y() << " " << box.max().z() << "\n";
                }
    }
    // Last and atomically (temporary name, fsync, rename), like every pqdc file.
    detail::AtomicFileWriter out((fs::path(dir) / "index.txt").string());
    out.append(index.str());
    out.commit();
    return summary;
}

/// Opens one grid of a store file with delayed loading (mapped, not copied).
openvdb::GridBase::Ptr open_delayed(const std::string& store, const fs::path& file) {
    try {
        openvdb::io::File f(file.string());
        f.setCopyMaxBytes(0);
        f.open(true);
        const openvdb::GridPtrVecPtr grids = f.getGrids();
        f.close();
        if (!grids || grids->size() != 1) throw input_error("it does not hold exactly one grid");
        return grids->front();
    } catch (const std::exception& e) {
        throw input_error("brick store '" + store + "': cannot read '" + file.string() + "' (" + e.what() +
                          "); split the volume again with pqdc-bricks split");
    }
}

template <class GridT>
LoadedGrid assemble(const std::string& store, const GridT& shell, const std::vector<std::string>& lines) {
    using TreeT = typename GridT::TreeType;
    // A delay-loaded leaf reads its inactive values against the background
    // of the grid it was read with (the stream metadata points at it), so
    // the brick grids must outlive every leaf copied from them: the
    // returned grid owns them.
    struct Owner {
        typename GridT::Ptr grid;
        std::vector<openvdb::GridBase::Ptr> bricks;
    };
    auto owner = std::make_shared<Owner>();
    auto tree = std::make_shared<TreeT>(shell.tree());
    for (const std::string& line : lines) {
        std::istringstream in(line);
        std::string word, file;
        openvdb::CoordBBox box;
        in >> word >> file >> box.min().x() >> box.min().y() >> box.min().z() >> box.max().x() >> box.max().y() >>
            box.max().z();
        if (!in || word != "brick")
            throw input_error("brick store '" + store + "': index.txt has a bad line '" + line +
                              "'; split the volume again with pqdc-bricks split");
        const openvdb::GridBase::Ptr brick = open_delayed(store, fs::path(store) / file);
        const auto* typed = dynamic_cast<const GridT*>(brick.get());
        if (!typed) throw input_error("brick store '" + store + "': '" + file + "' holds another value type");
        // Leaf copies keep their file references: nothing is loaded.
        detail::copy_tree_box(typed->tree(), box, *tree);
        owner->bricks.push_back(brick);
    }
    owner->grid = with_tree(shell, tree);
    LoadedGrid out;
    out.grid = openvdb::GridBase::Ptr(owner, owner->grid.get());
    out.grid_names = {shell.getName()};
    out.scalar_grid_names = out.grid_names;
    out.delay_loaded = true;
    return out;
}

}  // namespace

BrickStoreSummary write_brick_store(const openvdb::GridBase& grid, const std::string& dir,
                                    const BrickOptions& bricks) {
    validate(bricks);
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec || !fs::is_directory(dir)) throw io_error("cannot create the directory '" + dir + "': " + ec.message());
    if (!fs::is_empty(dir, ec))
        throw io_error("'" + dir + "' is not empty; give a new or empty directory for the brick store");
    if (const auto* f = dynamic_cast<const openvdb::FloatGrid*>(&grid)) return split(*f, dir, bricks);
    if (const auto* d = dynamic_cast<const openvdb::DoubleGrid*>(&grid)) return split(*d, dir, bricks);
    throw input_error("grid '" + grid.getName() + "' holds " + grid.valueType() +
                      " values; a brick store holds a float or double grid");
}

bool is_brick_store(const std::string& path) {
    std::error_code ec;
    return fs::is_directory(path, ec) && fs::is_regular_file(fs::path(path) / "index.txt", ec);
}

LoadedGrid read_brick_store(const std::string& dir) {
    openvdb::initialize();
    std::ifstream index(fs::path(dir) / "index.txt");
    std::string magic, shell_line, line;
    std::getline(index, magic);
    std::getline(index, shell_line);
    if (!index || magic != kIndexMagic || shell_line != "shell grid.vdb")
        throw input_error("'" + dir + "' is not a pqdc brick store (index.txt missing or of another format); "
                          "make one with pqdc-bricks split");
    std::vector<std::string> lines;
    while (std::getline(index, line))
        if (!line.empty()) lines.push_back(line);
    const LoadedGrid shell = read_scalar_grid((fs::path(dir) / "grid.vdb").string());
    if (const auto* f = dynamic_cast<const openvdb::FloatGrid*>(shell.grid.get())) return assemble(dir, *f, lines);
    return assemble(dir, static_cast<const openvdb::DoubleGrid&>(*shell.grid), lines);
}

}  // namespace pqdc
