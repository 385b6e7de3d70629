// The renderer's shared pieces (src/render/): the camera, the render
// triangles, and the title. render.cpp is the driver.
#pragma once

#include "pqdc/render.hpp"

#include <cmath>
#include <cstddef>
#include <string>

namespace pqdc::render_detail {

using Vec3d = openvdb::Vec3d;

constexpr double kPi = 3.14159265358979323846;

inline bool finite(const Vec3d& v) { return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]); }

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

/// The bounding box of the mesh's finite points (empty when there are none).
openvdb::BBoxd finite_bounds(const Mesh& mesh);
bool box_is_empty(const openvdb::BBoxd& b);

/// Places the camera so the framed points fill the image up to the margin:
/// every point of `frame_bounds` when set (a camera that stays put across
/// meshes), else every finite mesh point (a tight fit).
Camera make_camera(const RenderOptions& o, const Mesh& mesh, const openvdb::BBoxd& bounds, bool frame_mesh_points,
                   int samples_x, int samples_y);

/// One of the render triangles: a mesh triangle or half of a quad.
struct RenderTriangle {
    unsigned v[3];
    std::size_t face;       // index into triangles then quads
    unsigned edge_mask;     // bit k: side v[k] -> v[k+1] is a polygon edge
};

/// Mesh triangles, then each quad as 0-1-2 and 0-2-3.
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

/// The caption in the top-left corner, blended over the image.
void draw_title(Image& image, const std::string& title, const Color& color);

}  // namespace pqdc::render_detail
