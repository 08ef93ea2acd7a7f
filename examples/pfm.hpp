// PFM (portable float map) reading and writing for the tools and tests. PFM is three text
// lines ("PF" or "Pf", "width height", scale whose sign gives the byte order) and then
// bottom-up rows of 32-bit floats. Errors are values; nothing throws.
#pragma once

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

namespace firefly_tools {

struct pfm_image {
    int width = 0, height = 0, channels = 0;
    std::vector<float> pixels;  // top-down, interleaved
};

// Returns an empty string on success, else the reason.
inline std::string read_pfm(const std::string& path, pfm_image& out) {
    std::FILE* f = std::fopen(path.c_str(), "rb");
    if (!f) return "cannot open " + path;
    char magic[3] = {0, 0, 0};
    int w = 0, h = 0;
    double scale = 0;
    const bool header = std::fscanf(f, "%2s %d %d %lf", magic, &w, &h, &scale) == 4;
    int sep = std::fgetc(f);  // exactly one whitespace byte before the data
    if (!header || sep == EOF || (std::strcmp(magic, "PF") != 0 && std::strcmp(magic, "Pf") != 0)) {
        std::fclose(f);
        return path + " is not a PFM file";
    }
    const int c = magic[1] == 'F' ? 3 : 1;
    if (w <= 0 || h <= 0 || w > (1 << 16) || h > (1 << 16) || scale == 0) {
        std::fclose(f);
        return path + ": bad PFM size or scale";
    }
    const std::size_t n = static_cast<std::size_t>(w) * static_cast<std::size_t>(h) * static_cast<std::size_t>(c);
    std::vector<float> raw(n);
    const std::size_t got = std::fread(raw.data(), sizeof(float), n, f);
    std::fclose(f);
    if (got != n) return path + ": truncated PFM data";
    const std::uint16_t probe = 1;
    const bool host_little = *reinterpret_cast<const std::uint8_t*>(&probe) == 1;
    if ((scale < 0) != host_little) {
        for (float& v : raw) {
            std::uint32_t u;
            std::memcpy(&u, &v, 4);
            u = (u >> 24) | ((u >> 8) & 0xff00u) | ((u << 8) & 0xff0000u) | (u << 24);
            std::memcpy(&v, &u, 4);
        }
    }
    out.width = w;
    out.height = h;
    out.channels = c;
    out.pixels.resize(n);
    const std::size_t row = static_cast<std::size_t>(w) * static_cast<std::size_t>(c);
    for (int y = 0; y < h; ++y)  // PFM rows are bottom-up
        std::memcpy(&out.pixels[static_cast<std::size_t>(y) * row],
                    &raw[static_cast<std::size_t>(h - 1 - y) * row], row * sizeof(float));
    return {};
}

inline std::string write_pfm(const std::string& path, const pfm_image& img) {
    std::FILE* f = std::fopen(path.c_str(), "wb");
    if (!f) return "cannot write " + path;
    const std::uint16_t probe = 1;
    const bool host_little = *reinterpret_cast<const std::uint8_t*>(&probe) == 1;
    std::fprintf(f, "%s\n%d %d\n%s\n", img.channels == 3 ? "PF" : "Pf", img.width, img.height,
                 host_little ? "-1.0" : "1.0");
    const std::size_t row = static_cast<std::size_t>(img.width) * static_cast<std::size_t>(img.channels);
    bool ok = true;
    for (int y = img.height - 1; y >= 0 && ok; --y)
        ok = std::fwrite(&img.pixels[static_cast<std::size_t>(y) * row], sizeof(float), row, f) == row;
    ok = (std::fclose(f) == 0) && ok;
    return ok ? std::string() : "write failed: " + path;
}

}  // namespace firefly_tools
