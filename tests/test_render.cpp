#include "pqdc/render.hpp"

#include "pqdc/exceptions.hpp"
#include "cli_runner.hpp"
#include "pqdc/mesh_io.hpp"
#include "test_files.hpp"
#include "test_meshes.hpp"

#include <catch2/catch.hpp>

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <tbb/global_control.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

namespace {

using openvdb::Vec3d;

std::string make_test_dir(const std::string& name) {
    const std::filesystem::path dir = std::filesystem::path(PQDC_BINARY_DIR) / "test_output" / ("render_" + name);
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
    return dir.string();
}

const float* pixel(const pqdc::Image& im, int x, int y) { return &im.rgba[4 * (std::size_t(y) * im.width + x)]; }

bool is_background(const pqdc::Image& im, int x, int y) {
    const float* p = pixel(im, x, y);
    return p[0] == 1.0f && p[1] == 1.0f && p[2] == 1.0f && p[3] == 1.0f;
}

// Looking down -Z at the box [-1, 1]^3 with no margin: for a square image
// world (x, y) maps to pixel (W/2 (1 + x), H/2 (1 - y)).
pqdc::RenderOptions front_view(int w, int h) {
    pqdc::RenderOptions o;
    o.width = w;
    o.height = h;
    o.azimuth_degrees = 0;
    o.elevation_degrees = 0;
    o.margin = 0;
    o.frame_bounds = openvdb::BBoxd(Vec3d(-1.0), Vec3d(1.0));
    return o;
}

pqdc::Mesh unit_triangle(bool facing_viewer) {
    pqdc::Mesh m;
    m.points = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
    m.triangles = {facing_viewer ? openvdb::Vec3I(0, 1, 2) : openvdb::Vec3I(0, 2, 1)};
    return m;
}

/// The unit sphere at the origin.
pqdc::Mesh uv_sphere(int rings, int segments) {
    return pqdc_test::uv_sphere(openvdb::Vec3d(0.0), 1.0, rings, segments);
}

}  // namespace

TEST_CASE("a triangle lands where the camera puts it", "[render]") {
    const int W = 64, H = 64;
    const pqdc::Image im = pqdc::render(unit_triangle(true), front_view(W, H));
    REQUIRE(im.width == W);
    REQUIRE(im.height == H);
    REQUIRE(im.rgba.size() == std::size_t(W) * H * 4);
    auto px = [&](double x, double y) { return std::make_pair(int(W / 2.0 * (1 + x)), int(H / 2.0 * (1 - y))); };
    // Inside the triangle (away from its edges): shaded surface.
    for (auto [x, y] : {px(0.25, 0.25), px(0.1, 0.6), px(0.6, 0.1)}) {
        INFO(x << "," << y);
        CHECK_FALSE(is_background(im, x, y));
        CHECK(pixel(im, x, y)[3] == 1.0f);
    }
    // Outside: left half, bottom half, beyond the hypotenuse.
    std::size_t covered_elsewhere = 0;
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const double wx = 2.0 * (x + 0.5) / W - 1, wy = 1 - 2.0 * (y + 0.5) / H;
            const bool clearly_outside = wx < -0.04 || wy < -0.04 || wx + wy > 1.06;
            if (clearly_outside && !is_background(im, x, y)) ++covered_elsewhere;
        }
    CHECK(covered_elsewhere == 0);
    // A wide image keeps the aspect ratio: the box spans the full height and
    // is centered horizontally.
    const pqdc::Image wide = pqdc::render(unit_triangle(true), front_view(2 * W, H));
    CHECK_FALSE(is_background(wide, W + W / 8, H / 2 - H / 8));  // world (0.25, 0.25)
    CHECK(is_background(wide, W + W / 2 + W / 8, H / 2 - H / 8));  // world (1.25, 0.25): outside
}

TEST_CASE("front faces and back faces get different colors", "[render]") {
    pqdc::RenderOptions o = front_view(40, 40);
    o.edge_width_pixels = 0;
    const pqdc::Image front = pqdc::render(unit_triangle(true), o);
    const pqdc::Image back = pqdc::render(unit_triangle(false), o);
    const float* f = pixel(front, 25, 15);
    const float* b = pixel(back, 25, 15);
    CHECK(f[2] > f[0]);  // bluish grey
    CHECK(b[0] > b[2]);  // red
}

