// Software rasterizer, the driver. Three passes:
//   1. project every vertex to sample space (parallel, per vertex);
//   2. bin render triangles (mesh triangles, quads as 0-1-2 / 0-2-3) into
//      horizontal bands of output rows, in triangle order (serial);
//   3. per band (parallel): z-buffer the band's samples keeping the nearest
//      triangle, ties to the lower index, then shade every sample from its
//      triangle id and average the samples of each pixel.
// Every value written depends only on the band's inputs, never on which
// thread ran it or in which order, so the bytes are thread-count independent.
// The camera is in camera.cpp, the caption in title.cpp, the file encoders in
// image_file.cpp.
#include "pqdc/render.hpp"

#include "pqdc/exceptions.hpp"

#include "render/render_internal.hpp"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

namespace pqdc {
namespace {

using namespace render_detail;
using render_detail::finite;  // beside the Color overload below

constexpr std::uint32_t kNoTriangle = std::numeric_limits<std::uint32_t>::max();
constexpr int kBandRows = 8;  // output rows per parallel task

bool finite(const Color& c) {
    return std::isfinite(c.r) && std::isfinite(c.g) && std::isfinite(c.b) && std::isfinite(c.a);
}

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

/// Throws input_error for a face that names a vertex the mesh does not have.
void check_indices(const Mesh& mesh) {
    const std::size_t nv = mesh.points.size();
    for (const auto& t : mesh.triangles)
        for (int k = 0; k < 3; ++k)
            if (t[k] >= nv) throw input_error("render: a triangle refers to vertex " + std::to_string(t[k]) +
                                              " but the mesh has " + std::to_string(nv) + " points");
    for (const auto& q : mesh.quads)
        for (int k = 0; k < 4; ++k)
            if (q[k] >= nv) throw input_error("render: a quad refers to vertex " + std::to_string(q[k]) +
                                              " but the mesh has " + std::to_string(nv) + " points");
}

/// Pass 1: every vertex in sample space, with its depth key.
struct Projected {
    std::vector<double> x, y, key;
    std::vector<char> visible;
};

Projected project_vertices(const Mesh& mesh, const Camera& cam) {
    const std::size_t nv = mesh.points.size();
    Projected p;
    p.x.resize(nv);
    p.y.resize(nv);
    p.key.resize(nv);
    p.visible.assign(nv, 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 8192), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i)
            p.visible[i] = finite(mesh.points[i]) && cam.project(mesh.points[i], p.x[i], p.y[i], p.key[i]);
    });
    return p;
}

/// Area-weighted vertex normals, summed serially (thread-count independent).
std::vector<Vec3d> vertex_normals(const Mesh& mesh, const TriangleSource& tris) {
    std::vector<Vec3d> vertex_normal(mesh.points.size(), Vec3d(0.0));
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
    return vertex_normal;
}

/// Sizes of the image in output pixels and in samples.
struct Raster {
    int ss, W, H, SW, SH;
    int band_count() const { return (H + kBandRows - 1) / kBandRows; }
};

/// Pass 2: the render triangles of each band of kBandRows output rows, in
/// triangle order (band b's are triangles[begin[b], begin[b + 1])).
struct Bands {
    std::vector<std::uint32_t> begin, triangles;
};

