// pqdc-render: a mesh to a PNG or EXR image with the software rasterizer.
// Exit codes: 0 ok, 1 runtime error, 2 usage error.

#include "pqdc/exceptions.hpp"
#include "pqdc/mesh_io.hpp"
#include "pqdc/render.hpp"

#include "cli_util.hpp"

#include <tbb/global_control.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <iostream>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

namespace {

using pqdc_cli::UsageError;
using pqdc_cli::parse_finite;
using pqdc_cli::parse_integer;

const char* kUsage = R"(usage: pqdc-render MESH.(obj|ply|off|stl) -o IMAGE.(png|exr) [options]

Renders a mesh with flat or smooth shading and thin lines along the polygon
edges. Back faces (seen from behind) are drawn in red. The image is the same
bytes for any thread count.)";
const std::vector<pqdc_cli::OptionSpec> kSpecs = {
    {"-o,--output", true, ".png (8-bit sRGB RGBA) or .exr (float linear RGBA); written atomically"},
    {"--width", true, "image width in pixels (default 1024)"},
    {"--height", true, "image height in pixels (default 1024)"},
    {"--azimuth", true, "degrees around the up axis; 0 looks from +Z for +Y up (default 30)", "Camera"},
    {"--elevation", true, "degrees above the horizon, [-90, 90] (default 25)", "Camera"},
    {"--up", true, "X,Y,Z: world up axis (default 0,1,0)", "Camera"},
    {"--perspective", false, "pinhole camera instead of orthographic", "Camera"},
    {"--fov", true, "vertical field of view for --perspective, degrees (default 30)", "Camera"},
    {"--frame", true, "X0,Y0,Z0,X1,Y1,Z1: frame this world box instead of the mesh bounds (keeps the camera fixed across several renders)", "Camera"},
    {"--edges", true, "on|off: lines along polygon edges (default on)", "Look"},
    {"--edge-width", true, "line width in pixels (default 1)", "Look"},
    {"--shading", true, "flat|smooth: face normals or interpolated vertex normals (default flat)", "Look"},
    {"--ssaa", true, "N x N samples per pixel, [1, 8] (default 3)", "Look"},
    {"--title", true, "caption in the top-left corner", "Look"},
    {"--transparent", false, "transparent background (alpha 0) instead of white", "Look"},
    {"--threads", true, "worker threads (default: all cores)", "Run"},
};


std::vector<double> parse_list(const std::string& option, const std::string& text, std::size_t count) {
    std::vector<double> values;
    std::stringstream in(text);
    std::string item;
    while (std::getline(in, item, ',')) values.push_back(parse_finite(option, item));
    if (values.size() != count)
        throw UsageError{option + " expects " + std::to_string(count) + " comma-separated numbers, got '" + text + "'"};
    return values;
}

struct CliOptions {
    std::string mesh;
    std::string output;
    pqdc::RenderOptions render;
    int threads = 0;
};

