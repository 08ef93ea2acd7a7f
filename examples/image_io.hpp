// Image files for the tools: OpenEXR (libopenexr) for EXR, libpng for previews, and PFM.
// Errors are returned as text (empty = success). OpenEXR reports errors by exceptions; they
// are caught here, at the edge of the tools, and never reach the library.
#pragma once

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <new>
#include <stdexcept>
#include <string>
#include <vector>

#include "pfm.hpp"

#ifdef FIREFLY_HAVE_OPENEXR
#include <Imath/ImathBox.h>
#include <Imath/half.h>
#include <OpenEXR/IlmThreadPool.h>
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfPartType.h>
#include <OpenEXR/ImfIO.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfInputPart.h>
#include <OpenEXR/ImfMultiPartInputFile.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStdIO.h>
#include <OpenEXR/ImfThreading.h>
#include <OpenEXR/openexr.h>

#include "exr_zip.hpp"
#endif
#ifdef FIREFLY_HAVE_PNG
#include <png.h>
#endif

namespace firefly_tools {

// An inclusive pixel rectangle, as EXR stores windows.
struct window {
    int min_x = 0, min_y = 0, max_x = -1, max_y = -1;
    bool empty() const { return max_x < min_x || max_y < min_y; }
};

// A float image with named channels, interleaved. `data_window` and `display_window` come
// from an EXR input and go to the outputs; empty windows mean "at the origin, image-sized".
struct image {
    int width = 0, height = 0;
    std::vector<std::string> channels;
    std::vector<float> pixels;
    window data_window{}, display_window{};
    int channel_count() const { return static_cast<int>(channels.size()); }
};

inline bool have_exr() {
#ifdef FIREFLY_HAVE_OPENEXR
    return true;
#else
    return false;
#endif
}
// OpenEXR's own thread pool (decompression of the lines of a file, compression on write):
// n threads, or none for n <= 1.
inline void set_exr_threads(unsigned n) {
#ifdef FIREFLY_HAVE_OPENEXR
    Imf::setGlobalThreadCount(n > 1 ? static_cast<int>(n) : 0);
#else
    (void)n;
#endif
}

inline bool have_png() {
#ifdef FIREFLY_HAVE_PNG
    return true;
#else
    return false;
#endif
}

#ifdef FIREFLY_HAVE_OPENEXR
// Bytes of float samples a file of `file_bytes` may claim: within the pixel limit, and no
// more than 1 MiB plus 4096 per byte of file (zlib inflates at most ~1032:1, and half data
// doubles when read as float), so a tiny file cannot claim gigabytes.
inline bool exr_size_plausible(std::uint64_t pixels, std::uint64_t channels, std::uint64_t file_bytes) {
    if (pixels > max_pixels) return false;
    return pixels * channels * 4 <= (std::uint64_t{1} << 20) + file_bytes * 4096;
}

// A data window's width and height (64-bit: a window may span int's range) into w and h, and
// whether both sides are in 1..max_side.
inline bool exr_window_shape(const Imath::Box2i& dw, std::int64_t& w, std::int64_t& h) {
    w = std::int64_t{dw.max.x} - dw.min.x + 1;
    h = std::int64_t{dw.max.y} - dw.min.y + 1;
    return w > 0 && h > 0 && w <= max_side && h <= max_side;
}

// The same, and `channels` of it plausible for a file of stream_bytes: a window the tools read.
inline bool exr_window_fits(const Imath::Box2i& dw, std::size_t channels, std::uint64_t stream_bytes, std::int64_t& w,
                            std::int64_t& h) {
    return exr_window_shape(dw, w, h) && exr_size_plausible(static_cast<std::uint64_t>(w * h), channels, stream_bytes);
}

inline std::size_t exr_channel_count(const Imf::Header& header) {
    std::size_t n = 0;
    for (auto it = header.channels().begin(); it != header.channels().end(); ++it) ++n;
    return n;
}

// A header's channel names, comma-separated, in the file's order.
inline std::string exr_channel_list(const Imf::Header& header) {
    std::string list;
    for (auto it = header.channels().begin(); it != header.channels().end(); ++it)
        list += (list.empty() ? "" : ", ") + std::string(it.name());
    return list;
}

inline std::string exr_channels_missing(const Imf::Header& header, const std::vector<std::string>& names) {
    std::string missing;
    for (const auto& n : names)
        if (!header.channels().findChannel(n.c_str())) missing += (missing.empty() ? "" : ", ") + n;
    if (missing.empty()) return {};
    return "missing channel(s) " + missing + " (the file has: " + exr_channel_list(header) + ")";
}

// True when a chlist value (entries of name, NUL, 16 bytes; then a NUL) fills exactly `v`:
// OpenEXR 3.1 parses it without looking at the attribute's size.
inline bool exr_chlist_fits(const std::vector<char>& v) {
    std::size_t p = 0;
    while (p < v.size()) {
        if (v[p] == 0) return p + 1 == v.size();
        const void* nul = std::memchr(v.data() + p, 0, std::min<std::size_t>(v.size() - p, 256));
        if (!nul) return false;
        p = static_cast<std::size_t>(static_cast<const char*>(nul) - v.data()) + 1 + 16;
    }
    return false;
}

inline std::uint32_t exr_u32(const char* b) {
    const auto* u = reinterpret_cast<const unsigned char*>(b);
    return u[0] | (u[1] << 8) | (u[2] << 16) | (std::uint32_t{u[3]} << 24);
}

// True when a stringvector value (entries of a 32-bit length and that many bytes) fills `v`.
inline bool exr_stringvector_fits(const std::vector<char>& v) {
    std::size_t p = 0;
    while (v.size() - p >= 4) {
        const std::uint32_t n = exr_u32(v.data() + p);
        p += 4;
        if (n > v.size() - p) return false;
        p += n;
    }
    return p == v.size();
}

// The value size of the attribute types OpenEXR 3.1 reads with a fixed size whatever the
// size field says; 0 for the others (read by size, or checked by content).
inline std::uint32_t exr_fixed_size(const std::string& type) {
    static const std::pair<const char*, std::uint32_t> fixed[] = {
        {"box2i", 16}, {"box2f", 16}, {"v2i", 8},  {"v2f", 8},  {"v2d", 16}, {"v3i", 12}, {"v3f", 12},
        {"v3d", 24},   {"int", 4},    {"float", 4}, {"double", 8}, {"compression", 1}, {"lineOrder", 1},
        {"envmap", 1}, {"deepImageState", 1}, {"m33f", 36}, {"m33d", 72}, {"m44f", 64}, {"m44d", 128},
        {"rational", 8}, {"timecode", 8}, {"keycode", 28}, {"tiledesc", 9}, {"chromaticities", 32}};
    for (const auto& f : fixed)
        if (type == f.first) return f.second;
    return 0;
}

// Walks the attribute list of every header (name, type, 32-bit size, value) and checks each
// claimed size against the bytes left, fixed-size types against their size, and the values
// OpenEXR 3.1 parses by their content (channel lists, string vectors, previews) against
// their sizes, so that OpenEXR never allocates for a value the stream cannot hold. Leaves
// the stream after the headers.
inline bool exr_attribute_sizes_fit(Imf::IStream& in, std::uint64_t stream_bytes, int version) {
    const bool multipart = (version & 0x1000) != 0;
    auto read_name = [&](std::string& out) {
        out.clear();
        char ch = 0;
        for (int i = 0; i < 256; ++i) {
            if (in.tellg() >= stream_bytes) return false;
            in.read(&ch, 1);
            if (ch == 0) return true;
            out += ch;
        }
        return false;
    };
    std::string name, type;
    std::vector<char> value;
    for (int header = 0;; ++header) {
        for (int attr = 0;; ++attr) {
            if (!read_name(name)) return false;
            if (name.empty()) {
                if (attr == 0 && header > 0) return true;  // the empty header ending a multi-part list
                break;
            }
            char b[8];
            if (!read_name(type) || stream_bytes - in.tellg() < 4) return false;
            in.read(b, 4);
            const std::uint32_t size = exr_u32(b);
            if (size > 0x7fffffffu || size > stream_bytes - in.tellg()) return false;
            const std::uint32_t fixed = exr_fixed_size(type);
            if (fixed != 0 && size != fixed) return false;
            if (type == "chlist" || type == "stringvector") {
                value.resize(size);
                if (size > 0) in.read(value.data(), static_cast<int>(size));
                if (!(type == "chlist" ? exr_chlist_fits(value) : exr_stringvector_fits(value))) return false;
            } else if (type == "preview") {  // width, height, then width x height RGBA bytes
                if (size < 8) return false;
                in.read(b, 8);
                if (std::uint64_t{exr_u32(b)} * exr_u32(b + 4) * 4 + 8 != size) return false;
                in.seekg(in.tellg() + size - 8);
            } else {
                in.seekg(in.tellg() + size);
            }
        }
        if (!multipart) return true;
    }
}

// Reads the header only and checks what it claims before OpenEXR allocates for the image:
// attribute sizes, the data window (each side at most 2^16) and the bytes of float samples.
// `multipart` tells whether the file holds several parts.
inline std::string exr_header_check(Imf::IStream& in, std::uint64_t stream_bytes, std::size_t channels_wanted,
                                    bool& multipart) {
    char head[8] = {0};
    if (stream_bytes < 8) return "is not an OpenEXR file";
    in.read(head, 8);
    if (head[0] != 0x76 || head[1] != 0x2f || head[2] != 0x31 || head[3] != 0x01) return "is not an OpenEXR file";
    int version = 0;
    std::memcpy(&version, head + 4, 4);
    multipart = (version & 0x1000) != 0;
    if (!exr_attribute_sizes_fit(in, stream_bytes, version)) return "has a header attribute larger than the file";
    const std::uint64_t end = in.tellg();
    in.seekg(8);
    Imf::Header probe;
    probe.readFrom(in, version);
    if (!multipart && in.tellg() != end) return "has a header OpenEXR reads differently from its sizes";
    std::int64_t w = 0, h = 0;
    if (!exr_window_shape(probe.dataWindow(), w, h)) return "has a bad data window";
    if (!exr_size_plausible(static_cast<std::uint64_t>(w * h), std::max(exr_channel_count(probe), channels_wanted),
                            stream_bytes))
        return "has a data window too large for the file (or beyond the 2^27-pixel limit)";
    in.seekg(0);
    return {};
}

// The threads of OpenEXR's global pool (set_exr_threads), at least 1: the calling thread.
inline std::size_t exr_pool_threads() {
    return static_cast<std::size_t>(std::max(1, IlmThread::ThreadPool::globalThreadPool().numThreads()));
}

// Runs fn(first, last) over [0, count) in bands on OpenEXR's global thread pool (set by
// set_exr_threads; with no threads the bands run here, in order). False when a band threw
// (out of memory): an exception must not leave a task (a pool thread would terminate, and
// without threads the group would wait for a task that never ends).
template <class Fn>
bool on_exr_pool(std::size_t count, const Fn& fn) {
    class band : public IlmThread::Task {
    public:
        band(IlmThread::TaskGroup* g, const Fn& f, std::size_t a, std::size_t b, unsigned char& failed)
            : Task(g), f_(f), a_(a), b_(b), failed_(failed) {}
        void execute() override {
            try {
                f_(a_, b_);
            } catch (...) {
                failed_ = 1;
            }
        }

    private:
        const Fn& f_;
        std::size_t a_, b_;
        unsigned char& failed_;
    };
    const std::size_t bands = std::min(count, exr_pool_threads() * 4);
    std::vector<unsigned char> failed(bands, 0);
    {
        IlmThread::TaskGroup group;  // its destructor waits for every band
        for (std::size_t k = 0; k < bands; ++k)
            IlmThread::ThreadPool::addGlobalTask(new band(&group, fn, count * k / bands, count * (k + 1) / bands, failed[k]));
    }
    return std::find(failed.begin(), failed.end(), 1) == failed.end();
}

// How a scanline file's chunks are laid out, when the tools unpack them themselves (ZIP, ZIPS
// or no compression, every channel sampled at every pixel; lines_per_chunk 0 otherwise): per
// channel in file order, its bytes per sample, its type and where it goes in the output.
struct exr_chunk_layout {
    struct channel {
        int bytes;
        Imf::PixelType type;
        int dest;  // index in the wanted names, -1 when not wanted
    };
    std::vector<channel> channels;
    std::size_t line_bytes = 0;
    int lines_per_chunk = 0;
};

inline exr_chunk_layout exr_layout_of(const Imf::Header& header, const std::vector<std::string>& names, int width) {
    exr_chunk_layout l;
    const Imf::Compression c = header.compression();
    if (header.hasTileDescription() || (header.hasType() && header.type() != Imf::SCANLINEIMAGE)) return l;
    if (c != Imf::NO_COMPRESSION && c != Imf::ZIPS_COMPRESSION && c != Imf::ZIP_COMPRESSION) return l;
    if (__BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__) return l;  // the chunks' bytes are little-endian
    std::size_t pixel_bytes = 0;
    for (auto it = header.channels().begin(); it != header.channels().end(); ++it) {
        const Imf::Channel& ch = it.channel();
        if (ch.xSampling != 1 || ch.ySampling != 1) return {};
        if (ch.type != Imf::HALF && ch.type != Imf::FLOAT && ch.type != Imf::UINT) return {};
        const int dest = static_cast<int>(std::find(names.begin(), names.end(), it.name()) - names.begin());
        l.channels.push_back({ch.type == Imf::HALF ? 2 : 4, ch.type, dest < static_cast<int>(names.size()) ? dest : -1});
        pixel_bytes += static_cast<std::size_t>(l.channels.back().bytes);
    }
    l.line_bytes = pixel_bytes * static_cast<std::size_t>(width);
    l.lines_per_chunk = c == Imf::ZIP_COMPRESSION ? exr_zip::lines_zip : c == Imf::ZIPS_COMPRESSION ? exr_zip::lines_zips
                                                                                                   : exr_zip::lines_none;
    return l;
}

// One line of a chunk (the file's channels in order) into the wanted channels of `out` (nc
// floats per pixel), converting half and unsigned int as OpenEXR does.
inline void exr_scatter_line(const exr_chunk_layout& l, const std::uint8_t* p, int width, std::size_t nc, float* out) {
    for (const auto& ch : l.channels) {
        if (ch.dest >= 0) {
            float* o = out + ch.dest;
            for (int x = 0; x < width; ++x, p += ch.bytes, o += nc) {
                if (ch.type == Imf::FLOAT) {
                    std::memcpy(o, p, 4);
                } else if (ch.type == Imf::HALF) {
                    std::uint16_t b;
                    std::memcpy(&b, p, 2);
                    Imath::half h;
                    h.setBits(b);
                    *o = static_cast<float>(h);
                } else {
                    std::uint32_t u;
                    std::memcpy(&u, p, 4);
                    *o = static_cast<float>(u);
                }
            }
        } else {
            p += static_cast<std::size_t>(ch.bytes) * static_cast<std::size_t>(width);
        }
    }
}

// Reads the pixels of an open file whose layout exr_layout_of accepted into out.pixels (sized,
// nc channels): the chunks' stored bytes through OpenEXR, then unpacked on its thread pool.
// File: Imf::InputFile, or Imf::InputPart of a multi-part file.
template <class File>
std::string exr_read_chunks(File& file, const exr_chunk_layout& l, const Imath::Box2i& dw,
                                   std::size_t nc, image& out) {
    const int width = dw.max.x - dw.min.x + 1, height = dw.max.y - dw.min.y + 1;
    const std::size_t chunks = static_cast<std::size_t>((height + l.lines_per_chunk - 1) / l.lines_per_chunk);
    std::vector<std::size_t> start(chunks + 1, 0);
    std::vector<std::uint8_t> stored;
    for (std::size_t k = 0; k < chunks; ++k) {
        const char* data = nullptr;
        int size = 0;
        file.rawPixelData(dw.min.y + static_cast<int>(k) * l.lines_per_chunk, data, size);
        if (size < 0) return "a chunk of negative size";
        stored.insert(stored.end(), data, data + size);
        start[k + 1] = stored.size();
    }
    // A chunk stored in as many bytes as its lines hold, or more, holds them as they are (as
    // OpenEXR reads it); fewer are a zlib stream (ZIP, ZIPS) or a damaged chunk.
    const bool zip = file.header().compression() != Imf::NO_COMPRESSION;
    std::vector<unsigned char> bad(chunks, 0);
    const bool ran = on_exr_pool(chunks, [&](std::size_t first, std::size_t last) {
        exr_zip::codec codec;  // per band: nothing of a hostile file's size outlives the read
        std::vector<std::uint8_t> raw;
        for (std::size_t k = first; k < last; ++k) {
            const int y0 = static_cast<int>(k) * l.lines_per_chunk;
            const int lines = std::min(l.lines_per_chunk, height - y0);
            const std::size_t n = l.line_bytes * static_cast<std::size_t>(lines);
            raw.resize(n);
            const std::size_t packed = start[k + 1] - start[k];
            if (packed >= n) {
                std::memcpy(raw.data(), stored.data() + start[k], n);
            } else if (!zip || !codec.unpack(stored.data() + start[k], packed, raw.data(), n)) {
                bad[k] = 1;
                continue;
            }
            for (int j = 0; j < lines; ++j)
                exr_scatter_line(l, raw.data() + l.line_bytes * static_cast<std::size_t>(j), width, nc,
                                 out.pixels.data() + (static_cast<std::size_t>(y0 + j) * static_cast<std::size_t>(width)) * nc);
        }
    });
    if (!ran) return "out of memory";
    for (std::size_t k = 0; k < chunks; ++k)
        if (bad[k]) return "the chunk at line " + std::to_string(dw.min.y + static_cast<int>(k) * l.lines_per_chunk) +
                           " does not unpack to its lines";
    return {};
}

// The output's size and windows from the data and display windows of the file (or of the
// parts) its channels come from; false when the window is bad or too large for the file.
inline bool exr_prepare(const Imath::Box2i& dw, const Imath::Box2i& disp, const std::vector<std::string>& names,
                        std::uint64_t stream_bytes, image& out) {
    std::int64_t w = 0, h = 0;
    if (!exr_window_fits(dw, names.size(), stream_bytes, w, h)) return false;
    out.width = static_cast<int>(w);
    out.height = static_cast<int>(h);
    out.channels = names;
    out.pixels.assign(static_cast<std::size_t>(w * h) * names.size(), 0.0f);
    out.data_window = {dw.min.x, dw.min.y, dw.max.x, dw.max.y};
    out.display_window = {disp.min.x, disp.min.y, disp.max.x, disp.max.y};
    return true;
}

// Reads the channels `wanted` names from one file or part into `out` (prepared, its channels
// interleaved in the order of `wanted`; an empty name is a channel another part holds).
template <class File>
std::string exr_read_part(File& file, const std::vector<std::string>& wanted, image& out) {
    const Imath::Box2i dw = file.header().dataWindow();
    const std::size_t nc = wanted.size();
    const exr_chunk_layout layout = exr_layout_of(file.header(), wanted, out.width);
    if (layout.lines_per_chunk > 0) return exr_read_chunks(file, layout, dw, nc, out);
    // Slice::Make places the window's origin with integer (not pointer) arithmetic, so
    // windows far from (0, 0) address nothing outside the buffer.
    Imf::FrameBuffer fb;
    for (std::size_t c = 0; c < nc; ++c)
        if (!wanted[c].empty())
            fb.insert(wanted[c].c_str(), Imf::Slice::Make(Imf::FLOAT, out.pixels.data() + c, dw, nc * sizeof(float),
                                                          nc * sizeof(float) * static_cast<std::size_t>(out.width)));
    file.setFrameBuffer(fb);
    file.readPixels(dw.min.y, dw.max.y);
    return {};
}

// A single-part file: every channel from its one header.
inline std::string exr_read_single(Imf::IStream& in, std::uint64_t stream_bytes, const std::vector<std::string>& names,
                                   image& out) {
    Imf::InputFile file(in);
    if (!exr_prepare(file.header().dataWindow(), file.header().displayWindow(), names, stream_bytes, out))
        return "bad data window";
    const std::string missing = exr_channels_missing(file.header(), names);
    if (!missing.empty()) return missing;
    return exr_read_part(file, names, out);
}

// Which part of a multi-part file holds each named channel (deep parts hold none): a part
// with a channel of that name, or a part named PART holding CHANNEL for PART.CHANNEL. A name
// with more than one reading (two parts hold it, or it is a channel's name and PART.CHANNEL
// too) is refused with every reading, as are two names that read one channel. `part` and
// `channel` receive the part and the name within it.
inline std::string exr_locate_channels(const Imf::MultiPartInputFile& mp, const std::vector<std::string>& names,
                                       std::vector<int>& part, std::vector<std::string>& channel) {
    auto flat = [&](int p) {
        const Imf::Header& h = mp.header(p);
        return !(h.hasType() && Imf::isDeepData(h.type()));
    };
    auto has = [&](int p, const std::string& n) { return flat(p) && mp.header(p).channels().findChannel(n.c_str()) != nullptr; };
    auto name_of = [&](int p) { return mp.header(p).hasName() ? mp.header(p).name() : std::string(); };
    auto part_name = [&](int p) { return mp.header(p).hasName() ? name_of(p) : "#" + std::to_string(p); };  // for messages
    std::string missing;
    for (const auto& n : names) {
        std::vector<int> hits;
        std::vector<std::string> within;
        for (int p = 0; p < mp.parts(); ++p) {
            if (has(p, n)) hits.push_back(p), within.push_back(n);
            const std::string pn = name_of(p);
            if (!pn.empty() && n.size() > pn.size() + 1 && n.compare(0, pn.size(), pn) == 0 && n[pn.size()] == '.' &&
                has(p, n.substr(pn.size() + 1)))
                hits.push_back(p), within.push_back(n.substr(pn.size() + 1));
        }
        if (hits.size() > 1) {
            std::string in;
            for (std::size_t h = 0; h < hits.size(); ++h)
                in += (h == 0 ? "part '" : ", part '") + part_name(hits[h]) + "': " + within[h];
            return "channel " + n + " is ambiguous (" + in + "): name its part, as PART.CHANNEL";
        }
        if (hits.empty()) {
            missing += (missing.empty() ? "" : ", ") + n;
            continue;
        }
        for (std::size_t k = 0; k < part.size(); ++k)
            if (part[k] == hits[0] && channel[k] == within[0])
                return "channels " + names[k] + " and " + n + " are one channel (part '" + part_name(hits[0]) + "': " +
                       within[0] + ")";
        part.push_back(hits[0]);
        channel.push_back(within[0]);
    }
    if (missing.empty()) return {};
    std::string have;
    for (int p = 0; p < mp.parts(); ++p) {
        if (!flat(p)) continue;  // (a deep part's samples are not read)
        have += (have.empty() ? "part '" : "; part '") + part_name(p) + "': " + exr_channel_list(mp.header(p));
    }
    return "missing channel(s) " + missing + " (the file has " + (have.empty() ? "no part but deep ones" : have) + ")";
}

// Refuses a part to be read whose pixels could not come from the file: a line of it holds
// every channel of the part, wanted or not, and the output every channel asked for, so each
// counts (exr_header_check saw only the first part's header).
inline std::string exr_part_plausible(const Imf::MultiPartInputFile& mp, int part, std::size_t wanted,
                                      std::uint64_t stream_bytes) {
    const Imf::Header& h = mp.header(part);
    const std::size_t channels = std::max(exr_channel_count(h), wanted);
    std::int64_t w = 0, ht = 0;
    if (exr_window_fits(h.dataWindow(), channels, stream_bytes, w, ht)) return {};
    const std::string name = h.hasName() ? h.name() : "#" + std::to_string(part);
    return "part '" + name + "' is too large for the file: " + std::to_string(w) + " x " + std::to_string(ht) +
           " pixels of " + std::to_string(channels) + " channels in " + std::to_string(stream_bytes) + " bytes";
}

// A multi-part file: each channel from the part exr_locate_channels finds; the parts read
// must share one data window.
inline std::string exr_read_multipart(Imf::IStream& in, std::uint64_t stream_bytes,
                                      const std::vector<std::string>& names, image& out) {
    Imf::MultiPartInputFile mp(in);
    std::vector<int> part;
    std::vector<std::string> channel;
    if (std::string e = exr_locate_channels(mp, names, part, channel); !e.empty()) return e;
    const Imf::Header& first = mp.header(part[0]);
    for (int p : part)
        if (mp.header(p).dataWindow() != first.dataWindow())
            return "the parts that hold " + names[0] + " and the other channels have different data windows";
    for (int p : part)
        if (std::string e = exr_part_plausible(mp, p, names.size(), stream_bytes); !e.empty()) return e;
    if (!exr_prepare(first.dataWindow(), first.displayWindow(), names, stream_bytes, out)) return "bad data window";
    for (std::size_t c = 0; c < names.size(); ++c) {
        if (std::find(part.begin(), part.begin() + static_cast<std::ptrdiff_t>(c), part[c]) != part.begin() + static_cast<std::ptrdiff_t>(c))
            continue;  // read with an earlier channel of its part
        std::vector<std::string> wanted(names.size());
        for (std::size_t k = c; k < names.size(); ++k)
            if (part[k] == part[c]) wanted[k] = channel[k];
        Imf::InputPart reader(mp, part[c]);
        if (std::string e = exr_read_part(reader, wanted, out); !e.empty()) return e;
    }
    return {};
}

// Reads the named channels (in that order) from an EXR stream of `stream_bytes` bytes; the
// function the file reader and the fuzz target share. `name` labels the messages. In a
// multi-part file a channel may come from any part (exr_locate_channels).
inline std::string read_exr(Imf::IStream& in, std::uint64_t stream_bytes, const std::string& name,
                            const std::vector<std::string>& names, image& out) {
    try {
        if (names.empty()) return name + ": no channel asked for";
        bool multipart = false;
        const std::string bad = exr_header_check(in, stream_bytes, names.size(), multipart);
        if (!bad.empty()) return name + (bad[0] == 'i' ? " " : ": ") + bad;
        // OpenEXR's own header checks also refuse huge windows and tiles.
        Imf::Header::setMaxImageSize(max_side, max_side);
        Imf::Header::setMaxTileSize(max_side, max_side);
        const std::string e = multipart ? exr_read_multipart(in, stream_bytes, names, out)
                                        : exr_read_single(in, stream_bytes, names, out);
        return e.empty() ? e : name + ": " + e;
    } catch (const std::bad_alloc&) {
        return name + ": out of memory";
    } catch (const std::exception& e) {
        return name + ": " + e.what();
    }
}

// An Imf::OStream over an open file descriptor (the exclusive temporary of an output).
class fd_ostream : public Imf::OStream {
public:
    fd_ostream(int fd, const std::string& name) : Imf::OStream(name.c_str()), fd_(fd) {}
    void write(const char c[], int n) override {
        while (n > 0) {
            const ssize_t k = ::write(fd_, c, static_cast<std::size_t>(n));
            if (k < 0 && errno == EINTR) continue;
            if (k <= 0) throw std::runtime_error(std::string("write failed: ") + fileName());
            c += k;
            n -= static_cast<int>(k);
        }
    }
    uint64_t tellp() override {
        const off_t p = ::lseek(fd_, 0, SEEK_CUR);
        if (p < 0) throw std::runtime_error(std::string("seek failed: ") + fileName());
        return static_cast<uint64_t>(p);
    }
    void seekp(uint64_t pos) override {
        if (::lseek(fd_, static_cast<off_t>(pos), SEEK_SET) < 0)
            throw std::runtime_error(std::string("seek failed: ") + fileName());
    }

private:
    int fd_;
};

inline Imath::Box2i box_of(const window& w, const Imath::Box2i& fallback) {
    return w.empty() ? fallback : Imath::Box2i({w.min_x, w.min_y}, {w.max_x, w.max_y});
}

// OpenEXR's core library writes the header, places the chunks and their offset table through
// these callbacks into an Imf::OStream; the first error is kept for the message.
struct exr_core_sink {
    Imf::OStream* os;
    std::string error;
    std::uint64_t end = 0;  // bytes written so far: the core writes the chunks past the
                            // offset table's place first and the table last
};

inline std::int64_t exr_core_write(exr_const_context_t, void* user, const void* buffer, std::uint64_t size,
                                   std::uint64_t offset, exr_stream_error_func_ptr_t) {
    auto* sink = static_cast<exr_core_sink*>(user);
    try {
        if (offset > sink->end) {  // a gap: zeros, since not every stream can seek past its end
            const std::vector<char> zeros(static_cast<std::size_t>(offset - sink->end), 0);
            sink->os->seekp(sink->end);
            sink->os->write(zeros.data(), static_cast<int>(zeros.size()));
            sink->end = offset;
        }
        if (sink->os->tellp() != offset) sink->os->seekp(offset);
        sink->end = std::max(sink->end, offset + size);
        const char* p = static_cast<const char*>(buffer);
        for (std::uint64_t left = size; left > 0;) {
            const int n = static_cast<int>(std::min<std::uint64_t>(left, std::uint64_t{1} << 30));
            sink->os->write(p, n);
            p += n;
            left -= static_cast<std::uint64_t>(n);
        }
        return static_cast<std::int64_t>(size);
    } catch (const std::exception& e) {
        if (sink->error.empty()) sink->error = e.what();
        return -1;
    }
}

// The sink of the write in progress on this thread: the core calls the handler with its
// context locked, so the handler must not ask the context for its user data (a deadlock).
inline exr_core_sink*& exr_current_sink() {
    thread_local exr_core_sink* sink = nullptr;
    return sink;
}

inline void exr_core_error(exr_const_context_t, exr_result_t code, const char* message) {
    exr_core_sink* sink = exr_current_sink();
    if (sink && sink->error.empty()) sink->error = message ? message : exr_get_default_error_message(code);
}

// The header of a float scanline file with ZIP compression and the image's channels (in name
// order, as EXR stores them); false (with the sink's message) when OpenEXR refuses it.
inline bool exr_core_header(exr_context_t ctxt, const image& img, const Imath::Box2i& dw,
                            const std::vector<std::string>& sorted) {
    const Imath::Box2i disp = box_of(img.display_window, dw);
    const exr_attr_box2i_t data_window{{dw.min.x, dw.min.y}, {dw.max.x, dw.max.y}};
    const exr_attr_box2i_t display_window{{disp.min.x, disp.min.y}, {disp.max.x, disp.max.y}};
    const exr_attr_v2f_t centre{0.0f, 0.0f};
    int part = 0;
    if (exr_set_longname_support(ctxt, 1) != EXR_ERR_SUCCESS) return false;  // names past 31 bytes, as Imf writes
    if (exr_add_part(ctxt, nullptr, EXR_STORAGE_SCANLINE, &part) != EXR_ERR_SUCCESS) return false;
    if (exr_initialize_required_attr(ctxt, part, &display_window, &data_window, 1.0f, &centre, 1.0f,
                                     EXR_LINEORDER_INCREASING_Y, EXR_COMPRESSION_ZIP) != EXR_ERR_SUCCESS)
        return false;
    for (const auto& n : sorted)
        if (exr_add_channel(ctxt, part, n.c_str(), EXR_PIXEL_FLOAT, EXR_PERCEPTUALLY_LOGARITHMIC, 1, 1) !=
            EXR_ERR_SUCCESS)
            return false;
    return exr_write_header(ctxt) == EXR_ERR_SUCCESS;
}

// The bytes of chunk k (ZIP: 16 lines) of `img`, its channels in the file's order: each line
// holds each channel's samples in turn.
inline void exr_gather_chunk(const image& img, const std::vector<std::size_t>& order, int y0, int lines,
                             std::vector<std::uint8_t>& raw) {
    const std::size_t nc = img.channels.size(), w = static_cast<std::size_t>(img.width);
    raw.resize(static_cast<std::size_t>(lines) * w * nc * 4);
    float* o = reinterpret_cast<float*>(raw.data());
    for (int j = 0; j < lines; ++j) {
        const float* row = img.pixels.data() + static_cast<std::size_t>(y0 + j) * w * nc;
        for (std::size_t c : order)
            for (std::size_t x = 0; x < w; ++x) *o++ = row[x * nc + c];
    }
    if (__BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__)  // EXR stores little-endian values
        for (std::size_t i = 0; i + 3 < raw.size(); i += 4) {
            std::swap(raw[i], raw[i + 3]);
            std::swap(raw[i + 1], raw[i + 2]);
        }
}

// Every chunk (ZIP: 16 lines) of `img`, packed on OpenEXR's thread pool a batch at a time
// (exr_zip.hpp) and handed to the core in order; false (with the sink's message) on failure.
inline bool exr_write_chunks(exr_context_t ctxt, const image& img, const std::vector<std::size_t>& order, int y_min,
                             exr_core_sink& sink) {
    const int lines = exr_zip::lines_zip;
    const std::size_t chunks = static_cast<std::size_t>((img.height + lines - 1) / lines);
    const std::size_t batch = 4 * exr_pool_threads();
    std::vector<std::vector<std::uint8_t>> packed(batch);
    std::vector<unsigned char> failed(batch, 0);
    for (std::size_t first = 0; first < chunks; first += batch) {
        const std::size_t count = std::min(batch, chunks - first);
        const bool ran = on_exr_pool(count, [&](std::size_t a, std::size_t b) {
            exr_zip::codec codec;
            std::vector<std::uint8_t> raw;
            for (std::size_t i = a; i < b; ++i) {
                const int y0 = static_cast<int>(first + i) * lines;
                exr_gather_chunk(img, order, y0, std::min(lines, img.height - y0), raw);
                failed[i] = !codec.pack(raw.data(), raw.size(), packed[i]);
            }
        });
        for (std::size_t i = 0; i < count; ++i) {
            if (!ran || failed[i]) {
                sink.error = "out of memory";
                return false;
            }
            if (exr_write_scanline_chunk(ctxt, 0, y_min + static_cast<int>(first + i) * lines, packed[i].data(),
                                         packed[i].size()) != EXR_ERR_SUCCESS)
                return false;
        }
    }
    return true;
}

// Writes all channels of `img` as 32-bit float EXR (ZIP compression) to a stream, through
// OpenEXR's core library (header, chunk placement, offset table) and exr_write_chunks.
inline std::string write_exr(Imf::OStream& os, const image& img) {
    const std::string name = os.fileName();
    const Imath::Box2i origin({0, 0}, {img.width - 1, img.height - 1});
    const Imath::Box2i dw = box_of(img.data_window, origin);
    if (img.width < 1 || img.height < 1 || std::int64_t{dw.max.x} - dw.min.x + 1 != img.width ||
        std::int64_t{dw.max.y} - dw.min.y + 1 != img.height)
        return name + ": the data window does not match the image size";
    std::vector<std::size_t> order(img.channels.size());
    for (std::size_t c = 0; c < order.size(); ++c) order[c] = c;
    std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return img.channels[a] < img.channels[b]; });
    std::vector<std::string> sorted;
    for (std::size_t c : order) sorted.push_back(img.channels[c]);
    if (sorted.empty() || std::adjacent_find(sorted.begin(), sorted.end()) != sorted.end())
        return name + ": no channels, or a channel name twice";
    exr_core_sink sink{&os, {}};
    struct current {  // the handler's sink while this write runs (nested writes keep theirs)
        exr_core_sink* before;
        explicit current(exr_core_sink* s) : before(exr_current_sink()) { exr_current_sink() = s; }
        ~current() { exr_current_sink() = before; }
    } in_use(&sink);
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.user_data = &sink;
    init.write_fn = exr_core_write;
    init.error_handler_fn = exr_core_error;
    exr_context_t ctxt = nullptr;
    if (exr_start_write(&ctxt, name.c_str(), EXR_WRITE_FILE_DIRECTLY, &init) != EXR_ERR_SUCCESS)
        return name + ": " + (sink.error.empty() ? "cannot start writing" : sink.error);
    bool ok = false;
    try {  // the context is finished whatever happens
        ok = exr_core_header(ctxt, img, dw, sorted) && exr_write_chunks(ctxt, img, order, dw.min.y, sink);
    } catch (const std::exception& e) {
        if (sink.error.empty()) sink.error = e.what();
    }
    const bool finished = exr_finish(&ctxt) == EXR_ERR_SUCCESS;
    if (ok && finished && sink.error.empty()) return {};
    return name + ": " + (sink.error.empty() ? "write failed" : sink.error);
}
#endif

