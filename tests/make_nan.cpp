// Test files for the command-line checks (tests/cli_check.cmake):
//   make_nan OUT.pfm                      a 16x8 PFM whose every value is NaN
//   make_nan fill OUT.pfm W H C VALUE     a W x H PFM of C channels (1 or 3), all VALUE
//                                         (a number, or "max" for FLT_MAX)
//   make_nan shift IN.exr OUT.exr X Y     IN's channels with the data window moved to
//                                         (X, Y) and a display window around it
//   make_nan alpha IN.exr OUT.exr         IN's channels and windows, and alpha A = 1
//   make_nan black IN.exr OUT.exr X Y S   IN with every channel of the S x S square at (X, Y)
//                                         (data-window coordinates) set to 0: a bucket written black
//   make_nan tile IN.exr OUT.exr X Y S V  IN with the colour channels (R, G, B) of that square set
//                                         to V, the variance kept: a bucket of garbage
//   make_nan bigwindow IN.exr OUT.exr     IN's bytes with the header's data window made
//                                         65536 x 65536 (a small file claiming 4 G pixels)
//   make_nan same_pfm IN.exr C.pfm V.pfm  exit 0 when C.pfm holds IN's R,G,B and V.pfm its
//                                         Variance.* (bit for bit), else 1 with the first difference
//   make_nan info FILE.exr                prints "data X0 Y0 X1 Y1 display X0 Y0 X1 Y1
//                                         nonfinite N" (N: non-finite samples, all channels)
#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "image_io.hpp"