TEST_CASE("edge lines darken pixels along polygon edges only", "[render]") {
    // A unit square quad: its sides get lines, its diagonal does not.
    pqdc::Mesh m;
    m.points = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
    m.quads = {{0, 1, 2, 3}};
    pqdc::RenderOptions o = front_view(100, 100);
    o.edge_width_pixels = 2;
    const pqdc::Image lines = pqdc::render(m, o);
    o.edge_width_pixels = 0;
    const pqdc::Image plain = pqdc::render(m, o);
    // Square covers pixels x in [50, 100), y in [0, 50).
    auto lum = [](const pqdc::Image& im, int x, int y) {
        const float* p = pixel(im, x, y);
        return p[0] + p[1] + p[2];
    };
    CHECK(lum(lines, 50, 25) < 0.5f * lum(plain, 50, 25));   // left side x = 0
    CHECK(lum(lines, 75, 49) < 0.5f * lum(plain, 75, 49));   // bottom side y = 0
    CHECK(lum(lines, 75, 25) == lum(plain, 75, 25));         // on the diagonal: no line
    CHECK(lum(lines, 65, 40) == lum(plain, 65, 40));         // interior
}

TEST_CASE("smooth shading, perspective and titles render", "[render]") {
    const pqdc::Mesh sphere = uv_sphere(12, 16);
    pqdc::RenderOptions o;
    o.width = 64;
    o.height = 48;
    o.shading = pqdc::Shading::smooth;
    o.projection = pqdc::Projection::perspective;
    const pqdc::Image im = pqdc::render(sphere, o);
    CHECK_FALSE(is_background(im, 32, 24));  // framed in the middle
    CHECK(is_background(im, 0, 0));
    CHECK(is_background(im, 63, 47));
    o.title = "Sphere";
    const pqdc::Image titled = pqdc::render(sphere, o);
    CHECK(titled.rgba != im.rgba);
    o.title.clear();
    o.shading = pqdc::Shading::flat;
    CHECK(pqdc::render(sphere, o).rgba != im.rgba);
}

TEST_CASE("an empty mesh gives the background", "[render]") {
    pqdc::RenderOptions o;
    o.width = 8;
    o.height = 8;
    o.background = {0.0f, 0.0f, 0.0f, 0.0f};
    const pqdc::Image im = pqdc::render(pqdc::Mesh{}, o);
    for (float v : im.rgba) CHECK(v == 0.0f);
}

TEST_CASE("render output does not depend on the thread count", "[render]") {
    const std::string dir = make_test_dir("threads");
    const pqdc::Mesh sphere = uv_sphere(40, 60);
    pqdc::RenderOptions o;
    o.width = 160;
    o.height = 120;
    o.title = "threads";
    auto run = [&](int threads, const std::string& path) {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
        const pqdc::Image im = pqdc::render(sphere, o);
        pqdc::write_image(im, path);
        return im;
    };
    const pqdc::Image one = run(1, dir + "/one.png");
    const pqdc::Image two = run(2, dir + "/two.png");
    CHECK(std::memcmp(one.rgba.data(), two.rgba.data(), one.rgba.size() * sizeof(float)) == 0);
    CHECK(pqdc_test::read_file(dir + "/one.png") == pqdc_test::read_file(dir + "/two.png"));
}

TEST_CASE("PNG files have a valid header", "[render]") {
    const std::string dir = make_test_dir("png");
    pqdc::RenderOptions o = front_view(37, 21);
    pqdc::write_image(pqdc::render(unit_triangle(true), o), dir + "/t.PNG");
    const std::string bytes = pqdc_test::read_file(dir + "/t.PNG");
    REQUIRE(bytes.size() > 33);
    CHECK(bytes.compare(0, 8, "\x89PNG\r\n\x1a\n") == 0);
    CHECK(bytes.compare(12, 4, "IHDR") == 0);
    auto be32 = [&](std::size_t at) {
        return (std::uint32_t(std::uint8_t(bytes[at])) << 24) | (std::uint32_t(std::uint8_t(bytes[at + 1])) << 16) |
               (std::uint32_t(std::uint8_t(bytes[at + 2])) << 8) | std::uint32_t(std::uint8_t(bytes[at + 3]));
    };
    CHECK(be32(16) == 37);
    CHECK(be32(20) == 21);
    CHECK(int(bytes[24]) == 8);  // bit depth
    CHECK(int(bytes[25]) == 6);  // RGBA
    CHECK(bytes.find("sRGB") != std::string::npos);
    CHECK(bytes.compare(bytes.size() - 8, 4, "IEND") == 0);
}