// Reads the named channels (in that order) of an EXR file: a regular file, size known.
inline std::string read_exr(const std::string& path, const std::vector<std::string>& names, image& out) {
#ifdef FIREFLY_HAVE_OPENEXR
    try {
        std::uint64_t size = 0;
        if (std::string e = check_regular_input(path, &size); !e.empty()) return e;
        std::ifstream f(path, std::ios::binary);
        if (!f) return "cannot open " + path;
        Imf::StdIFStream in(f, path.c_str());
        return read_exr(in, size, path, names, out);
    } catch (const std::exception& e) {
        return path + ": " + e.what();
    }
#else
    (void)names;
    (void)out;
    return "cannot read " + path + ": built without OpenEXR (apt-get install libopenexr-dev)";
#endif
}

// Writes `img` to a file by name (the demo's outputs; the command-line tool writes through
// exclusive temporaries instead).
inline std::string write_exr(const std::string& path, const image& img) {
#ifdef FIREFLY_HAVE_OPENEXR
    try {
        Imf::StdOFStream os(path.c_str());
        return write_exr(os, img);
    } catch (const std::exception& e) {
        return path + ": " + e.what();
    }
#else
    (void)img;
    return "cannot write " + path + ": built without OpenEXR";
#endif
}

// An 8-bit sRGB preview of an RGB image (channels 0..2), exposure-scaled and clamped, to an
// open stdio stream (`name` labels the messages).
inline std::string write_png_preview(std::FILE* f, const std::string& name, const float* rgb, int width, int height,
                                     std::size_t stride_channels = 3, float exposure = 1.0f) {
#ifdef FIREFLY_HAVE_PNG
    std::vector<unsigned char> px(static_cast<std::size_t>(width) * static_cast<std::size_t>(height) * 3);
    for (std::size_t i = 0; i < static_cast<std::size_t>(width) * static_cast<std::size_t>(height); ++i)
        for (std::size_t c = 0; c < 3; ++c) {
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
    if (!png_image_write_to_stdio(&im, f, 0, px.data(), 0, nullptr)) return name + ": " + im.message;
    return {};
#else
    (void)f;
    (void)rgb;
    (void)width;
    (void)height;
    (void)stride_channels;
    (void)exposure;
    return name + " skipped: built without libpng (apt-get install libpng-dev)";
#endif
}

inline std::string write_png_preview(const std::string& path, const float* rgb, int width, int height,
                                     std::size_t stride_channels = 3, float exposure = 1.0f) {
    std::FILE* f = std::fopen(path.c_str(), "wb");
    if (!f) return "cannot write " + path;
    std::string e = write_png_preview(f, path, rgb, width, height, stride_channels, exposure);
    if (std::fclose(f) != 0 && e.empty()) e = "write failed: " + path;
    return e;
}

}  // namespace firefly_tools
