// The tools' EXR reading and writing (examples/image_io.hpp, examples/exr_zip.hpp): chunks
// packed and unpacked by the tools themselves must be the chunks OpenEXR writes and reads.
// Every file here is checked against OpenEXR's own FrameBuffer reader and writer.
#include <catch2/catch.hpp>

#include <OpenEXR/ImfMultiPartOutputFile.h>
#include <OpenEXR/ImfOutputPart.h>
#include <OpenEXR/ImfPartType.h>
#include <OpenEXR/ImfStdIO.h>
#include <OpenEXR/ImfTiledOutputPart.h>

#include <dirent.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <new>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "half_float.hpp"
#include "image_io.hpp"

namespace {

using firefly_tools::image;
namespace zip = firefly_tools::exr_zip;

// OpenEXR's own transform, written as the format describes it (two pointers, then the
// predictor in place), to check exr_zip's against.
std::vector<std::uint8_t> reference_forward(const std::vector<std::uint8_t>& in) {
    std::vector<std::uint8_t> t(in.size());
    std::size_t a = 0, b = (in.size() + 1) / 2;
    for (std::size_t i = 0; i < in.size(); ++i) t[i % 2 == 0 ? a++ : b++] = in[i];
    for (std::size_t i = t.size(); i-- > 1;) t[i] = static_cast<std::uint8_t>(t[i] - t[i - 1] + 128);
    return t;
}

std::vector<std::uint8_t> random_bytes(std::size_t n, unsigned seed, int spread = 256) {
    std::mt19937 rng(seed);
    std::vector<std::uint8_t> v(n);
    for (auto& x : v) x = static_cast<std::uint8_t>(rng() % static_cast<unsigned>(spread));
    return v;
}

// Writes an image through OpenEXR's FrameBuffer interface (its own compressor), channels of
// the given types, into a string.
std::string imf_write(const image& img, Imf::Compression compression, const std::vector<Imf::PixelType>& types) {
    Imf::StdOSStream os;
    const Imath::Box2i dw({img.data_window.min_x, img.data_window.min_y}, {img.data_window.max_x, img.data_window.max_y});
    Imf::Header header(dw, dw);
    header.compression() = compression;
    for (std::size_t c = 0; c < img.channels.size(); ++c) header.channels().insert(img.channels[c], Imf::Channel(types[c]));
    const std::size_t nc = img.channels.size(), w = static_cast<std::size_t>(img.width);
    std::vector<std::vector<char>> planes(nc);
    Imf::FrameBuffer fb;
    for (std::size_t c = 0; c < nc; ++c) {
        const std::size_t bytes = types[c] == Imf::HALF ? 2 : 4;
        planes[c].resize(img.pixels.size() / nc * bytes);
        for (std::size_t i = 0; i < img.pixels.size() / nc; ++i) {
            const float v = img.pixels[i * nc + c];
            if (types[c] == Imf::HALF) {
                const Imath::half h(v);
                const std::uint16_t bits = h.bits();
                std::memcpy(&planes[c][i * 2], &bits, 2);
            } else if (types[c] == Imf::UINT) {
                const auto u = static_cast<std::uint32_t>(std::isfinite(v) ? std::fmin(std::fabs(v), 1e6f) * 1000.0f : 7.0f);
                std::memcpy(&planes[c][i * 4], &u, 4);
            } else {
                std::memcpy(&planes[c][i * 4], &v, 4);
            }
        }
        fb.insert(img.channels[c], Imf::Slice::Make(types[c], planes[c].data(), dw, bytes, bytes * w));
    }
    Imf::OutputFile file(os, header);
    file.setFrameBuffer(fb);
    file.writePixels(img.height);
    return os.str();
}

// Reads named channels as float through OpenEXR's FrameBuffer interface.
std::vector<float> imf_read(const std::string& bytes, const std::vector<std::string>& names) {
    Imf::StdISStream is;
    is.str(bytes);
    Imf::InputFile file(is);
    const Imath::Box2i dw = file.header().dataWindow();
    const std::size_t w = static_cast<std::size_t>(dw.max.x - dw.min.x + 1), h = static_cast<std::size_t>(dw.max.y - dw.min.y + 1);
    const std::size_t nc = names.size();
    std::vector<float> px(w * h * nc, -1.0f);
    Imf::FrameBuffer fb;
    for (std::size_t c = 0; c < nc; ++c)
        fb.insert(names[c], Imf::Slice::Make(Imf::FLOAT, px.data() + c, dw, nc * 4, nc * 4 * w));
    file.setFrameBuffer(fb);
    file.readPixels(dw.min.y, dw.max.y);
    return px;
}

std::string tools_read(const std::string& bytes, const std::vector<std::string>& names, image& out) {
    Imf::StdISStream is;
    is.str(bytes);
    return firefly_tools::read_exr(is, bytes.size(), "test.exr", names, out);
}

std::string tools_write(const image& img, std::string& bytes) {
    Imf::StdOSStream os;
    const std::string e = firefly_tools::write_exr(os, img);
    bytes = os.str();
    return e;
}

// A w x h image of the named channels, data window at (x0, y0): smooth values with noise in
// the low bits (so ZIP finds some structure but not all), a few special values.
image test_image(int w, int h, int x0, int y0, const std::vector<std::string>& names, unsigned seed) {
    image img;
    img.width = w;
    img.height = h;
    img.channels = names;
    img.data_window = {x0, y0, x0 + w - 1, y0 + h - 1};
    img.display_window = img.data_window;
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    img.pixels.resize(static_cast<std::size_t>(w) * h * names.size());
    for (std::size_t i = 0; i < img.pixels.size(); ++i) img.pixels[i] = 0.25f + 0.5f * static_cast<float>(i % 97) / 97.0f + 0.01f * u(rng);
    if (img.pixels.size() > 5) {
        img.pixels[0] = 0.0f;
        img.pixels[1] = -3.5f;
        img.pixels[2] = 1e30f;
        img.pixels[3] = 1e-40f;  // denormal
        img.pixels[4] = std::numeric_limits<float>::infinity();
    }
    return img;
}

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
    return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

// One part of a multi-part file: its name, channels (all of one type), window, tiled or not.
struct part_spec {
    std::string name;
    image img;
    Imf::PixelType type;
    Imf::Compression compression;
    bool tiled;
};

// Writes the parts through OpenEXR's MultiPartOutputFile into a string; the display window
// (one for the whole file) is the first part's data window.
std::string imf_write_parts(const std::vector<part_spec>& parts) {
    std::vector<Imf::Header> headers;
    auto box = [](const image& img) {
        return Imath::Box2i({img.data_window.min_x, img.data_window.min_y}, {img.data_window.max_x, img.data_window.max_y});
    };
    for (const auto& p : parts) {
        Imf::Header h(box(parts[0].img), box(p.img));
        h.setName(p.name);
        h.compression() = p.compression;
        h.setType(p.tiled ? Imf::TILEDIMAGE : Imf::SCANLINEIMAGE);
        if (p.tiled) h.setTileDescription(Imf::TileDescription(8, 8, Imf::ONE_LEVEL));
        for (const auto& n : p.img.channels) h.channels().insert(n, Imf::Channel(p.type));
        headers.push_back(h);
    }
    Imf::StdOSStream os;
    Imf::MultiPartOutputFile file(os, headers.data(), static_cast<int>(headers.size()));
    for (std::size_t k = 0; k < parts.size(); ++k) {
        const image& img = parts[k].img;
        const Imath::Box2i dw = headers[k].dataWindow();
        const std::size_t nc = img.channels.size(), w = static_cast<std::size_t>(img.width), n = img.pixels.size() / nc;
        std::vector<std::vector<Imath::half>> halves(nc, std::vector<Imath::half>(n));
        Imf::FrameBuffer fb;
        for (std::size_t c = 0; c < nc; ++c) {
            if (parts[k].type == Imf::HALF) {
                for (std::size_t i = 0; i < n; ++i) halves[c][i] = Imath::half(img.pixels[i * nc + c]);
                fb.insert(img.channels[c], Imf::Slice::Make(Imf::HALF, halves[c].data(), dw, 2, 2 * w));
            } else {
                fb.insert(img.channels[c], Imf::Slice::Make(Imf::FLOAT, img.pixels.data() + c, dw, nc * 4, nc * 4 * w));
            }
        }
        if (parts[k].tiled) {
            Imf::TiledOutputPart out(file, static_cast<int>(k));
            out.setFrameBuffer(fb);
            out.writeTiles(0, out.numXTiles() - 1, 0, out.numYTiles() - 1);
        } else {
            Imf::OutputPart out(file, static_cast<int>(k));
            out.setFrameBuffer(fb);
            out.writePixels(img.height);
        }
    }
    return os.str();
}

// A temporary folder, removed with what it holds (no subfolders) when the test ends.
struct temp_dir {
    std::string path;
    temp_dir() {
        const char* tmp = std::getenv("TMPDIR");
        path = std::string(tmp ? tmp : "/tmp") + "/firefly-exr-XXXXXX";
        if (!::mkdtemp(&path[0])) path.clear();
    }
    ~temp_dir() {
        if (DIR* d = path.empty() ? nullptr : ::opendir(path.c_str())) {
            while (const dirent* e = ::readdir(d))
                if (std::strcmp(e->d_name, ".") != 0 && std::strcmp(e->d_name, "..") != 0)
                    ::unlink((path + "/" + e->d_name).c_str());
            ::closedir(d);
            ::rmdir(path.c_str());
        }
    }
};

// A two-part file of a few KB through OpenEXR's core writer: part 'a', one half channel at
// one pixel; part 'b', R, G, B and `extra` more half channels over 65536 x 16 pixels in one
// ZIP chunk of a few bytes. A line of 'b' holds all of its channels: with 1000 extra, the
// chunk claims 2.1 GB unpacked.
bool write_many_channels(const std::string& path, int extra) {
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    exr_context_t ctxt = nullptr;
    if (exr_start_write(&ctxt, path.c_str(), EXR_WRITE_FILE_DIRECTLY, &init) != EXR_ERR_SUCCESS) return false;
    int a = 0, b = 0;
    exr_attr_box2i_t display{}, data{};  // one display window for all parts, (0, 0)
    data.max.x = 65535;
    data.max.y = 15;
    const exr_attr_v2f_t centre{};
    bool ok = exr_add_part(ctxt, "a", EXR_STORAGE_SCANLINE, &a) == EXR_ERR_SUCCESS &&
              exr_initialize_required_attr_simple(ctxt, a, 1, 1, EXR_COMPRESSION_NONE) == EXR_ERR_SUCCESS &&
              exr_add_channel(ctxt, a, "Z", EXR_PIXEL_HALF, EXR_PERCEPTUALLY_LOGARITHMIC, 1, 1) == EXR_ERR_SUCCESS &&
              exr_add_part(ctxt, "b", EXR_STORAGE_SCANLINE, &b) == EXR_ERR_SUCCESS &&
              exr_initialize_required_attr(ctxt, b, &display, &data, 1.0f, &centre, 1.0f, EXR_LINEORDER_INCREASING_Y,
                                           EXR_COMPRESSION_ZIP) == EXR_ERR_SUCCESS;
    std::vector<std::string> names{"B", "G", "R"};
    for (int i = 0; i < extra; ++i) names.push_back("x" + std::to_string(10000 + i));
    for (const auto& n : names)
        ok = ok && exr_add_channel(ctxt, b, n.c_str(), EXR_PIXEL_HALF, EXR_PERCEPTUALLY_LOGARITHMIC, 1, 1) == EXR_ERR_SUCCESS;
    const std::vector<std::uint8_t> zeros(64, 0);
    std::vector<std::uint8_t> packed;  // a zlib stream of 64 bytes: shorter than the chunk claims
    zip::codec codec;
    ok = ok && codec.pack(zeros.data(), zeros.size(), packed) && packed.size() < zeros.size() &&
         exr_write_header(ctxt) == EXR_ERR_SUCCESS &&
         exr_write_scanline_chunk(ctxt, a, 0, zeros.data(), 2) == EXR_ERR_SUCCESS &&
         exr_write_scanline_chunk(ctxt, b, 0, packed.data(), packed.size()) == EXR_ERR_SUCCESS;
    return exr_finish(&ctxt) == EXR_ERR_SUCCESS && ok;
}

// Channel c of an image, as float (half-rounded when the part stores half).
std::vector<float> channel_of(const image& img, std::size_t c, bool half) {
    std::vector<float> v;
    for (std::size_t i = c; i < img.pixels.size(); i += img.channels.size())
        v.push_back(half ? static_cast<float>(Imath::half(img.pixels[i])) : img.pixels[i]);
    return v;
}

}  // namespace

