// The caption: a built-in bitmap font (render_font.inc), 4 x 4 sub-samples
// per pixel, so titles need no font library.
#include "render/render_internal.hpp"

#include <algorithm>
#include <cmath>

namespace pqdc::render_detail {
namespace {

#include "render_font.inc"

}  // namespace

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

}  // namespace pqdc::render_detail