Bands bin_triangles(const TriangleSource& tris, std::size_t nt, const Projected& p, const Raster& r) {
    const int band_count = r.band_count();
    const double band_samples = double(kBandRows) * r.ss;
    Bands bands;
    bands.begin.assign(std::size_t(band_count) + 1, 0);
    auto band_range = [&](std::size_t t, int& b0, int& b1) {
        const RenderTriangle rt = tris(t);
        const unsigned a = rt.v[0], b = rt.v[1], c = rt.v[2];
        if (!p.visible[a] || !p.visible[b] || !p.visible[c]) return false;
        const double ymin = std::min({p.y[a], p.y[b], p.y[c]}), ymax = std::max({p.y[a], p.y[b], p.y[c]});
        const double xmin = std::min({p.x[a], p.x[b], p.x[c]}), xmax = std::max({p.x[a], p.x[b], p.x[c]});
        if (ymax < 0 || ymin > r.SH || xmax < 0 || xmin > r.SW) return false;
        b0 = std::max(0, int(std::floor(ymin / band_samples)));
        b1 = std::min(band_count - 1, int(std::floor(ymax / band_samples)));
        return b0 <= b1;
    };
    if (nt > std::numeric_limits<std::uint32_t>::max() - 1)
        throw input_error("render: more than 4 billion triangles are not supported");
    for (std::size_t t = 0; t < nt; ++t) {
        int b0, b1;
        if (band_range(t, b0, b1))
            for (int b = b0; b <= b1; ++b) ++bands.begin[std::size_t(b) + 1];
    }
    for (int b = 0; b < band_count; ++b) bands.begin[std::size_t(b) + 1] += bands.begin[std::size_t(b)];
    bands.triangles.resize(bands.begin.back());
    std::vector<std::uint32_t> fill(bands.begin.begin(), bands.begin.end() - 1);
    for (std::size_t t = 0; t < nt; ++t) {
        int b0, b1;
        if (band_range(t, b0, b1))
            for (int b = b0; b <= b1; ++b) bands.triangles[fill[std::size_t(b)]++] = std::uint32_t(t);
    }
    return bands;
}

/// Pass 3a: the nearest triangle of every sample of one band (rows
/// [srow0, srow0 + srows) of samples), ties to the lower index.
void depth_pass(const Bands& bands, int band, const TriangleSource& tris, const Projected& p, const Raster& r,
                int srow0, int srows, std::vector<float>& depth, std::vector<std::uint32_t>& id) {
    const int SW = r.SW;
    depth.assign(std::size_t(srows) * SW, std::numeric_limits<float>::infinity());
    id.assign(std::size_t(srows) * SW, kNoTriangle);
    for (std::uint32_t k = bands.begin[std::size_t(band)]; k < bands.begin[std::size_t(band) + 1]; ++k) {
        const std::uint32_t t = bands.triangles[k];
        const RenderTriangle rt = tris(t);
        const double x0 = p.x[rt.v[0]], y0 = p.y[rt.v[0]], x1 = p.x[rt.v[1]], y1 = p.y[rt.v[1]];
        const double x2 = p.x[rt.v[2]], y2 = p.y[rt.v[2]];
        const double area2 = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0);
        if (!(area2 != 0.0) || !std::isfinite(area2)) continue;
        const double sign = area2 > 0 ? 1.0 : -1.0, inv_area = 1.0 / area2;
        const int xa = std::max(0, int(std::ceil(std::min({x0, x1, x2}) - 0.5)));
        const int xb = std::min(SW - 1, int(std::floor(std::max({x0, x1, x2}) - 0.5)));
        const int ya = std::max(srow0, int(std::ceil(std::min({y0, y1, y2}) - 0.5)));
        const int yb = std::min(srow0 + srows - 1, int(std::floor(std::max({y0, y1, y2}) - 0.5)));
        const double k0 = p.key[rt.v[0]], k1 = p.key[rt.v[1]], k2 = p.key[rt.v[2]];
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
}

/// Pass 3b: the colour of one sample. Lights in camera space: a key from the
/// upper left, a weak fill from the right.
class Shader {
public:
    Shader(const Mesh& mesh, const TriangleSource& tris, const Projected& p, const Camera& cam,
           const RenderOptions& o, const std::vector<Vec3d>& vertex_normal)
        : mesh_(mesh), tris_(tris), p_(p), cam_(cam), o_(o), vertex_normal_(vertex_normal) {
        const Vec3d view = -cam.forward;
        key_light_ = (-0.45 * cam.right + 0.6 * cam.up + 0.66 * view).unitSafe();
        fill_light_ = (0.7 * cam.right - 0.2 * cam.up + 0.68 * view).unitSafe();
        half_vector_ = (key_light_ + view).unitSafe();
        half_line_ = 0.5 * o.edge_width_pixels;
    }

