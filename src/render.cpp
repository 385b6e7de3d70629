// Software rasterizer. Three passes:
//   1. project every vertex to sample space (parallel, per vertex);
//   2. bin render triangles (mesh triangles, quads as 0-1-2 / 0-2-3) into
//      horizontal bands of output rows, in triangle order (serial);
//   3. per band (parallel): z-buffer the band's samples keeping the nearest
//      triangle, ties to the lower index, then shade every sample from its
//      triangle id and average the samples of each pixel.
// Every value written depends only on the band's inputs, never on which
// thread ran it or in which order, so the bytes are thread-count independent.
#include "pqdc/render.hpp"

#include "pqdc/exceptions.hpp"

#include "io/atomic_file.hpp"

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfIO.h>
#include <ImfOutputFile.h>
#include <png.h>
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <csetjmp>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

namespace pqdc {

namespace {

#include "render_font.inc"

using Vec3d = openvdb::Vec3d;

constexpr double kPi = 3.14159265358979323846;
constexpr std::uint32_t kNoTriangle = std::numeric_limits<std::uint32_t>::max();
constexpr int kBandRows = 8;  // output rows per parallel task

bool finite(const Vec3d& v) { return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]); }

bool finite(const Color& c) {
    return std::isfinite(c.r) && std::isfinite(c.g) && std::isfinite(c.b) && std::isfinite(c.a);
}

std::string lowercase(std::string s) {
    for (char& c : s)
        if (c >= 'A' && c <= 'Z') c = char(c - 'A' + 'a');
    return s;
}

/// Camera mapping world points to sample-space pixels (x right, y down).
struct Camera {
    Vec3d right, up, forward;  // orthonormal; forward points into the scene
    bool perspective = false;
    Vec3d center;              // orthographic: world point at the image center
    Vec3d eye;                 // perspective: camera position
    double scale = 1;          // orthographic: samples per world unit; perspective: focal length in samples
    double cx = 0, cy = 0;     // image center, samples

    /// Screen position and depth key (smaller = nearer, linear in screen
    /// space: view depth for orthographic, -1/z for perspective). False when
    /// the point is not in front of a perspective camera.
    bool project(const Vec3d& p, double& x, double& y, double& key) const {
        if (!perspective) {
            const Vec3d d = p - center;
            x = cx + scale * d.dot(right);
            y = cy - scale * d.dot(up);
            key = d.dot(forward);
            return true;
        }
        const Vec3d d = p - eye;
        const double z = d.dot(forward);
        if (!(z > 1e-9)) return false;
        x = cx + scale * d.dot(right) / z;
        y = cy - scale * d.dot(up) / z;
        key = -1.0 / z;
        return true;
    }
    /// Unit vector from a surface point towards the viewer.
    Vec3d to_viewer(const Vec3d& p) const {
        if (!perspective) return -forward;
        const Vec3d v = eye - p;
        const double l = v.length();
        return l > 0 ? v / l : -forward;
    }
};

openvdb::BBoxd finite_bounds(const Mesh& mesh) {
    openvdb::BBoxd box(Vec3d(std::numeric_limits<double>::max()), Vec3d(-std::numeric_limits<double>::max()));
    for (const Vec3d& p : mesh.points)
        if (finite(p)) box.expand(p);
    return box;
}

bool box_is_empty(const openvdb::BBoxd& b) {
    return !(b.min()[0] <= b.max()[0] && b.min()[1] <= b.max()[1] && b.min()[2] <= b.max()[2]);
}

