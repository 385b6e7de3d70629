#include "pqdc/brick_store.hpp"

#include "pqdc/exceptions.hpp"
#include "pqdc/extract.hpp"
#include "io/atomic_file.hpp"
#include "bricks/brick_source.hpp"
#include "bricks/bricks.hpp"
#include "bricks/file_digest.hpp"
#include "bricks/mapped_pages.hpp"
#include "bricks/store_index.hpp"

#include <openvdb/io/File.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <system_error>
#include <vector>

namespace pqdc {
namespace {

namespace fs = std::filesystem;

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

/// Writes a store's files: the shell, then bricks in tree order, then the
/// index, last and atomically (temporary name, fsync, rename), like every
/// pqdc file, so an interrupted run leaves no store: files without an
/// index, which the readers call an incomplete store. A run that fails
/// removes its files (write_store_dir).
class StoreWriter {
public:
    StoreWriter(const std::string& dir, const openvdb::GridBase& shell) : dir_(dir) {
        const fs::path path = fs::path(dir_) / "grid.vdb";
        write_grid(shell, path.string());
        index_ << detail::kStoreIndexMagic << "\nshell grid.vdb " << fs::file_size(path) << " "
               << written_digest(path) << "\n";
    }

    /// `brick`: a grid holding the volume's leaves and tiles inside `box`.
    void add(const openvdb::GridBase& brick, const openvdb::CoordBBox& box, std::uint64_t leaves) {
        const std::string name = detail::brick_file_name(summary_.bricks);
        const fs::path path = fs::path(dir_) / name;
        write_grid(brick, path.string());
        summary_.leaves += leaves;
        ++summary_.bricks;
        // The size lets the reader refuse a cut or replaced file before
        // OpenVDB parses it: a cut file made OpenVDB allocate about 8 GB for
        // a garbage map name, per process (three MPI ranks woke the OOM
        // killer). The checksum does the same for a damaged one, which keeps
        // its size (bricks/file_digest.hpp).
        index_ << "brick " << name << " " << box.min().x() << " " << box.min().y() << " " << box.min().z() << " "
               << box.max().x() << " " << box.max().y() << " " << box.max().z() << " " << fs::file_size(path) << " "
               << written_digest(path) << "\n";
    }

    BrickStoreSummary commit() {
        index_ << "end " << summary_.bricks << "\n";
        detail::AtomicFileWriter out((fs::path(dir_) / "index.txt").string());
        out.append(index_.str());
        out.commit();
        return summary_;
    }

private:
    /// The checksum of a file just written (read back: what is on disk).
    static std::string written_digest(const fs::path& path) {
        try {
            return detail::file_digest(path.string());
        } catch (const std::system_error& e) {
            throw io_error("cannot read back '" + path.string() + "' to checksum it: " + e.code().message());
        }
    }

