#include "pqdc/volume_io.hpp"
#include "pqdc/brick_store.hpp"

#include "pqdc/exceptions.hpp"

#include "atomic_file.hpp"
#include "foreign_message.hpp"

#include <openvdb/io/File.h>
#include <openvdb/io/GridDescriptor.h>
#include <openvdb/io/Stream.h>
#include <openvdb/tree/LeafManager.h>

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <ostream>
#include <streambuf>
#include <sstream>

namespace pqdc {
namespace {

std::string join(const std::vector<std::string>& names) {
    std::string s;
    for (const auto& n : names) s += (s.empty() ? "'" : ", '") + n + "'";
    return s.empty() ? "(none)" : s;
}

bool is_scalar_type(const std::string& type) {
    return type == openvdb::FloatGrid::gridType() || type == openvdb::DoubleGrid::gridType();
}

/// What a read is for: the grids it accepts and how messages name them.
struct Purpose {
    bool (*accept)(const std::string& type);
    const char* kinds;   ///< "float or double"
    const char* use;     ///< "mesh"
    const char* option;  ///< "--grid NAME"
};

bool is_mask_type(const std::string& type) {
    return is_scalar_type(type) || type == openvdb::BoolGrid::gridType() || type == openvdb::MaskGrid::gridType() ||
           type == openvdb::Int32Grid::gridType();
}

const Purpose kMeshing{is_scalar_type, "float or double", "mesh", "--grid NAME"};
const Purpose kMasking{is_mask_type, "bool, mask, float, double or int32", "use as a mask", "--mask FILE.vdb:NAME"};

/// Throws input_error unless the grid's transform maps index to world space
/// with finite numbers. OpenVDB refuses to build maps with tiny scales
/// (voxel size below ~1.5e-5: "nearly singular"), but a file can still
/// carry one; reading it succeeds and the failure would surface later as a
/// bare ArithmeticError without the file's name.
void check_transform_usable(const openvdb::GridBase& grid, const std::string& path) {
    const openvdb::math::Transform& xf = grid.transform();
    std::ostringstream voxel;
    voxel << xf.voxelSize();
    const std::string where = "grid '" + grid.getName() + "' in '" + path + "'";
    const auto non_finite = [&] {
        return input_error(where + " has a transform with non-finite entries (voxel size " + voxel.str() +
                           "); the file is corrupt or was written with a broken transform; re-export it with a "
                           "valid voxel size and origin");
    };
    const openvdb::Vec3d vs = xf.voxelSize(), origin = xf.indexToWorld(openvdb::Vec3d(0.0));
    for (int i = 0; i < 3; ++i)
        if (!std::isfinite(vs[i]) || !std::isfinite(origin[i])) throw non_finite();
    try {
        const openvdb::Mat4d m = xf.baseMap()->getAffineMap()->getMat4();
        for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j)
                if (!std::isfinite(m(i, j))) throw non_finite();
    } catch (const pqdc::error&) {
        throw;
    } catch (const std::exception& e) {
        throw input_error(where + " has a transform OpenVDB cannot invert (voxel size " + voxel.str() + ": " +
                          detail::foreign_message(e.what()) +
                          "); OpenVDB needs voxels of at least about 1.5e-5 world units: re-export the grid in "
                          "larger units (e.g. millimetres instead of metres)");
    }
}

/// What the header and grid descriptors of a .vdb file say about its layout.
struct FileLayout {
    bool known = false;          ///< a format this parser understands (file version >= 222) was read
    bool has_grid_offsets = false;  ///< written by io::File (seekable) rather than io::Stream
    bool header_complete = false;   ///< the header, file metadata and grid count were all there
    struct Grid {
        std::string name;
        std::int64_t end = 0;  ///< byte offset where the grid's data ends
    };
    std::vector<Grid> grids;  ///< in file order (offset files only)
};

/// Reads the header and, for files with grid offsets, every grid descriptor
/// (they sit in front of each grid and point at its end). OpenVDB reads
/// whatever bytes are there and fills missing ones silently, so a file cut
/// short inside its last leaf buffers still "reads"; comparing the
/// descriptors' end offsets with the file size is what reveals it.
FileLayout read_layout(const std::string& path, std::int64_t file_size) {
    FileLayout out;
    std::ifstream is(path, std::ios::binary);
    auto read = [&](void* p, std::size_t n) { return bool(is.read(static_cast<char*>(p), std::streamsize(n))); };
    auto read_string = [&](std::string& str) {
        std::uint32_t n = 0;
        if (!read(&n, 4) || std::int64_t(n) > file_size) return false;
        str.resize(n);
        return n == 0 || read(str.data(), n);
    };
    std::int64_t magic = 0;
    std::uint32_t version = 0, library[2];
    char offsets = 0, uuid[36];
    if (!read(&magic, 8) || magic != openvdb::OPENVDB_MAGIC) {
        // A file cut inside the 8-byte magic number that starts like one: OpenVDB
        // reads the missing bytes as zeros, accepts it and finds no grids.
        const std::int64_t expected = openvdb::OPENVDB_MAGIC;
        const std::streamsize got = is.gcount();
        out.known = got > 0 && got < 8 && std::memcmp(&magic, &expected, std::size_t(got)) == 0;
        return out;
    }
    if (!read(&version, 4)) {
        out.known = true;  // the magic number and nothing after it
        return out;
    }
    if (version < openvdb::OPENVDB_FILE_VERSION_NODE_MASK_COMPRESSION || version > openvdb::OPENVDB_FILE_VERSION)
        return out;
    if (!read(library, 8) || !read(&offsets, 1) || !read(uuid, 36)) {
        out.known = true;
        return out;
    }
    std::uint32_t meta_count = 0;
    if (!read(&meta_count, 4)) {
        out.known = true;
        return out;
    }
    for (std::uint32_t i = 0; i < meta_count; ++i) {
        std::string name, type;
        std::uint32_t bytes = 0;
        if (!read_string(name) || !read_string(type) || !read(&bytes, 4) || std::int64_t(bytes) > file_size ||
            !is.seekg(bytes, std::ios::cur)) {
            out.known = true;
            return out;
        }
    }
    std::int32_t grid_count = 0;
    out.known = true;
    if (!read(&grid_count, 4) || grid_count < 0 || std::int64_t(is.tellg()) > file_size) return out;
    out.header_complete = true;
    out.has_grid_offsets = offsets != 0;
    if (!out.has_grid_offsets) return out;
    for (std::int32_t g = 0; g < grid_count; ++g) {
        std::string unique, type, parent;
        std::int64_t pos[3];  // grid, block, end
        if (!read_string(unique) || !read_string(type) || !read_string(parent) || !read(pos, sizeof pos)) {
            out.grids.push_back({"", file_size + 1});  // the descriptor itself is cut off
            return out;
        }
        out.grids.push_back({openvdb::io::GridDescriptor::nameAsString(
                                 openvdb::io::GridDescriptor::stripSuffix(unique)),
                             pos[2]});
        if (pos[2] > file_size || pos[2] <= std::int64_t(is.tellg())) return out;
        is.seekg(pos[2]);
    }
    return out;
}

[[noreturn]] void throw_truncated(const std::string& path, const std::string& detail) {
    throw input_error("'" + path + "' is truncated (" + detail +
                      "); re-export it or check that the copy is complete");
}

/// Grids are read by name: two of one name cannot be told apart (OpenVDB
/// warns and reads the first).
void check_unique_name(const std::string& path, const std::string& name, const LoadedGrid& out, const Purpose& purpose) {
    const auto same = std::count(out.grid_names.begin(), out.grid_names.end(), name);
    if (same > 1)
        throw input_error("'" + path + "' has " + std::to_string(same) + " grids named '" + name +
                          "'; pqdc reads grids by name and cannot tell them apart: rename them (or choose another "
                          "grid with " + purpose.option + ")");
}

/// Picks the grid to read and throws the errors a user can act on.
std::string choose_grid(const std::string& path, const std::string& grid_name, const std::vector<std::string>& types,
                        const std::vector<bool>& scalar, LoadedGrid& out, const Purpose& purpose) {
    if (out.grid_names.empty())
        throw input_error("'" + path + "' contains no grids, so there is nothing to " + purpose.use +
                          "; write a " + purpose.kinds + " grid into it");
    if (grid_name.empty()) {
        if (out.scalar_grid_names.empty()) {
            std::ostringstream s;
            s << "'" << path << "' has no " << purpose.kinds << " grid to " << purpose.use << "; its grids are ";
            for (std::size_t i = 0; i < out.grid_names.size(); ++i)
                s << (i ? ", '" : "'") << out.grid_names[i] << "' (" << types[i] << ")";
            s << "; convert one to a float grid (e.g. a level set or fog volume) first";
            throw input_error(s.str());
        }
        out.chosen_automatically = true;
        check_unique_name(path, out.scalar_grid_names.front(), out, purpose);
        return out.scalar_grid_names.front();
    }
    std::size_t i = 0;
    while (i < out.grid_names.size() && out.grid_names[i] != grid_name) ++i;
    if (i == out.grid_names.size())
        throw input_error("'" + path + "' has no grid named '" + grid_name + "'; its grids are " +
                          join(out.grid_names) + " (choose one with " + purpose.option + ")");
    if (!scalar[i])
        throw input_error("grid '" + grid_name + "' in '" + path + "' holds " + types[i] + " values; pqdc can " +
                          purpose.use + " " + purpose.kinds + " grids: " +
                          (out.scalar_grid_names.empty() ? std::string("this file has none")
                                                         : "choose one of " + join(out.scalar_grid_names)));
    check_unique_name(path, grid_name, out, purpose);
    return grid_name;
}

}  // namespace

