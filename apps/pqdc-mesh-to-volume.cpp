// pqdc-mesh-to-volume: turns a closed polygon mesh (OFF, OBJ, PLY) into a
// narrow-band level set .vdb with exact distances (pqdc::mesh_to_level_set),
// to make test volumes from CAD and scanned models.
// Exit codes: 0 ok, 1 runtime error (unreadable input, write failure), 2 usage error.

#include "pqdc/exceptions.hpp"
#include "pqdc/mesh.hpp"
#include "pqdc/mesh_io.hpp"
#include "pqdc/mesh_to_volume.hpp"
#include "pqdc/volume_io.hpp"

#include "cli_util.hpp"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

namespace {

using pqdc_cli::UsageError;
using pqdc_cli::parse_finite;
using pqdc_cli::parse_integer;

const char* kUsage = R"(usage: pqdc-mesh-to-volume INPUT.(off|obj|ply|stl) -o OUTPUT.vdb [options]

Converts a closed (watertight) polygon mesh into a narrow-band signed distance
level set (OpenVDB float grid, class level set, inside negative, world units).)";
const char* kFooter = R"(Values are exact distances to the mesh. On a closed, consistently oriented mesh
the sign is exact too; otherwise it comes from OpenVDB's flood fill, which
needs a closed surface: open meshes give unreliable signs near their holes.)";
const std::vector<pqdc_cli::OptionSpec> kSpecs = {
    {"--resolution", true, "voxels along the longest side of the mesh's bounding box, in [8, 16384] (default 128)", "Lattice"},
    {"--voxel-size", true, "voxel size in world units (> 0); replaces --resolution", "Lattice"},
    {"--half-width", true, "narrow band half width in voxels, in [1, 1000] (default 3)", "Lattice"},
    {"--distances", true, "exact (default) or openvdb: meshToLevelSet's own values, faster, off by up to a voxel near concave creases", "Lattice"},
    {"-o,--output", true, "FILE.vdb, written atomically (temporary file + rename)", "Output"},
    {"--grid-name", true, "name of the grid in the file (default surface)", "Output"},
    {"-q,--quiet", false, "print errors and warnings only", "Output"},
};


struct Options {
    std::string input;
    std::string output;
    std::string grid_name = "surface";
    int resolution = 128;
    double voxel_size = 0.0;  // 0 = from resolution
    double half_width = 3.0;
    pqdc::LevelSetDistances distances = pqdc::LevelSetDistances::exact;
    bool quiet = false;
};

std::string lower_extension(const std::string& path)
{
    const std::size_t slash = path.find_last_of('/');
    const std::size_t dot = path.find_last_of('.');
    if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
    std::string ext = path.substr(dot + 1);
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
    return ext;
}

/// Returns false when --help was handled.
bool parse(int argc, char** argv, Options& o)
{
    bool have_resolution = false;
    std::vector<std::string> positional;
    bool done = false;
    const auto given = pqdc_cli::parse_options(argc, argv, "pqdc-mesh-to-volume", kUsage, kSpecs, "INPUT: .off (ASCII OFF/COFF/NOFF), .obj, .ply or .stl; polygons of any size (n-gons are fan-triangulated)", positional, done, kFooter);
    if (done) return false;
    for (const auto& [a, v] : given) {
        if (a == "--output") {
            o.output = v;
        } else if (a == "--resolution") {
            o.resolution = static_cast<int>(parse_integer(a, v, 8, 16384));
            have_resolution = true;
        } else if (a == "--voxel-size") {
            o.voxel_size = parse_finite(a, v);
            if (!(o.voxel_size > 0.0)) throw UsageError{"--voxel-size must be > 0 (world units)"};
        } else if (a == "--half-width") {
            o.half_width = parse_finite(a, v);
            if (!(o.half_width >= 1.0 && o.half_width <= 1000.0)) {
                throw UsageError{"--half-width must be in [1, 1000] voxels"};
            }
        } else if (a == "--distances") {
            if (v == "exact") {
                o.distances = pqdc::LevelSetDistances::exact;
            } else if (v == "openvdb") {
                o.distances = pqdc::LevelSetDistances::openvdb;
            } else {
                throw UsageError{"--distances must be exact or openvdb, not '" + v + "'"};
            }
        } else if (a == "--grid-name") {
            o.grid_name = v;
            if (o.grid_name.empty()) throw UsageError{"--grid-name must not be empty"};
        } else if (a == "--quiet" || a == "-q") {
            o.quiet = true;
        }
    }
    if (positional.size() != 1) throw UsageError{"expected exactly one input mesh file"};
    o.input = positional[0];
    if (o.output.empty()) throw UsageError{"no output file; give -o OUTPUT.vdb"};
    if (lower_extension(o.output) != "vdb") {
        throw UsageError{"output '" + o.output + "' must end in .vdb"};
    }
    if (have_resolution && o.voxel_size > 0.0) {
        throw UsageError{"give either --resolution or --voxel-size, not both"};
    }
    const std::string ext = lower_extension(o.input);
    if (ext != "off" && ext != "obj" && ext != "ply" && ext != "stl") {
        throw UsageError{"input '" + o.input + "': unsupported extension; use .off, .obj, .ply or .stl"};
    }
    return true;
}