TEST_CASE("exr_zip: the transform is OpenEXR's and inverts exactly", "[exr_io]") {
    for (std::size_t n : {0u, 1u, 2u, 3u, 15u, 16u, 17u, 31u, 32u, 33u, 34u, 48u, 1000u, 1001u, 100003u}) {
        const auto raw = random_bytes(n, static_cast<unsigned>(n));
        std::vector<std::uint8_t> t(n), back(n);
        zip::forward_transform(raw.data(), n, t.data());
        CHECK(t == reference_forward(raw));
        zip::inverse_transform(t.data(), n, back.data());
        CHECK(back == raw);
    }
}

TEST_CASE("exr_zip: chunks round-trip; incompressible ones are stored as they are", "[exr_io]") {
    zip::codec codec;
    for (int spread : {2, 256}) {  // compressible, incompressible
        const auto raw = random_bytes(24000, 7, spread);
        std::vector<std::uint8_t> packed, back(raw.size());
        REQUIRE(codec.pack(raw.data(), raw.size(), packed));
        if (spread == 256) {
            CHECK(packed == raw);
        } else {
            CHECK(packed.size() < raw.size() / 2);
        }
        REQUIRE(codec.unpack(packed.data(), packed.size(), back.data(), back.size()));
        CHECK(back == raw);
    }
    const auto raw = random_bytes(1, 3);
    std::vector<std::uint8_t> packed, back(1);
    REQUIRE(codec.pack(raw.data(), 1, packed));
    CHECK(packed == raw);
}