    std::string dir_;
    std::ostringstream index_;
    BrickStoreSummary summary_;
};

/// f(box) for every brick box of the root child at `origin`, in tree order.
template <class F>
void for_each_brick_box(const openvdb::Coord& origin, int root_dim, const openvdb::Coord& extent, const F& f) {
    for (int x = origin.x(); x < origin.x() + root_dim; x += extent.x())
        for (int y = origin.y(); y < origin.y() + root_dim; y += extent.y())
            for (int z = origin.z(); z < origin.z() + root_dim; z += extent.z())
                f(openvdb::CoordBBox(openvdb::Coord(x, y, z), openvdb::Coord(x, y, z) + extent - openvdb::Coord(1)));
}

/// The progress hook of a split over `boxes` brick boxes: fraction of the
/// boxes done, cancelled_error when the hook says stop (write_store_dir then
/// removes the files).
class SplitProgress {
public:
    SplitProgress(const BrickStoreProgress& hook, std::size_t boxes) : hook_(hook), boxes_(boxes) { report(); }
    void box_done() {
        ++done_;
        report();
    }

private:
    void report() const {
        if (hook_ && !hook_(boxes_ > 0 ? double(done_) / double(boxes_) : 1.0))
            throw cancelled_error("writing the brick store was cancelled");
    }
    const BrickStoreProgress& hook_;
    std::size_t boxes_, done_ = 0;
};

/// f(box) for every brick box of `src` that holds data, in tree order
/// (root children, then boxes within each).
template <class TreeT, class F>
void for_each_source_brick(const TreeT& src, const openvdb::Coord& extent, const F& f) {
    for (auto n2 = src.root().cbeginChildOn(); n2; ++n2)
        for_each_brick_box(n2->origin(), int(n2->DIM), extent, [&](const openvdb::CoordBBox& box) {
            if (holds_data(*n2, box, src.background())) f(box);
        });
}

template <class GridT>
BrickStoreSummary split(const GridT& grid, const std::string& dir, const BrickOptions& options,
                        const BrickStoreProgress& hook) {
    using TreeT = typename GridT::TreeType;
    const TreeT& src = grid.tree();
    const openvdb::Coord extent = detail::brick_extent(options.brick_size);
    std::size_t boxes = 0;
    for_each_source_brick(src, extent, [&](const openvdb::CoordBBox&) { ++boxes; });
    SplitProgress progress(hook, boxes);
    // The shell: the root's tiles, no nodes below it.
    auto shell = std::make_shared<TreeT>(src.background());
    for (auto it = src.root().cbeginValueAll(); it; ++it)
        shell->addTile(TreeT::RootNodeType::LEVEL, it.getCoord(), *it, it.isValueOn());
    StoreWriter store(dir, *with_tree(grid, shell));
    for_each_source_brick(src, extent, [&](const openvdb::CoordBBox& box) {
        auto tree = std::make_shared<TreeT>(src.background());
        // Inside a root child: no root tile overlaps the box (the shell has them).
        detail::copy_tree_box(src, box, *tree);
        store.add(*with_tree(grid, tree), box, tree->leafCount());
        progress.box_done();
    });
    return store.commit();
}

/// f(box) for every brick box that overlaps `lattice`, in tree order (root
/// children in the root's order, then boxes within each).
template <class F>
void for_each_lattice_brick(const openvdb::CoordBBox& lattice, const openvdb::Coord& extent, const F& f) {
    constexpr int kRootDim = int(openvdb::FloatTree::RootNodeType::ChildNodeType::DIM);
    const openvdb::Coord lo = lattice.min() & ~(kRootDim - 1), hi = lattice.max() & ~(kRootDim - 1);
    for (int x = lo.x(); x <= hi.x(); x += kRootDim)  // root children in the root's (lexicographic) order
        for (int y = lo.y(); y <= hi.y(); y += kRootDim)
            for (int z = lo.z(); z <= hi.z(); z += kRootDim)
                for_each_brick_box(openvdb::Coord(x, y, z), kRootDim, extent, [&](const openvdb::CoordBBox& box) {
                    if (box.hasOverlap(lattice)) f(box);
                });
}

/// The procedural volume sample_field would make, sampled and written one
/// brick at a time (never the whole volume in memory).
BrickStoreSummary write_sampled(const ScalarField& field, const ProceduralSampling& sampling, const std::string& dir,
                                const BrickOptions& options, const BrickStoreProgress& hook) {
    const openvdb::Coord extent = detail::brick_extent(options.brick_size);
    const openvdb::CoordBBox lattice = procedural_index_bbox(field, sampling);
    std::size_t boxes = 0;
    for_each_lattice_brick(lattice, extent, [&](const openvdb::CoordBBox&) { ++boxes; });
    SplitProgress progress(hook, boxes);
    // The shell: the grid's name, class and transform with an empty tree.
    StoreWriter store(dir, *sample_field(field, sampling, openvdb::CoordBBox()));
    for_each_lattice_brick(lattice, extent, [&](const openvdb::CoordBBox& box) {
        const openvdb::FloatGrid::Ptr brick = sample_field(field, sampling, box);
        if (brick->tree().root().getTableSize() > 0)  // else all outside: background
            store.add(*brick, box, brick->tree().leafCount());
        progress.box_done();
    });
    return store.commit();
}

/// Makes `dir` (new or empty) and returns whether it was created. Its
/// parent must exist, as for every file pqdc writes (a typo in a path made a
/// tree of directories).
bool prepare_store_dir(const std::string& dir) {
    std::error_code ec;
    const bool existed = fs::exists(dir, ec);
    const fs::path parent = fs::absolute(dir, ec).parent_path();
    if (!existed && !fs::is_directory(parent, ec))
        throw io_error("cannot create the brick store '" + dir + "': the directory '" + parent.string() +
                       "' does not exist; create it first or choose another path");
    fs::create_directory(dir, ec);
    if (ec || !fs::is_directory(dir)) throw io_error("cannot create the directory '" + dir + "': " + ec.message());
    if (!fs::is_empty(dir, ec))
        throw io_error("'" + dir + "' is not empty; give a new or empty directory for the brick store");
    return !existed;
}

/// write() into the new or empty `dir`; when it throws, what it wrote goes
/// (and `dir`, if this made it): a failed write leaves no half store
/// behind, which would block the next try ("not empty").
template <class Write>
BrickStoreSummary write_store_dir(const std::string& dir, const Write& write) {
    const bool created = prepare_store_dir(dir);
    try {
        return write();
    } catch (...) {
        std::error_code ec;
        if (created) {
            fs::remove_all(dir, ec);
        } else {
            for (const auto& entry : fs::directory_iterator(dir, ec)) fs::remove_all(entry.path(), ec);
        }
        throw;
    }
}

/// Brick files read between two hand-backs of their mapped pages (each
/// scans /proc/self/maps, a line per file).
constexpr std::size_t kBricksPerRelease = 32;

template <class GridT>
LoadedGrid assemble(const detail::StoreIndex& index, const GridT& shell) {
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
    for (const detail::StoreBrickFile& b : index.bricks()) {
        detail::check_file_digest(index.dir(), (fs::path(index.dir()) / b.file).string(), b.digest);
        const typename GridT::Ptr brick = detail::open_typed_brick_file<GridT>(index.dir(), b, shell);
        // Leaf copies keep their file references: nothing is loaded.
        detail::copy_tree_box(brick->tree(), b.box, *tree);
        // The brick's own nodes would hold the topology a second time (0.4 GB
        // for 2.15 M leaves); its tree object stays, for its background.
        brick->tree().clear();
        owner->bricks.push_back(brick);
        // Reading a file's topology faults in most of its mapped pages; held
        // to the end they reached 3.6 GB on a 5.8 GB store (a 4096^3 sphere
        // with a 10-voxel band), three times the meshing's own peak.
        if (owner->bricks.size() % kBricksPerRelease == 0) detail::release_mapped_volume_pages();
    }
    detail::release_mapped_volume_pages();
    owner->grid = with_tree(shell, tree);
    LoadedGrid out;
    out.grid = openvdb::GridBase::Ptr(owner, owner->grid.get());
    out.grid_names = {shell.getName()};
    out.scalar_grid_names = out.grid_names;
    out.delay_loaded = true;
    return out;
}

/// The store's shell grid: float or double (input_error otherwise).
LoadedGrid read_shell(const detail::StoreIndex& index) {
    if (std::error_code ec; !fs::is_regular_file(index.shell_path(), ec))
        throw input_error("brick store '" + index.dir() + "' has no grid.vdb (its grid without voxels, which "
                          "pqdc-bricks writes first): the store is damaged; split the volume again with "
                          "pqdc-bricks split");
    detail::check_file_digest(index.dir(), index.shell_path(), index.shell_digest());
    LoadedGrid shell = read_scalar_grid(index.shell_path());
    if (!dynamic_cast<const openvdb::FloatGrid*>(shell.grid.get()) &&
        !dynamic_cast<const openvdb::DoubleGrid*>(shell.grid.get()))
        throw input_error("brick store '" + index.dir() + "': grid.vdb holds " + shell.grid->valueType() +
                          " values; a brick store holds a float or double grid");
    return shell;
}

}  // namespace

BrickStoreSummary write_brick_store(const openvdb::GridBase& grid, const std::string& dir,
                                    const BrickOptions& bricks, const BrickStoreProgress& progress) {
    validate(bricks);
    const auto* f = dynamic_cast<const openvdb::FloatGrid*>(&grid);
    const auto* d = dynamic_cast<const openvdb::DoubleGrid*>(&grid);
    if (!f && !d)
        throw input_error("grid '" + grid.getName() + "' holds " + grid.valueType() +
                          " values; a brick store holds a float or double grid");
    return write_store_dir(dir, [&] {
        return f ? split(*f, dir, bricks, progress) : split(*d, dir, bricks, progress);
    });
}

BrickStoreSummary write_brick_store(const ScalarField& field, const ProceduralSampling& sampling,
                                    const std::string& dir, const BrickOptions& bricks,
                                    const BrickStoreProgress& progress) {
    validate(bricks);
    procedural_index_bbox(field, sampling);  // validates the sampling before anything is written
    return write_store_dir(dir, [&] { return write_sampled(field, sampling, dir, bricks, progress); });
}

bool is_brick_store(const std::string& path) {
    std::error_code ec;
    return fs::is_directory(path, ec) && fs::is_regular_file(fs::path(path) / "index.txt", ec);
}

LoadedGrid read_brick_store(const std::string& dir) {
    openvdb::initialize();
    const detail::StoreIndex index(dir);
    const LoadedGrid shell = read_shell(index);
    if (const auto* f = dynamic_cast<const openvdb::FloatGrid*>(shell.grid.get())) return assemble(index, *f);
    return assemble(index, static_cast<const openvdb::DoubleGrid&>(*shell.grid));
}

BrickStore::BrickStore(const std::string& dir) : path_(dir) {
    openvdb::initialize();
    auto index = std::make_shared<detail::StoreIndex>(dir);
    shell_ = read_shell(*index).grid;
    index_ = std::move(index);
}

std::size_t BrickStore::brick_files() const { return index_->bricks().size(); }

bool BrickStore::assembles_for(const ExtractOptions& options) const {
    double background = NAN;
    if (const auto* f = dynamic_cast<const openvdb::FloatGrid*>(shell_.get())) background = double(f->background());
    if (const auto* d = dynamic_cast<const openvdb::DoubleGrid*>(shell_.get())) background = d->background();
    return !(background < options.isovalue || background > options.isovalue);
}

}  // namespace pqdc
