// PFM (portable float map) reading and writing for the tools and tests. PFM is three text
// lines ("PF" or "Pf", "width height", scale whose sign gives the byte order) and then
// bottom-up rows of 32-bit floats. Errors are values; nothing throws.
//
// The reader is strict: the header is "PF|Pf", whitespace, width, whitespace, height,
// whitespace, scale and exactly one whitespace byte; no comments, no CR. The data must be
// exactly width x height x channels floats: a short file and trailing bytes are both refused.
// Sizes are checked against the bytes present before anything is allocated.
#pragma once

#include <sys/stat.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

namespace firefly_tools {

// Largest image the tools read: 2^27 pixels (e.g. 16384 x 8192); each side at most 2^16.
inline constexpr std::uint64_t max_pixels = std::uint64_t{1} << 27;
inline constexpr int max_side = 1 << 16;

struct pfm_image {
    int width = 0, height = 0, channels = 0;
    std::vector<float> pixels;  // top-down, interleaved
};

namespace detail {

// Cursor over the header bytes.
struct pfm_cursor {
    const unsigned char* p;
    const unsigned char* end;
    bool space() const { return p < end && (*p == ' ' || *p == '\n' || *p == '\t'); }
    void skip_space() {
        while (space()) ++p;
    }
    // A decimal integer in [1, max_side].
    bool size(int& v) {
        std::uint32_t n = 0;
        const unsigned char* start = p;
        while (p < end && *p >= '0' && *p <= '9' && p - start < 7) n = n * 10 + (*p++ - '0');
        if (p == start || n == 0 || n > static_cast<std::uint32_t>(max_side)) return false;
        v = static_cast<int>(n);
        return true;
    }
    // The scale: a plain decimal number ([-]digits[.digits]), finite and non-zero.
    bool scale(double& v) {
        char buf[32];
        std::size_t n = 0;
        while (p < end && n + 1 < sizeof buf && *p != 0 && std::strchr("+-.0123456789eE", *p) != nullptr)
            buf[n++] = static_cast<char>(*p++);
        buf[n] = '\0';
        char* stop = nullptr;
        v = std::strtod(buf, &stop);
        return n > 0 && stop == buf + n && std::isfinite(v) && v != 0.0;
    }
};

inline bool host_little_endian() {
    const std::uint16_t probe = 1;
    std::uint8_t first = 0;
    std::memcpy(&first, &probe, 1);
    return first == 1;
}

}  // namespace detail

// Parses a whole PFM file held in memory. `name` only labels the messages.
inline std::string parse_pfm(const unsigned char* data, std::size_t size, const std::string& name, pfm_image& out) {
    detail::pfm_cursor cur{data, data + size};
    if (size < 3 || data[0] != 'P' || (data[1] != 'F' && data[1] != 'f')) return name + " is not a PFM file";
    const int c = data[1] == 'F' ? 3 : 1;
    cur.p = data + 2;
    // Comments and CR line ends are refused by name rather than read as shifted data.
    auto bad = [&](const char* what) {
        for (const unsigned char* q = data; q < cur.end && q <= cur.p; ++q)
            if (*q == '#' || *q == '\r') return name + ": PFM header with a comment or CR (not supported)";
        return name + ": bad PFM " + what;
    };
    if (!cur.space()) return bad("magic");
    int w = 0, h = 0;
    double scale = 0;
    cur.skip_space();
    if (!cur.size(w) || !cur.space()) return bad("width");
    cur.skip_space();
    if (!cur.size(h) || !cur.space()) return bad("height");
    cur.skip_space();
    if (!cur.scale(scale) || !cur.space()) return bad("scale");
    ++cur.p;  // exactly one whitespace byte before the data
    const std::uint64_t pixels = static_cast<std::uint64_t>(w) * static_cast<std::uint64_t>(h);
    const std::uint64_t n = pixels * static_cast<std::uint64_t>(c);
    const std::uint64_t have = static_cast<std::uint64_t>(cur.end - cur.p);
    if (have < n * 4) return name + ": truncated PFM data";
    if (have > n * 4) return name + ": PFM data followed by extra bytes (or a header this reader does not take)";
    if (pixels > max_pixels) return name + ": PFM image larger than the limit of 2^27 pixels";
    const bool swap = (scale < 0) != detail::host_little_endian();
    out.width = w;
    out.height = h;
    out.channels = c;
    out.pixels.resize(static_cast<std::size_t>(n));
    const std::size_t row = static_cast<std::size_t>(w) * static_cast<std::size_t>(c);
    for (int y = 0; y < h; ++y) {  // PFM rows are bottom-up
        const unsigned char* src = cur.p + static_cast<std::size_t>(h - 1 - y) * row * 4;
        float* dst = &out.pixels[static_cast<std::size_t>(y) * row];
        for (std::size_t i = 0; i < row; ++i) {
            std::uint32_t u;
            std::memcpy(&u, src + i * 4, 4);
            if (swap) u = (u >> 24) | ((u >> 8) & 0xff00u) | ((u << 8) & 0xff0000u) | (u << 24);
            std::memcpy(dst + i, &u, 4);
        }
    }
    return {};
}

// An input must be a regular file, which stat tells before the file is opened: opening a pipe
// waits for a writer that may never come. `size`, if given, receives the file's size.
inline std::string check_regular_input(const std::string& path, std::uint64_t* size = nullptr) {
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0) return "cannot open " + path;
    if (!S_ISREG(st.st_mode)) return path + " is not a regular file";
    if (size) *size = static_cast<std::uint64_t>(st.st_size);
    return {};
}