namespace {

int fill(int argc, char** argv) {
    if (argc != 7) return 2;
    firefly_tools::pfm_image img;
    img.width = std::atoi(argv[3]);
    img.height = std::atoi(argv[4]);
    img.channels = std::atoi(argv[5]);
    const float v = std::strcmp(argv[6], "max") == 0 ? FLT_MAX : std::strtof(argv[6], nullptr);
    img.pixels.assign(static_cast<std::size_t>(img.width * img.height * img.channels), v);
    return firefly_tools::write_pfm(argv[2], img).empty() ? 0 : 1;
}

#ifdef FIREFLY_HAVE_OPENEXR
std::vector<std::string> channel_names(const std::string& path) {
    Imf::InputFile f(path.c_str());
    std::vector<std::string> names;
    for (auto it = f.header().channels().begin(); it != f.header().channels().end(); ++it) names.push_back(it.name());
    return names;
}

// shift, or alpha (argc 4): copies IN with its windows and adds A = 1.
int shift(int argc, char** argv) {
    if (argc != 6 && argc != 4) return 2;
    firefly_tools::image img;
    std::string e = firefly_tools::read_exr(argv[2], channel_names(argv[2]), img);
    if (!e.empty()) {
        std::fprintf(stderr, "%s\n", e.c_str());
        return 1;
    }
    if (argc == 6) {
        const int x = std::atoi(argv[4]), y = std::atoi(argv[5]);
        img.data_window = {x, y, x + img.width - 1, y + img.height - 1};
        img.display_window = {x - 3, y - 2, x + img.width + 4, y + img.height + 5};
    } else {  // add alpha A = 1
        const std::size_t n = img.channels.size(), np = img.pixels.size() / n;
        std::vector<float> px(np * (n + 1), 1.0f);
        for (std::size_t i = 0; i < np; ++i)
            for (std::size_t c = 0; c < n; ++c) px[i * (n + 1) + c] = img.pixels[i * n + c];
        img.pixels = px;
        img.channels.push_back("A");
    }
    e = firefly_tools::write_exr(argv[3], img);
    if (!e.empty()) std::fprintf(stderr, "%s\n", e.c_str());
    return e.empty() ? 0 : 1;
}

// IN with the S x S square at (X, Y) (data-window coordinates) set to `value` in every channel,
// or in the colour channels (R, G, B) alone.
int square(char** argv, float value, bool colour_only) {
    firefly_tools::image img;
    std::string e = firefly_tools::read_exr(argv[2], channel_names(argv[2]), img);
    if (!e.empty()) {
        std::fprintf(stderr, "%s\n", e.c_str());
        return 1;
    }
    const int x0 = std::atoi(argv[4]), y0 = std::atoi(argv[5]), side = std::atoi(argv[6]);
    const std::size_t n = img.channels.size();
    for (int y = std::max(0, y0); y < std::min(img.height, y0 + side); ++y)
        for (int x = std::max(0, x0); x < std::min(img.width, x0 + side); ++x)
            for (std::size_t c = 0; c < n; ++c)
                if (!colour_only || img.channels[c] == "R" || img.channels[c] == "G" || img.channels[c] == "B")
                    img.pixels[(static_cast<std::size_t>(y) * static_cast<std::size_t>(img.width) + static_cast<std::size_t>(x)) * n + c] = value;
    e = firefly_tools::write_exr(argv[3], img);
    if (!e.empty()) std::fprintf(stderr, "%s\n", e.c_str());
    return e.empty() ? 0 : 1;
}

int black(int argc, char** argv) { return argc == 7 ? square(argv, 0.0f, false) : 2; }

// A bucket of garbage with a sane variance pass.
int tile(int argc, char** argv) { return argc == 8 ? square(argv, std::strtof(argv[7], nullptr), true) : 2; }

int bigwindow(int argc, char** argv) {
    if (argc != 4) return 2;
    std::FILE* f = std::fopen(argv[2], "rb");
    if (!f) return 1;
    std::vector<char> bytes(1 << 20);
    bytes.resize(std::fread(bytes.data(), 1, bytes.size(), f));
    std::fclose(f);
    const char key[] = "dataWindow\0box2i\0\x10\0\0\0";  // name, type, size 16
    const std::string all(bytes.begin(), bytes.end());
    const std::size_t at = all.find(std::string(key, sizeof key - 1));
    if (at == std::string::npos) return 1;
    std::int32_t box[4];
    std::memcpy(box, &bytes[at + sizeof key - 1], 16);
    box[2] = box[0] + 65535;
    box[3] = box[1] + 65535;
    std::memcpy(&bytes[at + sizeof key - 1], box, 16);
    f = std::fopen(argv[3], "wb");
    if (!f) return 1;
    const bool ok = std::fwrite(bytes.data(), 1, bytes.size(), f) == bytes.size();
    return std::fclose(f) == 0 && ok ? 0 : 1;
}

int info(int argc, char** argv) {
    if (argc != 3) return 2;
    firefly_tools::image img;
    const std::string e = firefly_tools::read_exr(argv[2], channel_names(argv[2]), img);
    if (!e.empty()) {
        std::fprintf(stderr, "%s\n", e.c_str());
        return 1;
    }
    std::size_t bad = 0;
    for (float v : img.pixels) bad += std::isfinite(v) ? 0 : 1;
    const auto& d = img.data_window;
    const auto& s = img.display_window;
    std::printf("data %d %d %d %d display %d %d %d %d nonfinite %zu\n", d.min_x, d.min_y, d.max_x, d.max_y, s.min_x,
                s.min_y, s.max_x, s.max_y, bad);
    return 0;
}

// Compares channels [first, first + pfm.channels) of img with a PFM, bit for bit.
bool same_channels(const firefly_tools::image& img, std::size_t first, const char* path) {
    firefly_tools::pfm_image p;
    const std::string e = firefly_tools::read_pfm(path, p);
    const std::size_t n = img.channels.size(), nc = static_cast<std::size_t>(p.channels);
    if (!e.empty() || p.width != img.width || p.height != img.height || first + nc > n) {
        std::fprintf(stderr, "%s: %s\n", path, e.empty() ? "another size or channel count" : e.c_str());
        return false;
    }
    for (std::size_t i = 0; i < p.pixels.size(); ++i) {
        const float a = img.pixels[(i / nc) * n + first + i % nc], b = p.pixels[i];
        if (std::memcmp(&a, &b, sizeof a) != 0) {
            std::fprintf(stderr, "%s: value %zu is %.9g, the EXR's %.9g\n", path, i, static_cast<double>(b),
                         static_cast<double>(a));
            return false;
        }
    }
    return true;
}

int same_pfm(int argc, char** argv) {
    if (argc != 5) return 2;
    firefly_tools::image img;
    const std::string e = firefly_tools::read_exr(argv[2], {"R", "G", "B", "Variance.R", "Variance.G", "Variance.B"}, img);
    if (!e.empty()) {
        std::fprintf(stderr, "%s\n", e.c_str());
        return 1;
    }
    return same_channels(img, 0, argv[3]) && same_channels(img, 3, argv[4]) ? 0 : 1;
}
#endif

}  // namespace

int main(int argc, char** argv) {
    if (argc >= 2 && std::strcmp(argv[1], "fill") == 0) return fill(argc, argv);
#ifdef FIREFLY_HAVE_OPENEXR
    try {
        if (argc >= 2 && std::strcmp(argv[1], "shift") == 0) return argc == 6 ? shift(argc, argv) : 2;
        if (argc >= 2 && std::strcmp(argv[1], "alpha") == 0) return argc == 4 ? shift(argc, argv) : 2;
        if (argc >= 2 && std::strcmp(argv[1], "info") == 0) return info(argc, argv);
        if (argc >= 2 && std::strcmp(argv[1], "same_pfm") == 0) return same_pfm(argc, argv);
        if (argc >= 2 && std::strcmp(argv[1], "bigwindow") == 0) return bigwindow(argc, argv);
        if (argc >= 2 && std::strcmp(argv[1], "black") == 0) return black(argc, argv);
        if (argc >= 2 && std::strcmp(argv[1], "tile") == 0) return tile(argc, argv);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "%s\n", e.what());
        return 1;
    }
#endif
    if (argc != 2) return 2;
    firefly_tools::pfm_image img;
    img.width = 16;
    img.height = 8;
    img.channels = 3;
    img.pixels.assign(16 * 8 * 3, std::numeric_limits<float>::quiet_NaN());
    return firefly_tools::write_pfm(argv[1], img).empty() ? 0 : 1;
}