TEST_CASE("exr_zip: streams that are not exactly the chunk are refused", "[exr_io]") {
    zip::codec codec;
    const auto raw = random_bytes(5000, 11, 4);
    std::vector<std::uint8_t> packed;
    REQUIRE(codec.pack(raw.data(), raw.size(), packed));
    REQUIRE(packed.size() < raw.size());
    std::vector<std::uint8_t> back(raw.size() + 1);
    CHECK_FALSE(codec.unpack(packed.data(), packed.size(), back.data(), raw.size() - 1));  // too short an output
    CHECK_FALSE(codec.unpack(packed.data(), packed.size(), back.data(), raw.size() + 1));  // the stream ends early
    CHECK_FALSE(codec.unpack(packed.data(), packed.size() - 3, back.data(), raw.size()));  // truncated
    auto flipped = packed;
    flipped[flipped.size() / 2] ^= 0x5a;
    CHECK_FALSE(codec.unpack(flipped.data(), flipped.size(), back.data(), raw.size()));  // checksum
    REQUIRE(codec.unpack(raw.data(), raw.size(), back.data(), 10));  // stored in more bytes than it holds:
    CHECK(std::equal(raw.begin(), raw.begin() + 10, back.begin()));   // as it is, as OpenEXR reads it
}

TEST_CASE("write_exr: OpenEXR reads back the same bits, with any thread count", "[exr_io]") {
    const std::vector<std::string> names{"R", "G", "B", "Variance.R", "Variance.G", "Variance.B", "A"};
    for (const auto& size : std::vector<std::pair<int, int>>{{1, 1}, {37, 16}, {37, 17}, {64, 33}, {3, 100}}) {
        const image img = test_image(size.first, size.second, -5, 7, names, 3);
        std::string one, two;
        firefly_tools::set_exr_threads(0);
        REQUIRE(tools_write(img, one).empty());
        firefly_tools::set_exr_threads(2);
        REQUIRE(tools_write(img, two).empty());
        firefly_tools::set_exr_threads(0);
        CHECK(one == two);
        CHECK(same_bits(imf_read(one, names), img.pixels));
        image back;
        REQUIRE(tools_read(one, names, back).empty());
        CHECK(same_bits(back.pixels, img.pixels));
        CHECK(back.data_window.min_x == -5);
        CHECK(back.data_window.max_y == 7 + size.second - 1);
    }
}