/// Places the camera so the framed points fill the image up to the margin:
/// every point of `frame_bounds` when set (a camera that stays put across
/// meshes), else every finite mesh point (a tight fit).
Camera make_camera(const RenderOptions& o, const Mesh& mesh, const openvdb::BBoxd& bounds, bool frame_mesh_points,
                   int samples_x, int samples_y) {
    Camera cam;
    const Vec3d u = o.up.unitSafe();
    // Reference horizontal axis: +Z projected into the horizontal plane, or +X
    // when up is (nearly) parallel to Z.
    Vec3d r0 = Vec3d(0, 0, 1) - u * u[2];
    if (r0.length() < 1e-6) r0 = Vec3d(1, 0, 0) - u * u[0];
    r0.normalize();
    const Vec3d r1 = u.cross(r0);
    const double az = o.azimuth_degrees * kPi / 180.0, el = o.elevation_degrees * kPi / 180.0;
    const Vec3d horizontal = std::cos(az) * r0 + std::sin(az) * r1;
    const Vec3d to_eye = std::cos(el) * horizontal + std::sin(el) * u;
    cam.forward = -to_eye;
    cam.right = -std::sin(az) * r0 + std::cos(az) * r1;
    cam.up = cam.right.cross(cam.forward);
    cam.cx = samples_x * 0.5;
    cam.cy = samples_y * 0.5;
    const double margin = o.margin * std::min(samples_x, samples_y);

    // A first camera that sees everything: orthographic at unit scale, or a
    // perspective camera outside the bounding sphere with its field of view.
    const Vec3d c = bounds.getCenter();
    cam.center = c;
    cam.scale = 1.0;
    if (o.projection == Projection::perspective) {
        cam.perspective = true;
        double radius = 0.5 * bounds.extents().length();
        if (!(radius > 0)) radius = 1.0;
        const double half_v = 0.5 * o.field_of_view_degrees * kPi / 180.0;
        const double half_h = std::atan(std::tan(half_v) * samples_x / samples_y);
        cam.eye = c - cam.forward * (radius / std::sin(std::min(half_v, half_h)));
        cam.scale = (samples_y * 0.5) / std::tan(half_v);
    }

    // Then zoom and shift the image plane so the projected points' extent
    // is centered and touches the margin (both cameras map linearly in scale).
    double xmin = std::numeric_limits<double>::infinity(), xmax = -xmin, ymin = xmin, ymax = -xmin;
    auto visit = [&](const Vec3d& p) {
        double x, y, key;
        if (!cam.project(p, x, y, key)) return;
        xmin = std::min(xmin, x), xmax = std::max(xmax, x);
        ymin = std::min(ymin, y), ymax = std::max(ymax, y);
    };
    if (frame_mesh_points) {
        for (const Vec3d& p : mesh.points)
            if (finite(p)) visit(p);
    } else {
        for (int i = 0; i < 8; ++i)
            visit(Vec3d((i & 1) ? bounds.max()[0] : bounds.min()[0], (i & 2) ? bounds.max()[1] : bounds.min()[1],
                        (i & 4) ? bounds.max()[2] : bounds.min()[2]));
    }
    if (!(xmin <= xmax && ymin <= ymax)) return cam;
    const double dx = xmax - xmin, dy = ymax - ymin;
    double zoom = std::min(dx > 0 ? (samples_x - 2 * margin) / dx : std::numeric_limits<double>::infinity(),
                           dy > 0 ? (samples_y - 2 * margin) / dy : std::numeric_limits<double>::infinity());
    if (!std::isfinite(zoom) || !(zoom > 0)) zoom = 1.0;
    const double mid_x = 0.5 * (xmin + xmax) - cam.cx, mid_y = 0.5 * (ymin + ymax) - cam.cy;
    cam.scale *= zoom;
    cam.cx = samples_x * 0.5 - zoom * mid_x;
    cam.cy = samples_y * 0.5 - zoom * mid_y;
    return cam;
}

/// One of the render triangles: a mesh triangle or half of a quad.
struct RenderTriangle {
    unsigned v[3];
    std::size_t face;       // index into triangles then quads
    unsigned edge_mask;     // bit k: side v[k] -> v[k+1] is a polygon edge
};

