#include <pqdc/extract.hpp>
#include <pqdc/render.hpp>

#include <openvdb/tools/LevelSetSphere.h>

#include <cstdio>

int main() {
    openvdb::initialize();
    const auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(5.0f, openvdb::Vec3f(0.0f), 0.5f);
    const pqdc::Mesh mesh = pqdc::extract(*grid, pqdc::ExtractOptions{});
    const pqdc::Image image = pqdc::render(mesh, pqdc::RenderOptions{});
    std::printf("render consumer: %d x %d image\n", image.width, image.height);
    return image.width > 0 && image.rgba.size() == 4u * std::size_t(image.width) * std::size_t(image.height) ? 0 : 1;
}