TEST_CASE("write_exr: refuses what cannot be written, with a message", "[exr_io]") {
    image img = test_image(4, 4, 0, 0, {"R", "G"}, 1);
    std::string bytes;
    img.channels = {"R", "R"};
    CHECK_FALSE(tools_write(img, bytes).empty());
    img = test_image(4, 4, 0, 0, {"R"}, 1);
    img.data_window = {0, 0, 9, 9};
    CHECK_FALSE(tools_write(img, bytes).empty());
}

TEST_CASE("read_exr: files OpenEXR wrote read as OpenEXR reads them, in every compression", "[exr_io]") {
    const std::vector<std::string> in_file{"A", "B", "G", "R", "Variance", "Z"};
    const std::vector<Imf::PixelType> types{Imf::HALF, Imf::FLOAT, Imf::HALF, Imf::FLOAT, Imf::UINT, Imf::FLOAT};
    const std::vector<std::string> wanted{"R", "G", "B", "Variance", "A"};  // Z read and skipped
    for (Imf::Compression c : {Imf::ZIP_COMPRESSION, Imf::ZIPS_COMPRESSION, Imf::NO_COMPRESSION, Imf::PIZ_COMPRESSION,
                               Imf::RLE_COMPRESSION}) {
        for (const auto& size : std::vector<std::pair<int, int>>{{1, 1}, {33, 16}, {33, 35}}) {
            const image img = test_image(size.first, size.second, 3, -9, in_file, 5);
            const std::string bytes = imf_write(img, c, types);
            for (unsigned threads : {0u, 2u}) {
                firefly_tools::set_exr_threads(threads);
                image back;
                REQUIRE(tools_read(bytes, wanted, back).empty());
                CHECK(same_bits(back.pixels, imf_read(bytes, wanted)));
            }
            firefly_tools::set_exr_threads(0);
        }
    }
}