class TriangleSource {
public:
    explicit TriangleSource(const Mesh& mesh) : mesh_(mesh) {}
    std::size_t size() const { return mesh_.triangles.size() + 2 * mesh_.quads.size(); }
    RenderTriangle operator()(std::size_t t) const {
        const std::size_t nt = mesh_.triangles.size();
        if (t < nt) {
            const auto& f = mesh_.triangles[t];
            return {{f[0], f[1], f[2]}, t, 7u};
        }
        const std::size_t q = (t - nt) / 2;
        const auto& f = mesh_.quads[q];
        if ((t - nt) % 2 == 0) return {{f[0], f[1], f[2]}, nt + q, 3u};  // sides 0-1, 1-2
        return {{f[0], f[2], f[3]}, nt + q, 6u};                            // sides 2-3, 3-0
    }
    /// Twice the vector area of a face (quads: cross of the diagonals).
    Vec3d face_area_vector2(std::size_t face) const {
        const auto& p = mesh_.points;
        const std::size_t nt = mesh_.triangles.size();
        if (face < nt) {
            const auto& f = mesh_.triangles[face];
            return (p[f[1]] - p[f[0]]).cross(p[f[2]] - p[f[0]]);
        }
        const auto& f = mesh_.quads[face - nt];
        return (p[f[2]] - p[f[0]]).cross(p[f[3]] - p[f[1]]);
    }

private:
    const Mesh& mesh_;
};

double distance_to_segment(double px, double py, double ax, double ay, double bx, double by) {
    const double dx = bx - ax, dy = by - ay;
    const double len2 = dx * dx + dy * dy;
    double t = len2 > 0 ? ((px - ax) * dx + (py - ay) * dy) / len2 : 0.0;
    t = std::min(1.0, std::max(0.0, t));
    const double ex = ax + t * dx - px, ey = ay + t * dy - py;
    return std::sqrt(ex * ex + ey * ey);
}

/// x^48 by squaring: the specular lobe, without pow() per sample.
double pow48(double x) {
    const double x2 = x * x, x4 = x2 * x2, x8 = x4 * x4, x16 = x8 * x8;
    return x16 * x16 * x16;
}

float srgb_encode(float linear) {
    const float c = std::min(1.0f, std::max(0.0f, linear));
    return c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1.0f / 2.4f) - 0.055f;
}

void draw_title(Image& image, const std::string& title, const Color& color) {
    if (title.empty()) return;
    // Text height about 2.8% of the image height, at least 10 pixels.
    const double text_px = std::max(10.0, 0.028 * image.height);
    const double scale = text_px / kFontCellHeight;  // output pixels per font pixel
    const double x0 = std::round(std::max(4.0, 0.6 * text_px));
    const double y0 = std::round(std::max(3.0, 0.4 * text_px));
    double pen = 0;  // font pixels
    constexpr int kSub = 4;  // sub-samples per output pixel axis
    for (char ch : title) {
        const int code = (static_cast<unsigned char>(ch) >= 32 && static_cast<unsigned char>(ch) < 127) ? ch : '?';
        const FontGlyph& g = kFontGlyphs[code - 32];
        const int px_begin = int(std::floor(x0 + pen * scale)), px_end = int(std::ceil(x0 + (pen + g.advance) * scale));
        const int py_begin = int(y0), py_end = int(std::ceil(y0 + kFontCellHeight * scale));
        for (int py = std::max(0, py_begin); py < std::min(image.height, py_end); ++py) {
            for (int px = std::max(0, px_begin); px < std::min(image.width, px_end); ++px) {
                int sum = 0;
                for (int sy = 0; sy < kSub; ++sy) {
                    const int fy = int(std::floor((py + (sy + 0.5) / kSub - y0) / scale));
                    if (fy < 0 || fy >= kFontCellHeight) continue;
                    for (int sx = 0; sx < kSub; ++sx) {
                        const int fx = int(std::floor((px + (sx + 0.5) / kSub - x0) / scale - pen));
                        if (fx < 0 || fx >= g.advance) continue;
                        const char h = g.coverage[fy * g.advance + fx];
                        sum += h <= '9' ? h - '0' : h - 'a' + 10;
                    }
                }
                const float c = float(sum) / float(15 * kSub * kSub) * color.a;
                if (c <= 0) continue;
                float* out = &image.rgba[4 * (std::size_t(py) * image.width + px)];
                out[0] = out[0] * (1 - c) + color.r * c;
                out[1] = out[1] * (1 - c) + color.g * c;
                out[2] = out[2] * (1 - c) + color.b * c;
                out[3] = out[3] * (1 - c) + c;
            }
        }
        pen += g.advance;
    }
}

