// A small deterministic software rasterizer for looking at meshes: figures,
// regression images, quick checks without a GUI. Its own library, built when
// libpng and OpenEXR are there: find_package(pqdc COMPONENTS render), then
// link pqdc::render.
//
//   pqdc::RenderOptions options;
//   options.azimuth_degrees = 40;
//   pqdc::Image image = pqdc::render(mesh, options);
//   pqdc::write_image(image, "mesh.png");
//
// Every output pixel averages supersampling^2 samples; each sample keeps the
// nearest face (ties broken by face index), so the image is the same bytes for
// any thread count. Faces are two-sided: back faces (seen from behind, i.e.
// wound clockwise on screen) get back_color, which makes flipped or open
// regions obvious.
#pragma once

#include "pqdc/mesh.hpp"

#include <openvdb/Types.h>
#include <openvdb/math/BBox.h>

#include <string>
#include <vector>

namespace pqdc {

/// Linear-light RGB plus alpha (coverage), each in [0, 1].
struct Color {
    float r = 0, g = 0, b = 0, a = 1;
};

enum class Projection {
    orthographic,  ///< parallel rays; sizes comparable across the image
    perspective,   ///< pinhole camera with vertical field_of_view_degrees
};

enum class Shading {
    flat,    ///< one normal per face (a quad uses its vector area): shows the faces
    smooth,  ///< area-weighted vertex normals interpolated across faces
};

struct RenderOptions {
    int width = 1024;   ///< output pixels, [1, 16384]
    int height = 1024;  ///< output pixels, [1, 16384]
    /// World "up" axis, any non-zero vector. Default +Y.
    openvdb::Vec3d up{0.0, 1.0, 0.0};
    /// Camera direction around `up`, degrees: 0 looks from the +Z side
    /// (for up = +Y; from +X when up is parallel to Z), increasing towards
    /// the side of up x that axis (+X for +Y up). Any value.
    double azimuth_degrees = 30.0;
    /// Camera height above the horizontal plane, degrees, [-90, 90].
    double elevation_degrees = 25.0;
    Projection projection = Projection::orthographic;
    /// Vertical opening angle of the perspective camera, degrees, (0, 170).
    double field_of_view_degrees = 30.0;
    /// The world box the camera frames. Empty (the default) frames the mesh's
    /// finite points; set it to keep the camera fixed across several meshes
    /// (e.g. the panels of one figure). Finite, and not a single point.
    openvdb::BBoxd frame_bounds = openvdb::BBoxd(openvdb::Vec3d(1.0), openvdb::Vec3d(-1.0));
    /// Fraction of the smaller image side left free around the framed box, [0, 0.45].
    double margin = 0.04;
    Shading shading = Shading::flat;
    /// Width of the lines drawn along polygon edges (not along the diagonal
    /// that splits a quad), output pixels, [0, 16]; 0 = no lines. Lines fade
    /// out on faces smaller than about 8 pixels so dense meshes still read.
    double edge_width_pixels = 1.0;
    Color edge_color{0.02f, 0.02f, 0.025f, 0.85f};  ///< a = line opacity
    Color front_color{0.62f, 0.66f, 0.72f, 1.0f};  ///< surface albedo seen from outside
    Color back_color{0.80f, 0.35f, 0.28f, 1.0f};   ///< albedo of back faces
    /// Behind the mesh. Alpha 0 gives a transparent background.
    Color background{1.0f, 1.0f, 1.0f, 1.0f};
    /// Samples per pixel along each axis (n x n per pixel), [1, 8].
    int supersampling = 3;
    /// Optional caption drawn in the top-left corner (printable ASCII; other
    /// characters show as '?').
    std::string title;
};

/// Throws option_error naming the field when an option is out of range.
void validate(const RenderOptions& options);

/// An image in linear light with premultiplied alpha, rows top to bottom.
struct Image {
    int width = 0;
    int height = 0;
    std::vector<float> rgba;  ///< 4 * width * height floats
};

/// Renders the mesh. Faces touching a non-finite point, or (perspective)
/// reaching behind the camera, are skipped. An empty mesh gives the
/// background. Throws option_error for invalid options, input_error for face
/// indices out of range.
Image render(const Mesh& mesh, const RenderOptions& options);

/// Writes .png (8-bit sRGB RGBA) or .exr (32-bit float linear RGBA,
/// premultiplied, ZIP) chosen by extension (case-insensitive), atomically.
/// Throws option_error for another extension, io_error on failure.
void write_image(const Image& image, const std::string& path);

}  // namespace pqdc