TEST_CASE("read_exr: a damaged chunk is an error naming its line, never a crash", "[exr_io]") {
    const std::vector<std::string> names{"B", "G", "R"};
    image img = test_image(40, 40, 0, 0, names, 9);
    for (std::size_t i = 0; i < img.pixels.size(); ++i) img.pixels[i] = static_cast<float>(i % 40) * 0.25f;  // compresses
    std::string good;
    REQUIRE(tools_write(img, good).empty());
    REQUIRE(good.size() < img.pixels.size());  // the chunks are zlib streams, not stored as they are
    image back;
    REQUIRE(tools_read(good, names, back).empty());
    // The last chunk's stored bytes sit at the end of the file: damage its middle.
    std::string bad = good;
    bad[bad.size() - 10] = static_cast<char>(bad[bad.size() - 10] ^ 0x77);
    const std::string e = tools_read(bad, names, back);
    CHECK_FALSE(e.empty());
    CHECK(e.find("test.exr") != std::string::npos);
}

TEST_CASE("on_exr_pool: a band that throws is reported, never a hang or a terminate", "[exr_io]") {
    for (unsigned threads : {0u, 2u}) {
        firefly_tools::set_exr_threads(threads);
        std::vector<int> seen(100, 0);
        CHECK(firefly_tools::on_exr_pool(seen.size(), [&](std::size_t a, std::size_t b) {
            for (std::size_t i = a; i < b; ++i) seen[i] = 1;
        }));
        CHECK(std::count(seen.begin(), seen.end(), 1) == 100);
        CHECK_FALSE(firefly_tools::on_exr_pool(100, [&](std::size_t a, std::size_t) {
            if (a == 0) throw std::bad_alloc();
        }));
    }
    firefly_tools::set_exr_threads(0);
}

TEST_CASE("write_exr: long channel names are written; names and windows OpenEXR refuses give a message", "[exr_io]") {
    const std::string long_name = "a.channel.name.longer.than.thirty.one.bytes";
    const image img = test_image(5, 3, 0, 0, {long_name, "R"}, 2);
    std::string bytes;
    REQUIRE(tools_write(img, bytes).empty());
    CHECK(same_bits(imf_read(bytes, {long_name, "R"}), img.pixels));
    image unnamed = test_image(5, 3, 0, 0, {"", "R"}, 2);
    CHECK_FALSE(tools_write(unnamed, bytes).empty());  // the core's error handler ran: no deadlock
    image far = test_image(5, 3, 0, 0, {"R"}, 2);
    far.data_window = {1073741820, 0, 1073741824, 2};
    far.display_window = far.data_window;
    CHECK_FALSE(tools_write(far, bytes).empty());
}