// ---- file encoders ----

struct PngWriteState {
    std::vector<char>* out;
};

void png_write_to_vector(png_structp png, png_bytep data, png_size_t length) {
    auto* state = static_cast<PngWriteState*>(png_get_io_ptr(png));
    state->out->insert(state->out->end(), reinterpret_cast<char*>(data), reinterpret_cast<char*>(data) + length);
}

void png_flush_noop(png_structp) {}

/// Encodes 8-bit RGBA rows; returns false if libpng reported an error.
bool encode_png(const std::vector<unsigned char>& rgba8, int width, int height, std::vector<char>& out) {
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
    if (!png) return false;
    png_infop info = png_create_info_struct(png);
    if (!info) {
        png_destroy_write_struct(&png, nullptr);
        return false;
    }
    PngWriteState state{&out};
    std::vector<png_bytep> rows(static_cast<std::size_t>(height));
    for (int y = 0; y < height; ++y)
        rows[std::size_t(y)] = const_cast<png_bytep>(rgba8.data() + std::size_t(y) * std::size_t(width) * 4);
    if (setjmp(png_jmpbuf(png))) {
        png_destroy_write_struct(&png, &info);
        return false;
    }
    png_set_write_fn(png, &state, png_write_to_vector, png_flush_noop);
    png_set_IHDR(png, info, png_uint_32(width), png_uint_32(height), 8, PNG_COLOR_TYPE_RGB_ALPHA, PNG_INTERLACE_NONE,
                 PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_set_sRGB_gAMA_and_cHRM(png, info, PNG_sRGB_INTENT_PERCEPTUAL);
    png_set_rows(png, info, rows.data());
    png_write_png(png, info, PNG_TRANSFORM_IDENTITY, nullptr);
    png_destroy_write_struct(&png, &info);
    return true;
}

class MemoryOStream : public Imf::OStream {
public:
    MemoryOStream() : Imf::OStream("<memory>") {}
    void write(const char c[], int n) override {
        const std::size_t end = pos_ + std::size_t(n);
        if (end > data_.size()) data_.resize(end);
        std::memcpy(data_.data() + pos_, c, std::size_t(n));
        pos_ = end;
    }
    uint64_t tellp() override { return pos_; }
    void seekp(uint64_t pos) override { pos_ = std::size_t(pos); }
    const std::vector<char>& data() const { return data_; }

private:
    std::vector<char> data_;
    std::size_t pos_ = 0;
};

}  // namespace

void validate(const RenderOptions& o) {
    auto fail = [](const std::string& what) { throw option_error("RenderOptions::" + what); };
    if (o.width < 1 || o.width > 16384) fail("width = " + std::to_string(o.width) + " is outside [1, 16384]");
    if (o.height < 1 || o.height > 16384) fail("height = " + std::to_string(o.height) + " is outside [1, 16384]");
    if (!finite(o.up) || o.up.length() < 1e-12) fail("up must be a finite non-zero vector");
    if (!std::isfinite(o.azimuth_degrees)) fail("azimuth_degrees must be finite");
    if (!(o.elevation_degrees >= -90 && o.elevation_degrees <= 90))
        fail("elevation_degrees = " + std::to_string(o.elevation_degrees) + " is outside [-90, 90]");
    if (!(o.field_of_view_degrees > 0 && o.field_of_view_degrees < 170))
        fail("field_of_view_degrees = " + std::to_string(o.field_of_view_degrees) + " is outside (0, 170)");
    if (!(o.margin >= 0 && o.margin <= 0.45)) fail("margin = " + std::to_string(o.margin) + " is outside [0, 0.45]");
    if (!(o.edge_width_pixels >= 0 && o.edge_width_pixels <= 16))
        fail("edge_width_pixels = " + std::to_string(o.edge_width_pixels) + " is outside [0, 16]");
    if (o.supersampling < 1 || o.supersampling > 8)
        fail("supersampling = " + std::to_string(o.supersampling) + " is outside [1, 8]");
    if (!finite(o.edge_color) || !finite(o.front_color) || !finite(o.back_color) || !finite(o.background))
        fail("colors must be finite");
    if (!box_is_empty(o.frame_bounds) && !(finite(o.frame_bounds.min()) && finite(o.frame_bounds.max())))
        fail("frame_bounds must be finite (or empty to frame the mesh)");
}

