// The camera: orientation from azimuth, elevation and up, then a zoom and
// shift that fit the framed points to the image.
#include "render/render_internal.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace pqdc::render_detail {

openvdb::BBoxd finite_bounds(const Mesh& mesh) {
    openvdb::BBoxd box(Vec3d(std::numeric_limits<double>::max()), Vec3d(-std::numeric_limits<double>::max()));
    for (const Vec3d& p : mesh.points)
        if (finite(p)) box.expand(p);
    return box;
}

bool box_is_empty(const openvdb::BBoxd& b) {
    return !(b.min()[0] <= b.max()[0] && b.min()[1] <= b.max()[1] && b.min()[2] <= b.max()[2]);
}

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

}  // namespace pqdc::render_detail