namespace {

/// Whether to delay-load the grid `name` described by `metas`.
bool delay(VolumeLoading loading, std::uint64_t delay_above_bytes, const openvdb::GridPtrVec& metas,
           const std::string& name) {
    if (loading != VolumeLoading::delayed_if_larger) return loading == VolumeLoading::delayed;
    for (const auto& meta : metas) {
        if (meta->getName() != name) continue;
        const auto bytes = meta->getMetadata<openvdb::Int64Metadata>(openvdb::GridBase::META_FILE_MEM_BYTES);
        return bytes && bytes->value() > 0 && std::uint64_t(bytes->value()) > delay_above_bytes;
    }
    return false;
}

/// Reads every leaf buffer a delayed read left in the mapped file, leaves
/// in parallel (each buffer loads itself under its own lock), for
/// LeafDecoding::parallel.
void load_leaf_buffers(const openvdb::GridBase& grid) {
    using Loadable = openvdb::TypeList<openvdb::FloatGrid, openvdb::DoubleGrid>;
    const bool typed = grid.apply<Loadable>([](const auto& typed_grid) {
        using TreeT = typename std::decay_t<decltype(typed_grid)>::TreeType;
        openvdb::tree::LeafManager<const TreeT> leaves(typed_grid.tree());
        leaves.foreach([](const typename TreeT::LeafNodeType& leaf, std::size_t) { leaf.buffer().data(); });
    });
    if (!typed) grid.readNonresidentBuffers();  // other value types (not read so today): one after the other
}

LoadedGrid read_grid_for(const std::string& path, const std::string& grid_name, const Purpose& purpose,
                         VolumeLoading loading, std::uint64_t delay_above_bytes = 0,
                         LeafDecoding decoding = LeafDecoding::serial) {
    openvdb::initialize();
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0)
        throw input_error("cannot open '" + path + "': " + std::strerror(errno) + " (check the path)");
    if (S_ISDIR(st.st_mode)) {
        if (is_brick_store(path))
            throw input_error("'" + path + "' is a pqdc brick store; a grid to " + purpose.use +
                              " must come from a .vdb file" +
                              (&purpose == &kMeshing ? " (pqdc STORE and pqdc.extract mesh a store; "
                                                       "pqdc::read_brick_store reads one)"
                                                     : ""));
        struct stat shell {};
        if (::stat((path + "/grid.vdb").c_str(), &shell) == 0)  // a brick store's first file, but no index.txt
            throw input_error("'" + path + "' is an incomplete brick store (no index.txt: pqdc-bricks did not "
                              "finish writing it); delete it and write it again");
        throw input_error("'" + path + "' is a directory; give the path of a .vdb file or of a brick store");
    }
    if (!S_ISREG(st.st_mode))
        throw input_error("'" + path + "' is not a regular file (a device, pipe or socket); give the path of a .vdb file");
    if (st.st_size == 0)
        throw input_error("'" + path + "' is empty (0 bytes), not an OpenVDB file; was it written completely?");
    {
        std::ifstream probe(path, std::ios::binary);
        if (!probe)
            throw input_error("cannot read '" + path + "': " + std::strerror(errno) + " (check its permissions)");
    }