    /// Linear RGB of the sample at (X, Y), covered by render triangle t.
    void shade(std::uint32_t t, int X, int Y, int ss, double rgb[3]) const {
        const RenderTriangle rt = tris_(t);
        const double px = X + 0.5, py = Y + 0.5;
        const double x0 = p_.x[rt.v[0]], y0 = p_.y[rt.v[0]], x1 = p_.x[rt.v[1]], y1 = p_.y[rt.v[1]];
        const double x2 = p_.x[rt.v[2]], y2 = p_.y[rt.v[2]];
        const double area2 = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0);
        double b[3] = {((x2 - x1) * (py - y1) - (y2 - y1) * (px - x1)) / area2,
                       ((x0 - x2) * (py - y2) - (y0 - y2) * (px - x2)) / area2,
                       ((x1 - x0) * (py - y0) - (y1 - y0) * (px - x0)) / area2};
        if (cam_.perspective) {  // perspective-correct weights: b_i / z_i
            double sum = 0;
            for (int k = 0; k < 3; ++k) sum += (b[k] *= -p_.key[rt.v[k]]);
            if (sum != 0)
                for (double& bk : b) bk /= sum;
        }
        const Vec3d& p0 = mesh_.points[rt.v[0]];
        const Vec3d face_normal = tris_.face_area_vector2(rt.face);
        const bool front = face_normal.dot(cam_.to_viewer(p0)) >= 0;
        Vec3d n = face_normal;
        if (o_.shading == Shading::smooth) {
            const Vec3d s = b[0] * vertex_normal_[rt.v[0]] + b[1] * vertex_normal_[rt.v[1]] +
                            b[2] * vertex_normal_[rt.v[2]];
            if (s.lengthSqr() > 0 && finite(s)) n = s;
        }
        n = n.unitSafe();
        if (!front) n = -n;
        const Color& albedo = front ? o_.front_color : o_.back_color;
        const double diffuse = std::max(0.0, n.dot(key_light_));
        const double fill = std::max(0.0, n.dot(fill_light_));
        const double spec = diffuse > 0 ? 0.16 * pow48(std::max(0.0, n.dot(half_vector_))) : 0.0;
        const double light = 0.14 + 0.7 * diffuse + 0.18 * fill;
        rgb[0] = albedo.r * light + spec;
        rgb[1] = albedo.g * light + spec;
        rgb[2] = albedo.b * light + spec;
        if (half_line_ > 0 && rt.edge_mask) {
            double d = std::numeric_limits<double>::infinity();
            const double xs[3] = {x0, x1, x2}, ys[3] = {y0, y1, y2};
            for (int k = 0; k < 3; ++k)
                if (rt.edge_mask & (1u << k))
                    d = std::min(d, distance_to_segment(px, py, xs[k], ys[k], xs[(k + 1) % 3], ys[(k + 1) % 3]));
            d /= ss;  // output pixels
            // Fade lines on faces under ~8 px across so dense meshes read.
            double face_px = std::sqrt(std::abs(area2) * (rt.edge_mask == 7u ? 0.5 : 1.0)) / ss;
            const double fade = std::min(1.0, std::max(0.0, (face_px - 2.0) / 6.0));
            const double cover = std::min(1.0, std::max(0.0, (half_line_ - d) * ss + 0.5));
            const double a = o_.edge_color.a * cover * fade;
            rgb[0] += (o_.edge_color.r - rgb[0]) * a;
            rgb[1] += (o_.edge_color.g - rgb[1]) * a;
            rgb[2] += (o_.edge_color.b - rgb[2]) * a;
        }
    }

private:
    const Mesh& mesh_;
    const TriangleSource& tris_;
    const Projected& p_;
    const Camera& cam_;
    const RenderOptions& o_;
    const std::vector<Vec3d>& vertex_normal_;
    Vec3d key_light_, fill_light_, half_vector_;
    double half_line_ = 0;
};