TEST_CASE("write_exr then read_exr: any size, channel set, window and bit pattern round-trips", "[exr_io][property]") {
    std::mt19937 rng(20261203);
    auto pick = [&](int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng); };
    for (int round = 0; round < 60; ++round) {
        const int w = pick(1, 70), h = pick(1, 40), nc = pick(1, 8);
        std::vector<std::string> names;
        for (int c = 0; c < nc; ++c) names.push_back(std::string(1, static_cast<char>('A' + pick(0, 25))) + std::to_string(c));
        image img = test_image(w, h, pick(-100, 100), pick(-100, 100), names, static_cast<unsigned>(round));
        for (float& v : img.pixels) {  // raw bit patterns among the values: NaN payloads, Inf, denormals
            if (pick(0, 9) == 0) {
                const std::uint32_t bits = static_cast<std::uint32_t>(rng());
                std::memcpy(&v, &bits, 4);
            }
        }
        const unsigned threads = static_cast<unsigned>(pick(0, 3));
        firefly_tools::set_exr_threads(threads);
        std::string bytes;
        REQUIRE(tools_write(img, bytes).empty());
        CHECK(same_bits(imf_read(bytes, names), img.pixels));
        image back;
        REQUIRE(tools_read(bytes, names, back).empty());
        CHECK(same_bits(back.pixels, img.pixels));
        CHECK((back.data_window.min_x == img.data_window.min_x && back.data_window.max_y == img.data_window.max_y));
    }
    firefly_tools::set_exr_threads(0);
}

TEST_CASE("read_exr: a multi-part file's channels come from the part that holds them", "[exr_io]") {
    // A renderer's AOVs as parts: the colour (float, ZIP) with alpha, the variance under the
    // same names (half, tiled, PIZ), and a one-channel variance (no compression).
    const image beauty = test_image(21, 19, -4, 7, {"A", "B", "G", "R"}, 11);
    const image variance = test_image(21, 19, -4, 7, {"B", "G", "R"}, 12);
    const image mean_var = test_image(21, 19, -4, 7, {"Variance"}, 13);
    const std::string bytes = imf_write_parts({{"beauty", beauty, Imf::FLOAT, Imf::ZIP_COMPRESSION, false},
                                               {"variance", variance, Imf::HALF, Imf::PIZ_COMPRESSION, true},
                                               {"mean", mean_var, Imf::FLOAT, Imf::NO_COMPRESSION, false}});
    for (unsigned threads : {0u, 2u}) {
        firefly_tools::set_exr_threads(threads);
        image back;
        // Names shared by two parts are given with the part's name.
        const std::vector<std::string> qualified{"beauty.R", "beauty.G", "beauty.B", "beauty.A", "variance.R",
                                                 "variance.G", "variance.B"};
        REQUIRE(tools_read(bytes, qualified, back).empty());
        CHECK(back.width == 21);
        CHECK(back.height == 19);
        CHECK(back.data_window.min_x == -4);
        CHECK(back.data_window.min_y == 7);
        CHECK(back.channels == qualified);
        const std::size_t from_beauty[] = {3, 2, 1, 0}, from_variance[] = {2, 1, 0};
        for (std::size_t c = 0; c < 4; ++c) CHECK(same_bits(channel_of(back, c, false), channel_of(beauty, from_beauty[c], false)));
        for (std::size_t c = 0; c < 3; ++c)
            CHECK(same_bits(channel_of(back, 4 + c, false), channel_of(variance, from_variance[c], true)));
        // A name only one part holds needs no part name.
        REQUIRE(tools_read(bytes, {"Variance", "beauty.G"}, back).empty());
        CHECK(same_bits(channel_of(back, 0, false), channel_of(mean_var, 0, false)));
        CHECK(same_bits(channel_of(back, 1, false), channel_of(beauty, 2, false)));
        REQUIRE(tools_read(bytes, {"A"}, back).empty());
        CHECK(same_bits(channel_of(back, 0, false), channel_of(beauty, 0, false)));
    }
    firefly_tools::set_exr_threads(0);
    image back;
    std::string e = tools_read(bytes, {"R", "G", "B"}, back);
    CHECK(e.find("channel R is ambiguous (part 'beauty': R, part 'variance': R): name its part, as PART.CHANNEL") !=
          std::string::npos);
    // Two names that read one channel are refused (one of them was left at 0).
    e = tools_read(bytes, {"beauty.G", "Variance", "mean.Variance"}, back);
    CHECK(e.find("channels Variance and mean.Variance are one channel (part 'mean': Variance)") != std::string::npos);
    CHECK(tools_read(bytes, {}, back).find("no channel asked for") != std::string::npos);
    e = tools_read(bytes, {"beauty.R", "Z"}, back);
    CHECK(e.find("missing channel(s) Z") != std::string::npos);
    CHECK(e.find("part 'beauty': A, B, G, R; part 'variance': B, G, R; part 'mean': Variance") != std::string::npos);
    e = tools_read(bytes, {"beauty.R", "nothing.R"}, back);
    CHECK(e.find("missing channel(s) nothing.R") != std::string::npos);
}