TEST_CASE("EXR round trip is exact", "[render]") {
    const std::string dir = make_test_dir("exr");
    pqdc::RenderOptions o = front_view(33, 17);
    o.background.a = 0;  // premultiplied alpha with real coverage values
    const pqdc::Image im = pqdc::render(uv_sphere(8, 8), o);
    const std::string path = dir + "/s.exr";
    pqdc::write_image(im, path);

    Imf::InputFile file(path.c_str());
    const Imath::Box2i dw = file.header().dataWindow();
    const int w = dw.max.x - dw.min.x + 1, h = dw.max.y - dw.min.y + 1;
    REQUIRE(w == 33);
    REQUIRE(h == 17);
    for (const char* c : {"R", "G", "B", "A"}) {
        REQUIRE(file.header().channels().findChannel(c) != nullptr);
        CHECK(file.header().channels().findChannel(c)->type == Imf::FLOAT);
    }
    std::vector<float> back(std::size_t(w) * h * 4, -1.0f);
    Imf::FrameBuffer fb;
    const char* names[4] = {"R", "G", "B", "A"};
    for (int k = 0; k < 4; ++k)
        fb.insert(names[k], Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(back.data() + k), sizeof(float) * 4,
                                       sizeof(float) * 4 * std::size_t(w)));
    file.setFrameBuffer(fb);
    file.readPixels(dw.min.y, dw.max.y);
    CHECK(back == im.rgba);
    bool some_partial_alpha = false;
    for (std::size_t i = 3; i < back.size(); i += 4) some_partial_alpha |= back[i] > 0 && back[i] < 1;
    CHECK(some_partial_alpha);  // antialiased silhouette
}

TEST_CASE("render rejects bad options and paths", "[render]") {
    const std::string dir = make_test_dir("errors");
    pqdc::RenderOptions o;
    o.width = 0;
    CHECK_THROWS_AS(pqdc::render(unit_triangle(true), o), pqdc::option_error);
    o = {};
    o.supersampling = 9;
    CHECK_THROWS_AS(pqdc::validate(o), pqdc::option_error);
    o = {};
    o.elevation_degrees = 91;
    CHECK_THROWS_WITH(pqdc::validate(o), Catch::Contains("elevation_degrees"));
    o = {};
    o.up = Vec3d(0.0);
    CHECK_THROWS_AS(pqdc::validate(o), pqdc::option_error);
    o = {};
    o.frame_bounds = openvdb::BBoxd(Vec3d(1.0), Vec3d(1.0));  // a point: the image came out blank
    CHECK_THROWS_WITH(pqdc::validate(o), Catch::Contains("frame_bounds is a single point"));
    o.frame_bounds = openvdb::BBoxd(Vec3d(0.0), Vec3d(1.0, 1.0, 0.0));  // a flat box frames a flat mesh
    CHECK_NOTHROW(pqdc::validate(o));

    pqdc::Mesh bad = unit_triangle(true);
    bad.triangles.emplace_back(0, 1, 3);
    CHECK_THROWS_AS(pqdc::render(bad, pqdc::RenderOptions{}), pqdc::input_error);

    pqdc::RenderOptions small;
    small.width = small.height = 8;
    const pqdc::Image im = pqdc::render(unit_triangle(true), small);
    CHECK_THROWS_AS(pqdc::write_image(im, dir + "/x.jpg"), pqdc::option_error);
    CHECK_THROWS_AS(pqdc::write_image(im, dir + "/missing/x.png"), pqdc::io_error);
    CHECK_THROWS_WITH(pqdc::write_image(im, dir + "/missing/x.png"), Catch::Contains("missing/x.png"));
    CHECK(std::distance(std::filesystem::directory_iterator(dir), std::filesystem::directory_iterator()) == 0);
}

#ifdef PQDC_RENDER_PATH
TEST_CASE("pqdc-render refuses a point frame and a directory output before rendering", "[render][cli]") {
    const std::string dir = make_test_dir("cli");
    pqdc::write_mesh(unit_triangle(true), dir + "/t.ply");
    std::filesystem::create_directory(dir + "/d.png");
    pqdc_test::RunSpec spec;
    spec.cwd = dir;
    spec.args = {"t.ply", "--frame", "0,0,0,0,0,0", "-o", "f.png"};
    const auto point = pqdc_test::run_program(PQDC_RENDER_PATH, spec);
    CHECK(point.exit_code == 2);
    CHECK_THAT(point.err, Catch::Contains("--frame is a single point"));
    spec.args = {"t.ply", "-o", "d.png", "--width", "4000", "--height", "4000"};
    const auto directory = pqdc_test::run_program(PQDC_RENDER_PATH, spec);
    CHECK(directory.exit_code == 1);
    CHECK_THAT(directory.err, Catch::Contains("cannot write 'd.png' (-o): it is a directory; give a file name"));
    CHECK(std::filesystem::is_empty(dir + "/d.png"));
    CHECK_FALSE(std::filesystem::exists(dir + "/f.png"));
}
#endif
