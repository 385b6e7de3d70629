// write_image: PNG (8-bit sRGB, straight alpha) through libpng, EXR (float
// linear RGBA) through OpenEXR, both encoded in memory and written atomically.
#include "pqdc/render.hpp"

#include "pqdc/exceptions.hpp"

#include "io/atomic_file.hpp"

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfIO.h>
#include <ImfOutputFile.h>
#include <png.h>

#include <algorithm>
#include <cmath>
#include <csetjmp>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

namespace pqdc {
namespace {

std::string lowercase(std::string s) {
    for (char& c : s)
        if (c >= 'A' && c <= 'Z') c = char(c - 'A' + 'a');
    return s;
}

float srgb_encode(float linear) {
    const float c = std::min(1.0f, std::max(0.0f, linear));
    return c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1.0f / 2.4f) - 0.055f;
}


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