CliOptions parse(int argc, char** argv, bool& done) {
    CliOptions o;
    done = false;
    std::vector<std::string> positional;
    bool edges_off = false;
    const auto given = pqdc_cli::parse_options(argc, argv, "pqdc-render", kUsage, kSpecs, "the mesh: .obj, .ply, .off or .stl (what pqdc writes)", positional, done);
    if (done) return o;
    for (const auto& [a, v] : given) {
        if (a == "--output") {
            o.output = v;
        } else if (a == "--width") {
            o.render.width = int(parse_integer(a, v, 1, 16384));
        } else if (a == "--height") {
            o.render.height = int(parse_integer(a, v, 1, 16384));
        } else if (a == "--azimuth") {
            o.render.azimuth_degrees = parse_finite(a, v);
        } else if (a == "--elevation") {
            o.render.elevation_degrees = parse_finite(a, v);
        } else if (a == "--up") {
            const auto up = parse_list(a, v, 3);
            o.render.up = openvdb::Vec3d(up[0], up[1], up[2]);
        } else if (a == "--perspective") {
            o.render.projection = pqdc::Projection::perspective;
        } else if (a == "--fov") {
            o.render.field_of_view_degrees = parse_finite(a, v);
        } else if (a == "--frame") {
            const auto b = parse_list(a, v, 6);
            o.render.frame_bounds = openvdb::BBoxd(openvdb::Vec3d(b[0], b[1], b[2]), openvdb::Vec3d(b[3], b[4], b[5]));
            if (!(b[0] <= b[3] && b[1] <= b[4] && b[2] <= b[5]))
                throw UsageError{"--frame expects the minimum corner first: X0<=X1, Y0<=Y1, Z0<=Z1"};
        } else if (a == "--edges") {
            if (v == "off") edges_off = true;
            else if (v == "on") edges_off = false;
            else throw UsageError{"--edges expects on or off, got '" + v + "'"};
        } else if (a == "--edge-width") {
            o.render.edge_width_pixels = parse_finite(a, v);
        } else if (a == "--shading") {
            if (v == "flat") o.render.shading = pqdc::Shading::flat;
            else if (v == "smooth") o.render.shading = pqdc::Shading::smooth;
            else throw UsageError{"--shading expects flat or smooth, got '" + v + "'"};
        } else if (a == "--ssaa") {
            o.render.supersampling = int(parse_integer(a, v, 1, 8));
        } else if (a == "--title") {
            o.render.title = v;
        } else if (a == "--transparent") {
            o.render.background.a = 0;
        } else if (a == "--threads") {
            o.threads = int(parse_integer(a, v, 1, 4096));
        }
    }
    if (edges_off) o.render.edge_width_pixels = 0;  // whatever --edge-width said
    if (pqdc_cli::option_given(given, "--fov") && o.render.projection != pqdc::Projection::perspective)
        throw UsageError{"--fov is the field of view of --perspective; add --perspective or drop it"};
    if (positional.empty()) throw UsageError{"no mesh given (see pqdc-render --help)"};
    if (positional.size() > 1)
        throw UsageError{"more than one mesh given: '" + positional[0] + "' and '" + positional[1] + "'"};
    o.mesh = positional[0];
    if (o.output.empty()) throw UsageError{"no output: give -o IMAGE.png or IMAGE.exr"};
    std::string ext = o.output.size() >= 4 ? o.output.substr(o.output.size() - 4) : "";
    for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    if (ext != ".png" && ext != ".exr")
        throw UsageError{"cannot tell the image format of '" + o.output + "' from its extension; use .png or .exr"};
    pqdc_cli::check_with_option_names([&] { pqdc::validate(o.render); },
                                      {{"RenderOptions::elevation_degrees", "--elevation"},
                                       {"RenderOptions::azimuth_degrees", "--azimuth"},
                                       {"RenderOptions::field_of_view_degrees", "--fov"},
                                       {"RenderOptions::edge_width_pixels", "--edge-width"},
                                       {"RenderOptions::supersampling", "--ssaa"},
                                       {"RenderOptions::frame_bounds", "--frame"},
                                       {"RenderOptions::width", "--width"},
                                       {"RenderOptions::height", "--height"},
                                       {"RenderOptions::up", "--up"}});
    try {
        pqdc::mesh_format_from_path(o.mesh);
    } catch (const pqdc::error& e) {
        throw UsageError{e.what()};
    }
    return o;
}

int run(const CliOptions& o) {
    std::optional<tbb::global_control> threads;
    if (o.threads > 0) threads.emplace(tbb::global_control::max_allowed_parallelism, std::size_t(o.threads));
    pqdc_cli::check_output_path("-o", o.output);  // before the work, as pqdc does
    const pqdc::Mesh mesh = pqdc::read_mesh(o.mesh);
    if (mesh.face_count() == 0)  // a blank image with exit 0 hid an empty or unread file
        throw pqdc::input_error("'" + o.mesh + "' has no faces (" + std::to_string(mesh.points.size()) +
                                " points); nothing to render");
    const std::size_t non_finite = std::size_t(std::count_if(mesh.points.begin(), mesh.points.end(), [](const auto& p) {
        return !(std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]));
    }));
    if (non_finite)
        std::cerr << "pqdc-render: warning: '" << o.mesh << "' has " << non_finite
                  << (non_finite == 1 ? " point" : " points")
                  << " with a NaN or infinite coordinate; the faces using them are not drawn\n";
    pqdc::write_image(pqdc::render(mesh, o.render), o.output);
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    return pqdc_cli::run_app("pqdc-render", argc, argv, parse, run, "use a smaller --width/--height or --ssaa");
}