TEST_CASE("read_exr: a name read two ways in a multi-part file is refused, never guessed", "[exr_io]") {
    // Part 'a' holds b.R and part 'a.b' holds R: a.b.R reads either. Part 'beauty' holds R and
    // part 'other' holds a channel named beauty.R: beauty.R reads either. Both were read from
    // the first part that matched.
    const image ab = test_image(4, 4, 0, 0, {"b.R"}, 1), abr = test_image(4, 4, 0, 0, {"R"}, 2);
    const std::string dotted = imf_write_parts({{"a", ab, Imf::FLOAT, Imf::ZIP_COMPRESSION, false},
                                                {"a.b", abr, Imf::FLOAT, Imf::ZIP_COMPRESSION, false}});
    image back;
    CHECK(tools_read(dotted, {"a.b.R"}, back).find("channel a.b.R is ambiguous (part 'a': b.R, part 'a.b': R)") !=
          std::string::npos);
    const image beauty = test_image(4, 4, 0, 0, {"R"}, 3), other = test_image(4, 4, 0, 0, {"beauty.R"}, 4);
    const std::string shadow = imf_write_parts({{"beauty", beauty, Imf::FLOAT, Imf::ZIP_COMPRESSION, false},
                                                {"other", other, Imf::FLOAT, Imf::ZIP_COMPRESSION, false}});
    CHECK(tools_read(shadow, {"beauty.R"}, back).find("ambiguous") != std::string::npos);
    REQUIRE(tools_read(shadow, {"other.beauty.R"}, back).empty());  // the part named: one reading
    CHECK(same_bits(back.pixels, other.pixels));
}

TEST_CASE("read_exr: channels from parts with different windows are refused", "[exr_io]") {
    const image beauty = test_image(8, 8, 0, 0, {"B", "G", "R"}, 1);
    const image shifted = test_image(8, 8, 1, 0, {"Variance"}, 2);
    const std::string bytes = imf_write_parts({{"beauty", beauty, Imf::FLOAT, Imf::ZIP_COMPRESSION, false},
                                               {"variance", shifted, Imf::FLOAT, Imf::ZIP_COMPRESSION, false}});
    image back;
    CHECK(tools_read(bytes, {"R", "G", "B", "Variance"}, back).find("different data windows") != std::string::npos);
    REQUIRE(tools_read(bytes, {"Variance"}, back).empty());  // one part alone: its own window
    CHECK(back.data_window.min_x == 1);
}

TEST_CASE("read_exr, read_pfm: a pipe is refused before it is opened, never waited on", "[exr_io]") {
    // opening a pipe for reading waits for a writer: a reader that opened it would hang here
    // (and the test time out)
    const char* tmp = std::getenv("TMPDIR");
    std::string dir = std::string(tmp ? tmp : "/tmp") + "/firefly-pipe-XXXXXX";
    REQUIRE(::mkdtemp(&dir[0]) != nullptr);
    const std::string pipe = dir + "/pipe";
    REQUIRE(::mkfifo(pipe.c_str(), 0600) == 0);
    image img;
    CHECK(firefly_tools::read_exr(pipe, {"R"}, img) == pipe + " is not a regular file");
    firefly_tools::pfm_image pfm;
    CHECK(firefly_tools::read_pfm(pipe, pfm) == pipe + " is not a regular file");
    CHECK(firefly_tools::read_pfm(dir + "/none", pfm) == "cannot open " + dir + "/none");
    ::unlink(pipe.c_str());
    ::rmdir(dir.c_str());
}

TEST_CASE("read_exr: a part whose lines claim more than the file holds is refused before any allocation", "[exr_io]") {
    // Part 'a' passes the first header's check; the channels come from part 'b', whose lines
    // count its 1003 channels, not the 3 asked for.
    temp_dir dir;
    REQUIRE_FALSE(dir.path.empty());
    const std::string path = dir.path + "/many_channels.exr";
    REQUIRE(write_many_channels(path, 1000));
    struct stat st {};
    REQUIRE(::stat(path.c_str(), &st) == 0);
    REQUIRE(st.st_size < 64 * 1024);
    image back;
    const std::string e = firefly_tools::read_exr(path, {"R", "G", "B"}, back);
    CHECK(e == path + ": part 'b' is too large for the file: 65536 x 16 pixels of 1003 channels in " +
                   std::to_string(st.st_size) + " bytes");
    CHECK(back.pixels.empty());
}