Image render(const Mesh& mesh, const RenderOptions& o) {
    validate(o);
    const std::size_t nv = mesh.points.size();
    for (const auto& t : mesh.triangles)
        for (int k = 0; k < 3; ++k)
            if (t[k] >= nv) throw input_error("render: a triangle refers to vertex " + std::to_string(t[k]) +
                                              " but the mesh has " + std::to_string(nv) + " points");
    for (const auto& q : mesh.quads)
        for (int k = 0; k < 4; ++k)
            if (q[k] >= nv) throw input_error("render: a quad refers to vertex " + std::to_string(q[k]) +
                                              " but the mesh has " + std::to_string(nv) + " points");

    const int ss = o.supersampling;
    const int W = o.width, H = o.height;
    const int SW = W * ss, SH = H * ss;
    Image image;
    image.width = W;
    image.height = H;
    image.rgba.assign(std::size_t(W) * std::size_t(H) * 4, 0.0f);

    const bool frame_mesh_points = box_is_empty(o.frame_bounds);
    openvdb::BBoxd bounds = frame_mesh_points ? finite_bounds(mesh) : o.frame_bounds;
    const bool have_geometry = !box_is_empty(bounds);
    if (!have_geometry) bounds = openvdb::BBoxd(Vec3d(-1.0), Vec3d(1.0));
    const Camera cam = make_camera(o, mesh, bounds, frame_mesh_points && have_geometry, SW, SH);

    // 1. Projection.
    std::vector<double> sx(nv), sy(nv), key(nv);
    std::vector<char> visible(nv, 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 8192), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i)
            visible[i] = finite(mesh.points[i]) && cam.project(mesh.points[i], sx[i], sy[i], key[i]);
    });

    // Area-weighted vertex normals, summed serially (thread-count independent).
    const TriangleSource tris(mesh);
    std::vector<Vec3d> vertex_normal;
    if (o.shading == Shading::smooth) {
        vertex_normal.assign(nv, Vec3d(0.0));
        const std::size_t nf = mesh.face_count();
        for (std::size_t f = 0; f < nf; ++f) {
            const Vec3d a = tris.face_area_vector2(f);
            if (!finite(a)) continue;
            if (f < mesh.triangles.size()) {
                for (int k = 0; k < 3; ++k) vertex_normal[mesh.triangles[f][k]] += a;
            } else {
                for (int k = 0; k < 4; ++k) vertex_normal[mesh.quads[f - mesh.triangles.size()][k]] += a;
            }
        }
    }

    // 2. Binning into bands of output rows.
    const int band_count = (H + kBandRows - 1) / kBandRows;
    const double band_samples = double(kBandRows) * ss;
    const std::size_t nt = have_geometry ? tris.size() : 0;
    std::vector<std::uint32_t> band_begin(std::size_t(band_count) + 1, 0);
    auto band_range = [&](std::size_t t, int& b0, int& b1) {
        const RenderTriangle rt = tris(t);
        const unsigned a = rt.v[0], b = rt.v[1], c = rt.v[2];
        if (!visible[a] || !visible[b] || !visible[c]) return false;
        const double ymin = std::min({sy[a], sy[b], sy[c]}), ymax = std::max({sy[a], sy[b], sy[c]});
        const double xmin = std::min({sx[a], sx[b], sx[c]}), xmax = std::max({sx[a], sx[b], sx[c]});
        if (ymax < 0 || ymin > SH || xmax < 0 || xmin > SW) return false;
        b0 = std::max(0, int(std::floor(ymin / band_samples)));
        b1 = std::min(band_count - 1, int(std::floor(ymax / band_samples)));
        return b0 <= b1;
    };
    if (nt > std::numeric_limits<std::uint32_t>::max() - 1)
        throw input_error("render: more than 4 billion triangles are not supported");
    for (std::size_t t = 0; t < nt; ++t) {
        int b0, b1;
        if (band_range(t, b0, b1))
            for (int b = b0; b <= b1; ++b) ++band_begin[std::size_t(b) + 1];
    }
    for (int b = 0; b < band_count; ++b) band_begin[std::size_t(b) + 1] += band_begin[std::size_t(b)];
    std::vector<std::uint32_t> band_triangles(band_begin.back());
    {
        std::vector<std::uint32_t> fill(band_begin.begin(), band_begin.end() - 1);
        for (std::size_t t = 0; t < nt; ++t) {
            int b0, b1;
            if (band_range(t, b0, b1))
                for (int b = b0; b <= b1; ++b) band_triangles[fill[std::size_t(b)]++] = std::uint32_t(t);
        }
    }

    // Lights in camera space: a key from the upper left, a weak fill from the right.
    const Vec3d view = -cam.forward;
    const Vec3d key_light = (-0.45 * cam.right + 0.6 * cam.up + 0.66 * view).unitSafe();
    const Vec3d fill_light = (0.7 * cam.right - 0.2 * cam.up + 0.68 * view).unitSafe();
    const Vec3d half_vector = (key_light + view).unitSafe();
    const double half_line = 0.5 * o.edge_width_pixels;
    const float inv_samples = 1.0f / float(ss * ss);

    // 3. Per band: z-buffer, shade, resolve.
    struct BandBuffers {
        std::vector<float> depth;
        std::vector<std::uint32_t> id;
    };
    tbb::enumerable_thread_specific<BandBuffers> buffers;  // reused: fresh pages cost more than the raster
    tbb::parallel_for(tbb::blocked_range<int>(0, band_count, 1), [&](const tbb::blocked_range<int>& range) {
        std::vector<float>& depth = buffers.local().depth;
        std::vector<std::uint32_t>& id = buffers.local().id;
        for (int band = range.begin(); band != range.end(); ++band) {
            const int row0 = band * kBandRows, rows = std::min(kBandRows, H - row0);
            const int srow0 = row0 * ss, srows = rows * ss;
            depth.assign(std::size_t(srows) * SW, std::numeric_limits<float>::infinity());
            id.assign(std::size_t(srows) * SW, kNoTriangle);

            for (std::uint32_t k = band_begin[std::size_t(band)]; k < band_begin[std::size_t(band) + 1]; ++k) {
                const std::uint32_t t = band_triangles[k];
                const RenderTriangle rt = tris(t);
                const double x0 = sx[rt.v[0]], y0 = sy[rt.v[0]], x1 = sx[rt.v[1]], y1 = sy[rt.v[1]];
                const double x2 = sx[rt.v[2]], y2 = sy[rt.v[2]];
                const double area2 = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0);
                if (!(area2 != 0.0) || !std::isfinite(area2)) continue;
                const double sign = area2 > 0 ? 1.0 : -1.0, inv_area = 1.0 / area2;
                const int xa = std::max(0, int(std::ceil(std::min({x0, x1, x2}) - 0.5)));
                const int xb = std::min(SW - 1, int(std::floor(std::max({x0, x1, x2}) - 0.5)));
                const int ya = std::max(srow0, int(std::ceil(std::min({y0, y1, y2}) - 0.5)));
                const int yb = std::min(srow0 + srows - 1, int(std::floor(std::max({y0, y1, y2}) - 0.5)));
                const double k0 = key[rt.v[0]], k1 = key[rt.v[1]], k2 = key[rt.v[2]];
                for (int y = ya; y <= yb; ++y) {
                    const double py = y + 0.5;
                    for (int x = xa; x <= xb; ++x) {
                        const double px = x + 0.5;
                        const double w0 = (x2 - x1) * (py - y1) - (y2 - y1) * (px - x1);
                        const double w1 = (x0 - x2) * (py - y2) - (y0 - y2) * (px - x2);
                        const double w2 = (x1 - x0) * (py - y0) - (y1 - y0) * (px - x0);
                        if (w0 * sign < 0 || w1 * sign < 0 || w2 * sign < 0) continue;
                        const float z = float((w0 * k0 + w1 * k1 + w2 * k2) * inv_area);
                        const std::size_t s = std::size_t(y - srow0) * SW + std::size_t(x);
                        if (z < depth[s] || (z == depth[s] && t < id[s])) {
                            depth[s] = z;
                            id[s] = t;
                        }
                    }
                }
            }

            for (int r = 0; r < rows; ++r) {
                for (int c = 0; c < W; ++c) {
                    float acc[4] = {0, 0, 0, 0};
                    for (int sy_ = 0; sy_ < ss; ++sy_) {
                        for (int sx_ = 0; sx_ < ss; ++sx_) {
                            const int X = c * ss + sx_, Y = (row0 + r) * ss + sy_;
                            const std::uint32_t t = id[std::size_t(Y - srow0) * SW + std::size_t(X)];
                            if (t == kNoTriangle) continue;
                            const RenderTriangle rt = tris(t);
                            const double px = X + 0.5, py = Y + 0.5;
                            const double x0 = sx[rt.v[0]], y0 = sy[rt.v[0]], x1 = sx[rt.v[1]], y1 = sy[rt.v[1]];
                            const double x2 = sx[rt.v[2]], y2 = sy[rt.v[2]];
                            const double area2 = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0);
                            double b[3] = {((x2 - x1) * (py - y1) - (y2 - y1) * (px - x1)) / area2,
                                           ((x0 - x2) * (py - y2) - (y0 - y2) * (px - x2)) / area2,
                                           ((x1 - x0) * (py - y0) - (y1 - y0) * (px - x0)) / area2};
                            if (cam.perspective) {  // perspective-correct weights: b_i / z_i
                                double sum = 0;
                                for (int k = 0; k < 3; ++k) sum += (b[k] *= -key[rt.v[k]]);
                                if (sum != 0)
                                    for (double& bk : b) bk /= sum;
                            }
                            const Vec3d& p0 = mesh.points[rt.v[0]];
                            const Vec3d face_normal = tris.face_area_vector2(rt.face);
                            const bool front = face_normal.dot(cam.to_viewer(p0)) >= 0;
                            Vec3d n = face_normal;
                            if (o.shading == Shading::smooth) {
                                const Vec3d s = b[0] * vertex_normal[rt.v[0]] + b[1] * vertex_normal[rt.v[1]] +
                                                b[2] * vertex_normal[rt.v[2]];
                                if (s.lengthSqr() > 0 && finite(s)) n = s;
                            }
                            n = n.unitSafe();
                            if (!front) n = -n;
                            const Color& albedo = front ? o.front_color : o.back_color;
                            const double diffuse = std::max(0.0, n.dot(key_light));
                            const double fill = std::max(0.0, n.dot(fill_light));
                            const double spec = diffuse > 0 ? 0.16 * pow48(std::max(0.0, n.dot(half_vector))) : 0.0;
                            const double light = 0.14 + 0.7 * diffuse + 0.18 * fill;
                            double rgb[3] = {albedo.r * light + spec, albedo.g * light + spec, albedo.b * light + spec};
                            if (half_line > 0 && rt.edge_mask) {
                                double d = std::numeric_limits<double>::infinity();
                                const double xs[3] = {x0, x1, x2}, ys[3] = {y0, y1, y2};
                                for (int k = 0; k < 3; ++k)
                                    if (rt.edge_mask & (1u << k))
                                        d = std::min(d, distance_to_segment(px, py, xs[k], ys[k], xs[(k + 1) % 3],
                                                                            ys[(k + 1) % 3]));
                                d /= ss;  // output pixels
                                // Fade lines on faces under ~8 px across so dense meshes read.
                                double face_px = std::sqrt(std::abs(area2) * (rt.edge_mask == 7u ? 0.5 : 1.0)) / ss;
                                const double fade = std::min(1.0, std::max(0.0, (face_px - 2.0) / 6.0));
                                const double cover = std::min(1.0, std::max(0.0, (half_line - d) * ss + 0.5));
                                const double a = o.edge_color.a * cover * fade;
                                rgb[0] += (o.edge_color.r - rgb[0]) * a;
                                rgb[1] += (o.edge_color.g - rgb[1]) * a;
                                rgb[2] += (o.edge_color.b - rgb[2]) * a;
                            }
                            acc[0] += float(rgb[0]);
                            acc[1] += float(rgb[1]);
                            acc[2] += float(rgb[2]);
                            acc[3] += 1.0f;
                        }
                    }
                    float* out = &image.rgba[4 * (std::size_t(row0 + r) * W + std::size_t(c))];
                    const float a = acc[3] * inv_samples;
                    const float bg_a = o.background.a * (1.0f - a);
                    out[0] = acc[0] * inv_samples + o.background.r * bg_a;
                    out[1] = acc[1] * inv_samples + o.background.g * bg_a;
                    out[2] = acc[2] * inv_samples + o.background.b * bg_a;
                    out[3] = a + bg_a;
                }
            }
        }
    });

    Color text = o.edge_color;
    text.a = 1.0f;
    draw_title(image, o.title, text);
    return image;
}