// Reads a PFM file: a regular file whose size is checked before it is read.
inline std::string read_pfm(const std::string& path, pfm_image& out) {
    if (std::string e = check_regular_input(path); !e.empty()) return e;
    std::FILE* f = std::fopen(path.c_str(), "rb");
    if (!f) return "cannot open " + path;
    struct stat st {};
    if (fstat(fileno(f), &st) != 0 || !S_ISREG(st.st_mode)) {
        std::fclose(f);
        return path + " is not a regular file";
    }
    // Header (at most ~40 bytes) plus the largest image the limit allows.
    const std::uint64_t limit = 64 + max_pixels * 12;
    if (static_cast<std::uint64_t>(st.st_size) > limit) {
        std::fclose(f);
        return path + ": file larger than any PFM this tool reads";
    }
    std::vector<unsigned char> bytes(static_cast<std::size_t>(st.st_size));
    const bool ok = std::fread(bytes.data(), 1, bytes.size(), f) == bytes.size();
    std::fclose(f);
    if (!ok) return "cannot read " + path;
    return parse_pfm(bytes.data(), bytes.size(), path, out);
}

// Writes img to an open stream (`name` for messages); the caller closes it.
inline std::string write_pfm(std::FILE* f, const std::string& name, const pfm_image& img) {
    if (std::fprintf(f, "%s\n%d %d\n%s\n", img.channels == 3 ? "PF" : "Pf", img.width, img.height,
                     detail::host_little_endian() ? "-1.0" : "1.0") < 0)
        return "write failed: " + name;
    const std::size_t row = static_cast<std::size_t>(img.width) * static_cast<std::size_t>(img.channels);
    bool ok = true;
    for (int y = img.height - 1; y >= 0 && ok; --y)
        ok = std::fwrite(&img.pixels[static_cast<std::size_t>(y) * row], sizeof(float), row, f) == row;
    return ok ? std::string() : "write failed: " + name;
}

inline std::string write_pfm(const std::string& path, const pfm_image& img) {
    std::FILE* f = std::fopen(path.c_str(), "wb");
    if (!f) return "cannot write " + path;
    std::string e = write_pfm(f, path, img);
    if (std::fclose(f) != 0 && e.empty()) e = "write failed: " + path;
    return e;
}

}  // namespace firefly_tools