    const std::int64_t size = std::int64_t(st.st_size);
    const FileLayout layout = read_layout(path, size);
    if (layout.known && !layout.header_complete) throw_truncated(path, "it ends inside its header");
    for (const auto& g : layout.grids)
        if (g.end > size)
            throw_truncated(path, g.name.empty() ? "it ends inside a grid descriptor"
                                                 : "it has " + std::to_string(size) + " bytes, but grid '" + g.name +
                                                       "' ends at byte " + std::to_string(g.end));

    LoadedGrid out;
    std::vector<std::string> types;  // value types for messages, parallel to out.grid_names
    std::vector<bool> scalar;
    auto add = [&](const openvdb::GridBase& g) {
        out.grid_names.push_back(g.getName());
        types.push_back(g.isType<openvdb::MaskGrid>() ? "mask" : g.valueType());  // a mask reports "bool"
        scalar.push_back(purpose.accept(g.type()));
        if (scalar.back()) out.scalar_grid_names.push_back(g.getName());
    };
    try {
        if (layout.known && !layout.has_grid_offsets) {
            // Written as one stream (e.g. by io::Stream): no offsets to seek to,
            // every grid is read in sequence; our own stream shows a short read.
            std::ifstream is(path, std::ios::binary);
            openvdb::io::Stream stream(is, /*delayLoad=*/false);
            if (is.fail()) throw_truncated(path, "its data ends early");
            const openvdb::GridPtrVecPtr grids = stream.getGrids();
            // By name, as io::File (and so vdb_print) would list them.
            if (grids) {
                std::stable_sort(grids->begin(), grids->end(),
                                 [](const auto& a, const auto& b) { return a->getName() < b->getName(); });
                for (const auto& g : *grids) add(*g);
            }
            const std::string name = choose_grid(path, grid_name, types, scalar, out, purpose);
            for (const auto& g : *grids)
                if (g->getName() == name) {
                    out.grid = g;
                    break;
                }
        } else {
            openvdb::io::File file(path);
            // The metadata first (it decides the loading); a second open
            // costs the header only.
            file.open(false);
            const openvdb::GridPtrVecPtr metas = file.readAllGridMetadata();
            // io::File lists grids by name (its descriptor map), which is the
            // order vdb_print shows and so the order users expect "first" in.
            for (const auto& meta : *metas) add(*meta);
            const std::string name = choose_grid(path, grid_name, types, scalar, out, purpose);
            out.delay_loaded = delay(loading, delay_above_bytes, *metas, name);
            const bool mapped = out.delay_loaded || decoding == LeafDecoding::parallel;
            if (mapped) {
                // Mapped in place, never copied to a temporary file (the
                // point of a delayed read is not to hold it twice); the file
                // must not change while it is in use.
                file.close();
                file.setCopyMaxBytes(0);
                file.open(/*delayLoad=*/true);
            }
            out.grid = file.readGrid(name);
            file.close();
            // A whole read leaves nothing in the file, which may change or
            // vanish afterwards without harm.
            if (mapped && !out.delay_loaded) load_leaf_buffers(*out.grid);
        }
    } catch (const pqdc::error&) {
        throw;
    } catch (const std::bad_alloc&) {
        throw resource_error("reading '" + path + "' ran out of memory; the file is corrupt (a size field is "
                             "garbage) or its grid does not fit in memory");
    } catch (const std::exception& e) {
        throw input_error("'" + path + "' is not a readable OpenVDB file (corrupt, truncated or another format: " +
                          detail::foreign_message(e.what()) + "); re-export it or check that the copy is complete");
    }
    if (!out.grid) throw input_error("'" + path + "': reading the grid failed; re-export the file");
    check_transform_usable(*out.grid, path);
    return out;
}

}  // namespace

