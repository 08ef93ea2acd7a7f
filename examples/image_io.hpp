// Image files for the tools: OpenEXR (libopenexr) for EXR, libpng for previews, and PFM.
// Errors are returned as text (empty = success). OpenEXR reports errors by exceptions; they
// are caught here, at the edge of the tools, and never reach the library.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "pfm.hpp"

#ifdef FIREFLY_HAVE_OPENEXR
#include <Imath/ImathBox.h>
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfOutputFile.h>
#endif
#ifdef FIREFLY_HAVE_PNG
#include <png.h>
#endif

namespace firefly_tools {

// A float image with named channels, interleaved.
struct image {
    int width = 0, height = 0;
    std::vector<std::string> channels;
    std::vector<float> pixels;
    int channel_count() const { return static_cast<int>(channels.size()); }
};

inline bool have_exr() {
#ifdef FIREFLY_HAVE_OPENEXR
    return true;
#else
    return false;
#endif
}
inline bool have_png() {
#ifdef FIREFLY_HAVE_PNG
    return true;
#else
    return false;
#endif
}

// Reads the named channels (in that order) of an EXR file.
inline std::string read_exr(const std::string& path, const std::vector<std::string>& names, image& out) {
#ifdef FIREFLY_HAVE_OPENEXR
    try {
        {
            std::FILE* probe = std::fopen(path.c_str(), "rb");
            if (!probe) return "cannot open " + path;
            unsigned char magic[4] = {0, 0, 0, 0};
            const bool ok = std::fread(magic, 1, 4, probe) == 4;
            std::fclose(probe);
            if (!ok || magic[0] != 0x76 || magic[1] != 0x2f || magic[2] != 0x31 || magic[3] != 0x01)
                return path + " is not an OpenEXR file";
        }
        Imf::InputFile file(path.c_str());
        const Imath::Box2i dw = file.header().dataWindow();
        const long w = static_cast<long>(dw.max.x) - dw.min.x + 1, h = static_cast<long>(dw.max.y) - dw.min.y + 1;
        if (w <= 0 || h <= 0 || w > (1 << 16) || h > (1 << 16)) return path + ": bad data window";
        std::string missing;
        for (const auto& n : names)
            if (!file.header().channels().findChannel(n.c_str())) missing += (missing.empty() ? "" : ", ") + n;
        if (!missing.empty()) {
            std::string have;
            for (auto it = file.header().channels().begin(); it != file.header().channels().end(); ++it)
                have += (have.empty() ? "" : ", ") + std::string(it.name());
            return path + ": missing channel(s) " + missing + " (the file has: " + have + ")";
        }
        out.width = static_cast<int>(w);
        out.height = static_cast<int>(h);
        out.channels = names;
        const std::size_t nc = names.size();
        out.pixels.assign(static_cast<std::size_t>(w * h) * nc, 0.0f);
        Imf::FrameBuffer fb;
        for (std::size_t c = 0; c < nc; ++c) {
            char* base = reinterpret_cast<char*>(out.pixels.data() + c) -
                         (static_cast<long>(dw.min.x) + static_cast<long>(dw.min.y) * w) * static_cast<long>(nc * sizeof(float));
            fb.insert(names[c].c_str(), Imf::Slice(Imf::FLOAT, base, nc * sizeof(float), nc * sizeof(float) * static_cast<std::size_t>(w)));
        }
        file.setFrameBuffer(fb);
        file.readPixels(dw.min.y, dw.max.y);
        return {};
    } catch (const std::exception& e) {
        return path + ": " + e.what();
    }
#else
    (void)names;
    (void)out;
    return "cannot read " + path + ": built without OpenEXR (apt-get install libopenexr-dev)";
#endif
}

// Writes all channels of `img` as 32-bit float EXR (ZIP compression).
inline std::string write_exr(const std::string& path, const image& img) {
#ifdef FIREFLY_HAVE_OPENEXR
    try {
        Imf::Header header(img.width, img.height);
        header.compression() = Imf::ZIP_COMPRESSION;
        const std::size_t nc = img.channels.size();
        for (const auto& n : img.channels) header.channels().insert(n.c_str(), Imf::Channel(Imf::FLOAT));
        Imf::OutputFile file(path.c_str(), header);
        Imf::FrameBuffer fb;
        for (std::size_t c = 0; c < nc; ++c)
            fb.insert(img.channels[c].c_str(),
                      Imf::Slice(Imf::FLOAT, const_cast<char*>(reinterpret_cast<const char*>(img.pixels.data() + c)),
                                 nc * sizeof(float), nc * sizeof(float) * static_cast<std::size_t>(img.width)));
        file.setFrameBuffer(fb);
        file.writePixels(img.height);
        return {};
    } catch (const std::exception& e) {
        return path + ": " + e.what();
    }
#else
    (void)img;
    return "cannot write " + path + ": built without OpenEXR";
#endif
}

// An 8-bit sRGB preview of an RGB image (channels 0..2), exposure-scaled and clamped.
inline std::string write_png_preview(const std::string& path, const float* rgb, int width, int height,
                                     std::size_t stride_channels = 3, float exposure = 1.0f) {
#ifdef FIREFLY_HAVE_PNG
    std::vector<unsigned char> px(static_cast<std::size_t>(width) * height * 3);
    for (std::size_t i = 0; i < static_cast<std::size_t>(width) * height; ++i)
        for (int c = 0; c < 3; ++c) {
            float v = rgb[i * stride_channels + c] * exposure;
            v = std::isfinite(v) ? std::clamp(v, 0.0f, 1.0f) : 1.0f;
            v = v <= 0.0031308f ? 12.92f * v : 1.055f * std::pow(v, 1.0f / 2.4f) - 0.055f;
            px[i * 3 + c] = static_cast<unsigned char>(v * 255.0f + 0.5f);
        }
    png_image im{};
    im.version = PNG_IMAGE_VERSION;
    im.width = static_cast<png_uint_32>(width);
    im.height = static_cast<png_uint_32>(height);
    im.format = PNG_FORMAT_RGB;
    if (!png_image_write_to_file(&im, path.c_str(), 0, px.data(), 0, nullptr))
        return path + ": " + im.message;
    return {};
#else
    (void)rgb;
    (void)width;
    (void)height;
    (void)stride_channels;
    (void)exposure;
    return path + " skipped: built without libpng (apt-get install libpng-dev)";
#endif
}

}  // namespace firefly_tools