int run(const Options& o)
{
    pqdc_cli::start_openvdb();
    const pqdc::Mesh mesh = pqdc::read_mesh(o.input);
    if (mesh.points.empty() || mesh.face_count() == 0) {
        throw pqdc::input_error("'" + o.input + "' has no faces; nothing to convert");
    }
    // The surface's box: a vertex no face uses (a stray point far away) set
    // the voxel size of --resolution (62.5 for a unit tetrahedron).
    std::vector<bool> used(mesh.points.size(), false);
    for (const auto& t : mesh.triangles)
        for (int k = 0; k < 3; ++k) used[t[k]] = true;
    for (const auto& q : mesh.quads)
        for (int k = 0; k < 4; ++k) used[q[k]] = true;
    openvdb::BBoxd bounds;
    for (std::size_t i = 0; i < mesh.points.size(); ++i) {
        const openvdb::Vec3d& p = mesh.points[i];
        if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) {
            throw pqdc::input_error("'" + o.input + "' has a non-finite vertex coordinate");
        }
        if (used[i]) bounds.expand(p);
    }
    const openvdb::Vec3d extent = bounds.extents();
    const double longest = std::max(extent[0], std::max(extent[1], extent[2]));
    if (!(longest > 0.0)) throw pqdc::input_error("'" + o.input + "' has all vertices at one point");

    const double voxel_size = o.voxel_size > 0.0 ? o.voxel_size : longest / o.resolution;
    const double cells = longest / voxel_size;
    if (cells > 16384.0) {
        throw pqdc::option_error("--voxel-size " + pqdc_cli::number_text(voxel_size) + " gives " + pqdc_cli::number_text(cells) +
                                 " voxels along the mesh's longest side; the maximum is 16384");
    }
    if (cells < 1.0) {
        throw pqdc::option_error("--voxel-size " + pqdc_cli::number_text(voxel_size) + " is larger than the mesh (" +
                                 pqdc_cli::number_text(longest) + " world units); choose a smaller one");
    }

    pqdc::MeshToLevelSetOptions options;
    options.voxel_size = voxel_size;
    options.half_width_voxels = o.half_width;
    options.distances = o.distances;
    pqdc::MeshToLevelSetStats stats;
    openvdb::FloatGrid::Ptr grid;
    try {
        grid = pqdc::mesh_to_level_set(mesh, options, &stats);
    } catch (const pqdc::input_error& e) {
        throw pqdc::input_error("'" + o.input + "': " + e.what());
    } catch (const pqdc::option_error& e) {  // a voxel size OpenVDB cannot take, from --voxel-size or --resolution
        std::string what = e.what();
        const std::string field = "MeshToLevelSetOptions::voxel_size";
        if (what.rfind(field, 0) == 0) what = "'" + o.input + "': the voxel size" + what.substr(field.size());
        throw pqdc::option_error(what);
    }
    // The flood fill needs a closed surface; say so rather than silently
    // writing wrong signs.
    if (stats.boundary_edges > 0) {
        std::cerr << "pqdc-mesh-to-volume: warning: '" << o.input << "' is not closed (" << stats.boundary_edges
                  << " edges belong to one face only); the level set's signs may be wrong near the holes\n";
    } else if (stats.inconsistent_edges > 0 && o.distances == pqdc::LevelSetDistances::exact) {
        std::cerr << "pqdc-mesh-to-volume: warning: '" << o.input << "' has " << stats.inconsistent_edges
                  << " edges shared by more than two faces or walked the same way by two; signs come from "
                     "OpenVDB's flood fill and may be wrong next to the surface\n";
    }
    grid->setName(o.grid_name);
    pqdc::write_grid(*grid, o.output);
    if (!o.quiet) {
        const openvdb::CoordBBox active = grid->evalActiveVoxelBoundingBox();
        std::ostringstream line;
        line << "wrote " << o.output << ": grid '" << o.grid_name << "', voxel size " << voxel_size << ", "
             << grid->activeVoxelCount() << " active voxels in " << active.dim() << " from " << mesh.points.size()
             << " vertices, " << mesh.face_count() << " faces\n";
        pqdc_cli::write_stdout(line.str());
    }
    return 0;
}

}  // namespace

int main(int argc, char** argv)
{
    auto parsed = [](int c, char** v, bool& done) {
        Options o;
        done = !parse(c, v, o);
        return o;
    };
    return pqdc_cli::run_app("pqdc-mesh-to-volume", argc, argv, parsed, run,
                             "use a coarser --resolution or larger --voxel-size");
}