LoadedGrid read_scalar_grid(const std::string& path, const std::string& grid_name, VolumeLoading loading,
                            std::uint64_t delay_above_bytes, LeafDecoding decoding) {
    return read_grid_for(path, grid_name, kMeshing, loading, delay_above_bytes, decoding);
}

LoadedGrid read_mask_grid(const std::string& path, const std::string& grid_name) {
    LoadedGrid mask = read_grid_for(path, grid_name, kMasking, VolumeLoading::whole);
    // Here, where the file is known: meshing refuses it too, but named the
    // meshed volume's file.
    if (mask.grid && !mask.grid->transform().isLinear())
        throw input_error("'" + path + "': mask grid '" + mask.grid->getName() + "' has a " +
                          mask.grid->transform().mapType() +
                          " transform, which is not affine; resample the mask to a linear transform");
    return mask;
}

namespace {

/// Feeds OpenVDB's stream writer into the shared atomic writer, so a failed
/// write() (disk full, EFBIG) throws io_error at once instead of leaving the
/// ostream silently failed while OpenVDB keeps writing.
class AtomicStreamBuf : public std::streambuf {
public:
    explicit AtomicStreamBuf(detail::AtomicFileWriter& out) : out_(out) {}

protected:
    std::streamsize xsputn(const char* s, std::streamsize n) override {
        out_.append(s, std::size_t(n));
        return n;
    }
    int_type overflow(int_type c) override {
        if (!traits_type::eq_int_type(c, traits_type::eof())) {
            const char ch = traits_type::to_char_type(c);
            out_.append(&ch, 1);
        }
        return traits_type::not_eof(c);
    }

