#include "pqdc/volume_io.hpp"

#include "pqdc/exceptions.hpp"

#include <openvdb/io/File.h>
#include <openvdb/io/Stream.h>

#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <random>
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

}  // namespace

LoadedGrid read_scalar_grid(const std::string& path, const std::string& grid_name) {
    openvdb::initialize();
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0)
        throw input_error("cannot open '" + path + "': " + std::strerror(errno));
    if (S_ISDIR(st.st_mode)) throw input_error("'" + path + "' is a directory; give the path of a .vdb file");
    if (st.st_size == 0) throw input_error("'" + path + "' is empty; it is not an OpenVDB file");
    {
        std::ifstream probe(path, std::ios::binary);
        if (!probe) throw input_error("cannot read '" + path + "': " + std::strerror(errno));
    }

    LoadedGrid out;
    try {
        openvdb::io::File file(path);
        // No delayed loading: the whole grid is read (and validated) now, and
        // the file may change or vanish afterwards without harm.
        file.open(false);
        openvdb::GridPtrVecPtr metas = file.readAllGridMetadata();
        std::vector<std::string> types;
        for (const auto& g : *metas) {
            out.grid_names.push_back(g->getName());
            types.push_back(g->type());
            if (is_scalar_type(g->type())) out.scalar_grid_names.push_back(g->getName());
        }
        if (metas->empty()) throw input_error("'" + path + "' contains no grids");

        std::string name = grid_name;
        if (name.empty()) {
            if (out.scalar_grid_names.empty()) {
                std::ostringstream s;
                s << "'" << path << "' has no float or double grid to mesh; its grids are ";
                for (std::size_t i = 0; i < out.grid_names.size(); ++i)
                    s << (i ? ", '" : "'") << out.grid_names[i] << "' (" << types[i] << ")";
                throw input_error(s.str());
            }
            name = out.scalar_grid_names.front();
            out.chosen_automatically = true;
        } else {
            std::size_t i = 0;
            while (i < out.grid_names.size() && out.grid_names[i] != name) ++i;
            if (i == out.grid_names.size())
                throw input_error("'" + path + "' has no grid named '" + name + "'; its grids are " +
                                  join(out.grid_names));
            if (!is_scalar_type(types[i]))
                throw input_error("grid '" + name + "' in '" + path + "' holds " + types[i] +
                                  " values; pqdc meshes float or double grids: " + join(out.scalar_grid_names));
        }
        out.grid = file.readGrid(name);
        file.close();
    } catch (const pqdc::error&) {
        throw;
    } catch (const std::exception& e) {
        throw input_error("'" + path + "' is not a readable OpenVDB file (corrupt, truncated or another format): " +
                          e.what());
    }
    if (!out.grid) throw input_error("'" + path + "': reading the grid failed");
    return out;
}

void write_grid(const openvdb::GridBase& grid, const std::string& path) {
    openvdb::initialize();
    std::random_device rd;
    const std::string tmp = path + ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(rd());
    try {
        // Our own stream, so a short write (disk full) is seen in its state.
        std::ofstream os(tmp, std::ios::binary | std::ios::trunc);
        if (!os) throw io_error(std::strerror(errno));
        openvdb::GridCPtrVec grids{grid.copyGrid()};
        openvdb::io::Stream(os).write(grids);
        os.flush();
        if (!os) throw io_error("write failed (disk full?)");
        os.close();
        if (!os) throw io_error("closing failed (disk full?)");
        FILE* f = std::fopen(tmp.c_str(), "rb");
        if (f) {
            ::fsync(fileno(f));
            std::fclose(f);
        }
    } catch (const std::exception& e) {
        std::remove(tmp.c_str());
        throw io_error("cannot write '" + path + "': " + e.what());
    }
    if (std::rename(tmp.c_str(), path.c_str()) != 0) {
        const int err = errno;
        std::remove(tmp.c_str());
        throw io_error("cannot write '" + path + "': " + std::strerror(err));
    }
}

}  // namespace pqdc