/// Pass 3c: each pixel of the band's `rows` output rows from `row0` on, the
/// mean of its samples over the background.
void resolve_band(const Shader& shader, const std::vector<std::uint32_t>& id, const Raster& r, int row0, int rows,
                  const Color& background, Image& image) {
    const int ss = r.ss, srow0 = row0 * ss;
    const float inv_samples = 1.0f / float(ss * ss);
    for (int row = 0; row < rows; ++row) {
        for (int c = 0; c < r.W; ++c) {
            float acc[4] = {0, 0, 0, 0};
            for (int sy = 0; sy < ss; ++sy) {
                for (int sx = 0; sx < ss; ++sx) {
                    const int X = c * ss + sx, Y = (row0 + row) * ss + sy;
                    const std::uint32_t t = id[std::size_t(Y - srow0) * r.SW + std::size_t(X)];
                    if (t == kNoTriangle) continue;
                    double rgb[3];
                    shader.shade(t, X, Y, ss, rgb);
                    acc[0] += float(rgb[0]);
                    acc[1] += float(rgb[1]);
                    acc[2] += float(rgb[2]);
                    acc[3] += 1.0f;
                }
            }
            float* out = &image.rgba[4 * (std::size_t(row0 + row) * r.W + std::size_t(c))];
            const float a = acc[3] * inv_samples;
            const float bg_a = background.a * (1.0f - a);
            out[0] = acc[0] * inv_samples + background.r * bg_a;
            out[1] = acc[1] * inv_samples + background.g * bg_a;
            out[2] = acc[2] * inv_samples + background.b * bg_a;
            out[3] = a + bg_a;
        }
    }
}

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
    // A point has no size to fit into the image: the mesh came out blank.
    if (!box_is_empty(o.frame_bounds) && o.frame_bounds.extents() == Vec3d(0.0))
        fail("frame_bounds is a single point; give a box with a positive extent along at least one axis (or "
             "leave it empty to frame the mesh)");
}

Image render(const Mesh& mesh, const RenderOptions& o) {
    validate(o);
    check_indices(mesh);
    const Raster r{o.supersampling, o.width, o.height, o.width * o.supersampling, o.height * o.supersampling};
    Image image;
    image.width = r.W;
    image.height = r.H;
    image.rgba.assign(std::size_t(r.W) * std::size_t(r.H) * 4, 0.0f);

    const bool frame_mesh_points = box_is_empty(o.frame_bounds);
    openvdb::BBoxd bounds = frame_mesh_points ? finite_bounds(mesh) : o.frame_bounds;
    const bool have_geometry = !box_is_empty(bounds);
    if (!have_geometry) bounds = openvdb::BBoxd(Vec3d(-1.0), Vec3d(1.0));
    const Camera cam = make_camera(o, mesh, bounds, frame_mesh_points && have_geometry, r.SW, r.SH);

    const Projected projected = project_vertices(mesh, cam);
    const TriangleSource tris(mesh);
    const std::vector<Vec3d> vertex_normal =
        o.shading == Shading::smooth ? vertex_normals(mesh, tris) : std::vector<Vec3d>();
    const Bands bands = bin_triangles(tris, have_geometry ? tris.size() : 0, projected, r);
    const Shader shader(mesh, tris, projected, cam, o, vertex_normal);

    struct BandBuffers {
        std::vector<float> depth;
        std::vector<std::uint32_t> id;
    };
    tbb::enumerable_thread_specific<BandBuffers> buffers;  // reused: fresh pages cost more than the raster
    tbb::parallel_for(tbb::blocked_range<int>(0, r.band_count(), 1), [&](const tbb::blocked_range<int>& range) {
        BandBuffers& local = buffers.local();
        for (int band = range.begin(); band != range.end(); ++band) {
            const int row0 = band * kBandRows, rows = std::min(kBandRows, r.H - row0);
            depth_pass(bands, band, tris, projected, r, row0 * r.ss, rows * r.ss, local.depth, local.id);
            resolve_band(shader, local.id, r, row0, rows, o.background, image);
        }
    });

    Color text = o.edge_color;
    text.a = 1.0f;
    draw_title(image, o.title, text);
    return image;
}

}  // namespace pqdc