    // OpenVDB's seekable format writes each grid's descriptor, then seeks
    // back to fill in its offsets.
    pos_type seekoff(off_type off, std::ios_base::seekdir dir, std::ios_base::openmode) override {
        if (dir == std::ios_base::cur && off == 0) return pos_type(off_type(out_.position()));
        if (dir == std::ios_base::end) return pos_type(off_type(-1));
        const off_type to = dir == std::ios_base::beg ? off : off_type(out_.position()) + off;
        out_.seek(std::uint64_t(to));
        return pos_type(to);
    }
    pos_type seekpos(pos_type pos, std::ios_base::openmode which) override {
        return seekoff(off_type(pos), std::ios_base::beg, which);
    }

private:
    detail::AtomicFileWriter& out_;
};

/// io::File's format (grid offsets: random access and delayed loading)
/// onto any stream that can seek, here the atomic writer's.
class SeekableArchive : public openvdb::io::Archive {
public:
    explicit SeekableArchive(std::ostream& os) : os_(os) {}
    void write(const openvdb::GridCPtrVec& grids, const openvdb::MetaMap& meta = openvdb::MetaMap()) const override {
        Archive::write(os_, grids, /*seekable=*/true, meta);
    }

private:
    std::ostream& os_;
};

}  // namespace

void write_grid(const openvdb::GridBase& grid, const std::string& path) {
    openvdb::initialize();
    detail::AtomicFileWriter out(path);  // throws io_error naming the path
    AtomicStreamBuf buf(out);
    std::ostream os(&buf);
    // Rethrow the writer's io_error from inside OpenVDB's writes.
    os.exceptions(std::ios::badbit | std::ios::failbit);
    try {
        openvdb::GridCPtrVec grids{grid.copyGrid()};
        // To a file: io::File's seekable format, which can be read with
        // delayed loading (VolumeLoading::delayed); standard output cannot seek.
        if (path == "-") openvdb::io::Stream(os).write(grids);
        else SeekableArchive(os).write(grids);
    } catch (const pqdc::error&) {
        throw;
    } catch (const std::exception& e) {
        throw io_error("cannot write '" + path + "': " + e.what());
    }
    out.commit();
}

}  // namespace pqdc