namespace {
std::uint32_t bits_of(float f) {
    std::uint32_t u;
    std::memcpy(&u, &f, 4);
    return u;
}
float float_of(std::uint32_t u) {
    float f;
    std::memcpy(&f, &u, 4);
    return f;
}

// float -> half against Imath::half. Imath built with F16C quiets a signalling NaN, its
// software path keeps it: either is taken.
bool same_half(std::uint32_t u) {
    const float f = float_of(u);
    const std::uint16_t ours = firefly_examples::to_half(f).bits, ref = Imath::half(f).bits();
    return ours == ref || (std::isnan(f) && (ours | 0x0200u) == ref);
}

// Floats around every rounding point of half: for exponents in half's range, each half step
// (the kept bits k) with the dropped bits at 0, 1, just below, at and above the tie, and all
// ones. `d` is how many of the 24 significand bits half drops.
std::vector<std::uint32_t> rounding_points() {
    std::vector<std::uint32_t> v;
    for (std::uint32_t e = 101; e <= 143; ++e) {
        const int d = e >= 113 ? 13 : std::min(126 - static_cast<int>(e), 24);
        const std::uint32_t tie = 1u << (d - 1), full = (tie << 1) - 1u;
        for (std::uint32_t k = 0x800000u >> d; k <= 0xffffffu >> d; ++k)
            for (std::uint32_t low : {0u, 1u, tie - 1u, tie, tie + 1u, full}) {
                const std::uint32_t s = (k << d) + low;
                if (s >= 0x800000u && s <= 0xffffffu) v.push_back(e << 23 | (s & 0x7fffffu));
            }
    }
    return v;
}
}  // namespace

TEST_CASE("half16: float -> half is Imath::half's, rounding, subnormals and NaN included", "[exr_io][half]") {
    using firefly_examples::half16;
    std::vector<std::uint32_t> floats = rounding_points();
    for (std::uint32_t e = 0; e < 256; ++e)  // every exponent (float subnormals, Inf and NaN too),
        for (std::uint32_t m = 0; m < 0x800000u; m += 4093)  // the mantissa stepped
            for (std::uint32_t low : {0u, 1u, 0x3fu})
                floats.push_back(e << 23 | std::min(m + low, 0x7fffffu));
    for (std::uint32_t m : {1u, 0x1fffu, 0x2000u, 0x2001u, 0x3fffffu, 0x400000u, 0x400001u, 0x7fffffu})
        floats.push_back(0x7f800000u | m);  // NaN payloads, signalling and quiet
    floats.push_back(0x7f800000u);          // Inf
    floats.push_back(0);
    for (float f : {6.1e-5f, 6.1035156e-05f, 5.96e-8f, 2.98e-8f, 3e-8f, 1e-7f, 65504.0f, 65519.99f, 65520.0f, 1e9f})
        floats.push_back(bits_of(f));
    std::size_t bad = 0;
    std::uint32_t first_bad = 0;
    for (std::uint32_t u : floats)
        for (std::uint32_t sign : {0u, 0x80000000u})
            if (!same_half(u | sign) && bad++ == 0) first_bad = u | sign;
    INFO("floats checked: " << 2 * floats.size() << ", first mismatch: 0x" << std::hex << first_bad);
    CHECK(bad == 0);
    CHECK(firefly_examples::to_half(6.1e-5f).bits == 0x03ffu);  // the largest subnormal, not 0
    CHECK(std::isnan(firefly_examples::to_float(firefly_examples::to_half(-std::nanf("")))));
    CHECK(std::signbit(firefly_examples::to_float(firefly_examples::to_half(-std::nanf("")))));
    // every half reads as Imath reads it and stores back to its own bits
    std::size_t round_trip = 0, reads = 0;
    for (std::uint32_t b = 0; b < 65536; ++b) {
        const half16 h{static_cast<std::uint16_t>(b)};
        Imath::half ref;
        ref.setBits(static_cast<unsigned short>(b));
        reads += bits_of(firefly_examples::to_float(h)) != bits_of(static_cast<float>(ref));
        round_trip += firefly_examples::to_half(firefly_examples::to_float(h)).bits != b;
    }
    CHECK(reads == 0);
    CHECK(round_trip == 0);
}