void write_image(const Image& image, const std::string& path) {
    const std::size_t dot = path.find_last_of('.');
    const std::size_t slash = path.find_last_of('/');
    const std::string ext =
        (dot == std::string::npos || (slash != std::string::npos && dot < slash)) ? "" : lowercase(path.substr(dot));
    if (ext != ".png" && ext != ".exr")
        throw option_error("cannot tell the image format of '" + path + "' from its extension; use .png or .exr");
    if (image.width < 1 || image.height < 1 ||
        image.rgba.size() != std::size_t(image.width) * std::size_t(image.height) * 4)
        throw option_error("cannot write '" + path + "': the image is empty or its pixel array has the wrong size");

    std::vector<char> bytes;
    if (ext == ".png") {
        std::vector<unsigned char> rgba8(image.rgba.size());
        for (std::size_t i = 0; i < image.rgba.size(); i += 4) {
            const float a = std::min(1.0f, std::max(0.0f, image.rgba[i + 3]));
            for (int k = 0; k < 3; ++k) {
                const float straight = a > 0 ? image.rgba[i + std::size_t(k)] / a : 0.0f;
                rgba8[i + std::size_t(k)] = static_cast<unsigned char>(std::lround(srgb_encode(straight) * 255.0f));
            }
            rgba8[i + 3] = static_cast<unsigned char>(std::lround(a * 255.0f));
        }
        if (!encode_png(rgba8, image.width, image.height, bytes))
            throw io_error("cannot write '" + path + "': PNG encoding failed (out of memory?)");
    } else {
        try {
            Imf::Header header(image.width, image.height);
            header.compression() = Imf::ZIP_COMPRESSION;
            const char* names[4] = {"R", "G", "B", "A"};
            Imf::FrameBuffer frame;
            for (int k = 0; k < 4; ++k) {
                header.channels().insert(names[k], Imf::Channel(Imf::FLOAT));
                frame.insert(names[k], Imf::Slice(Imf::FLOAT, (char*)(image.rgba.data() + k), sizeof(float) * 4,
                                                  sizeof(float) * 4 * std::size_t(image.width)));
            }
            MemoryOStream stream;
            {
                Imf::OutputFile file(stream, header, 0);
                file.setFrameBuffer(frame);
                file.writePixels(image.height);
            }
            bytes = stream.data();
        } catch (const std::exception& e) {
            throw io_error("cannot write '" + path + "': OpenEXR: " + e.what());
        }
    }
    detail::AtomicFileWriter out(path);
    out.append(bytes.data(), bytes.size());
    out.commit();
}

}  // namespace pqdc
