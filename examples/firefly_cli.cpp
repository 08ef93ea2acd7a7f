// firefly: the command-line cleaner for real renderer output.
//
//   firefly half_a.exr half_b.exr -o clean.exr
//   firefly beauty_a.####.exr beauty_b.####.exr --frames 1-240 -o clean.####.exr
//
// Reads the two half buffers of a frame (colour R,G,B and variance Variance.R/G/B, the names
// pbrt-v4 and Blender write; optional alpha A), cleans them with firefly::detector and writes
// the combined image (A + B) / 2 with the variance of that mean. Every output is written under
// a temporary name and renamed when complete, so a failure never leaves a partial file.
#include <firefly/firefly.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "image_io.hpp"

using namespace firefly;
using firefly_tools::image;

namespace {

const char* usage_text =
    "usage: firefly [options] HALF_A HALF_B -o OUTPUT\n"
    "\n"
    "Removes fireflies from a Monte Carlo render given as two half buffers (each holding half\n"
    "of every pixel's samples) with per-pixel variance, and writes the combined image.\n"
    "\n"
    "inputs\n"
    "  HALF_A HALF_B            OpenEXR files, one per half: colour and variance channels\n"
    "                           (PFM colour files work too, with --variance-a/--variance-b)\n"
    "  --channels R,G,B         colour channel names                  (default R,G,B)\n"
    "  --variance Variance.R,Variance.G,Variance.B\n"
    "                           variance channel names (1 or 3)       (default as shown)\n"
    "  --alpha-channel A        alpha channel; used when present      (default A)\n"
    "  --no-alpha               ignore alpha even when present\n"
    "  --variance-a FILE, --variance-b FILE\n"
    "                           variance PFM files for PFM colour inputs\n"
    "  --frames FIRST-LAST[:STEP]  frame sequence: '#' runs in every path become the frame\n"
    "                           number, zero-padded to the run's length\n"
    "\n"
    "outputs\n"
    "  -o, --output FILE        combined cleaned image (EXR: colour, Variance.*, alpha)\n"
    "  --halves PREFIX          also write PREFIX_a.exr and PREFIX_b.exr (cleaned halves)\n"
    "  --masks PREFIX           also write PREFIX_a.exr and PREFIX_b.exr with channels\n"
    "                           firefly, highlight, consistent, nonfinite (0 or 1)\n"
    "  --report FILE            JSON report: options, per-frame counts and timings\n"
    "  --preview PREFIX         PNG previews PREFIX_before.png, PREFIX_after.png (sRGB)\n"
    "  --exposure X             preview exposure multiplier [1]\n"
    "  -q, --quiet              no progress lines\n"
    "\n"
    "detector options (defaults in brackets)\n"
    "  --significance X         generalized ESD alpha [0.05]\n"
    "  --bound X                modified Z-score threshold [3.5]\n"
    "  --reduction mean|luminance|max   channel variances to one number [mean]\n"
    "  --lambdas exact|hill|normal      Student-t method for the critical values [exact]\n"
    "  --highlight-rule same_pixel|agree|confident|confident_and_agree  [confident]\n"
    "  --max-relative-error X   confident rule threshold [0.5]\n"
    "  --max-ratio X            agree rule factor [4]\n"
    "  --min-excess-z X         one-half outliers must exceed the other half by X sd [4]; 0: off\n"
    "  --cluster-relative-error X  confident rule bound for pixels next to another both-half\n"
    "                           outlier (highlights are spatially coherent) [0.8]; 0: off\n"
    "  --kernel N               reconstruction kernel width, odd [5]\n"
    "  --sigma X                reconstruction Gaussian sigma [1]\n"
    "  --tolerance X            phase 2 relative tolerance [1e-3]\n"
    "  --iterations N           phase 2 iteration cap [20]\n"
    "  --threads N              threads [1]; results are identical for any count\n"
    "\n"
    "  -h, --help               this text;  --version  the version\n";

struct cli {
    std::string in_a, in_b, out, halves, masks, report, preview;
    float exposure = 1.0f;
    std::string var_a, var_b;  // PFM variance files
    std::vector<std::string> colour = {"R", "G", "B"};
    std::vector<std::string> variance = {"Variance.R", "Variance.G", "Variance.B"};
    std::string alpha = "A";
    bool use_alpha = true, quiet = false;
    bool sequence = false;
    long first = 0, last = 0, step = 1;
    detector_options o;
    unsigned threads = 1;
};

bool ends_with(const std::string& s, const char* suffix) {
    const std::size_t n = std::strlen(suffix);
    if (s.size() < n) return false;
    for (std::size_t i = 0; i < n; ++i)
        if (std::tolower(static_cast<unsigned char>(s[s.size() - n + i])) != suffix[i]) return false;
    return true;
}

std::vector<std::string> split(const std::string& s) {
    std::vector<std::string> out;
    std::size_t start = 0;
    while (true) {
        const std::size_t comma = s.find(',', start);
        out.push_back(s.substr(start, comma - start));
        if (comma == std::string::npos) break;
        start = comma + 1;
    }
    return out;
}

// Replaces each run of '#' by the frame number, zero-padded to the run's length.
std::string frame_path(const std::string& pattern, long frame) {
    std::string out;
    for (std::size_t i = 0; i < pattern.size();) {
        if (pattern[i] != '#') {
            out += pattern[i++];
            continue;
        }
        std::size_t j = i;
        while (j < pattern.size() && pattern[j] == '#') ++j;
        char buf[32];
        std::snprintf(buf, sizeof buf, "%0*ld", static_cast<int>(j - i), frame);
        out += buf;
        i = j;
    }
    return out;
}

bool parse_number(const char* s, double& v) {
    char* end = nullptr;
    v = std::strtod(s, &end);
    return end != s && *end == '\0' && std::isfinite(v);
}

// Returns an empty string or the complaint.
std::string parse(int argc, char** argv, cli& c, bool& done) {
    std::vector<std::string> positional;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        auto value = [&](std::string& v) -> bool {
            if (i + 1 >= argc) return false;
            v = argv[++i];
            return true;
        };
        auto number = [&](double& v) -> bool {
            std::string s;
            return value(s) && parse_number(s.c_str(), v);
        };
        std::string s;
        double d = 0;
        if (a == "-h" || a == "--help") {
            std::fputs(usage_text, stdout);
            done = true;
            return {};
        } else if (a == "--version") {
            std::printf("firefly %d.%d.%d\n", FIREFLY_VERSION_MAJOR, FIREFLY_VERSION_MINOR, FIREFLY_VERSION_PATCH);
            done = true;
            return {};
        } else if (a == "-o" || a == "--output") {
            if (!value(c.out)) return "-o needs a file name";
        } else if (a == "--halves") {
            if (!value(c.halves)) return "--halves needs a prefix";
        } else if (a == "--masks") {
            if (!value(c.masks)) return "--masks needs a prefix";
        } else if (a == "--report") {
            if (!value(c.report)) return "--report needs a file name";
        } else if (a == "--preview") {
            if (!value(c.preview)) return "--preview needs a prefix";
            if (!firefly_tools::have_png()) return "--preview needs PNG support: rebuild with libpng-dev installed";
        } else if (a == "--exposure") {
            if (!number(d) || !(d > 0)) return "--exposure wants a positive number";
            c.exposure = static_cast<float>(d);
        } else if (a == "--variance-a") {
            if (!value(c.var_a)) return "--variance-a needs a file name";
        } else if (a == "--variance-b") {
            if (!value(c.var_b)) return "--variance-b needs a file name";
        } else if (a == "--channels") {
            if (!value(s) || (c.colour = split(s)).size() != 3) return "--channels wants three names, e.g. R,G,B";
        } else if (a == "--variance") {
            if (!value(s)) return "--variance needs channel names";
            c.variance = split(s);
            if (c.variance.size() != 1 && c.variance.size() != 3) return "--variance wants one or three names";
        } else if (a == "--alpha-channel") {
            if (!value(c.alpha)) return "--alpha-channel needs a name";
        } else if (a == "--no-alpha") {
            c.use_alpha = false;
        } else if (a == "-q" || a == "--quiet") {
            c.quiet = true;
        } else if (a == "--frames") {
            if (!value(s)) return "--frames needs FIRST-LAST";
            long f = 0, l = 0, st = 1;
            const int got = std::sscanf(s.c_str(), "%ld-%ld:%ld", &f, &l, &st);
            if (got < 2 || l < f || st < 1) return "--frames wants FIRST-LAST or FIRST-LAST:STEP with FIRST <= LAST";
            c.sequence = true;
            c.first = f;
            c.last = l;
            c.step = st;
        } else if (a == "--significance") {
            if (!number(d) || !(d > 0 && d < 1)) return "--significance wants a number in (0, 1)";
            c.o.alpha = d;
        } else if (a == "--bound") {
            if (!number(d) || d < 0) return "--bound wants a number >= 0";
            c.o.bound_threshold = d;
        } else if (a == "--reduction") {
            if (!value(s)) return "--reduction needs a value";
            if (s == "mean") c.o.reduction = variance_reduction::mean;
            else if (s == "luminance") c.o.reduction = variance_reduction::luminance;
            else if (s == "max") c.o.reduction = variance_reduction::max;
            else return "--reduction is mean, luminance or max";
        } else if (a == "--lambdas") {
            if (!value(s)) return "--lambdas needs a value";
            if (s == "exact") c.o.lambdas = lambda_method::exact;
            else if (s == "hill") c.o.lambdas = lambda_method::hill;
            else if (s == "normal") c.o.lambdas = lambda_method::normal;
            else return "--lambdas is exact, hill or normal";
        } else if (a == "--highlight-rule") {
            if (!value(s)) return "--highlight-rule needs a value";
            if (s == "same_pixel") c.o.highlight.rule = highlight_rule::same_pixel;
            else if (s == "agree") c.o.highlight.rule = highlight_rule::agree;
            else if (s == "confident") c.o.highlight.rule = highlight_rule::confident;
            else if (s == "confident_and_agree") c.o.highlight.rule = highlight_rule::confident_and_agree;
            else return "--highlight-rule is same_pixel, agree, confident or confident_and_agree";
        } else if (a == "--max-relative-error") {
            if (!number(d) || d < 0) return "--max-relative-error wants a number >= 0";
            c.o.highlight.max_relative_error = d;
        } else if (a == "--max-ratio") {
            if (!number(d) || d < 1) return "--max-ratio wants a number >= 1";
            c.o.highlight.max_ratio = d;
        } else if (a == "--min-excess-z") {
            if (!number(d) || d < 0) return "--min-excess-z wants a number >= 0";
            c.o.highlight.min_excess_z = d;
        } else if (a == "--cluster-relative-error") {
            if (!number(d) || d < 0) return "--cluster-relative-error wants a number >= 0";
            c.o.highlight.cluster_relative_error = d;
        } else if (a == "--kernel") {
            if (!number(d) || d != std::floor(d)) return "--kernel wants an odd whole number";
            c.o.reconstruction.kernel_width = static_cast<int>(d);
        } else if (a == "--sigma") {
            if (!number(d) || !(d > 0)) return "--sigma wants a positive number";
            c.o.reconstruction.sigma = d;
        } else if (a == "--tolerance") {
            if (!number(d) || d < 0) return "--tolerance wants a number >= 0";
            c.o.reconstruction.tolerance = d;
        } else if (a == "--iterations") {
            if (!number(d) || d < 0 || d != std::floor(d)) return "--iterations wants a whole number >= 0";
            c.o.reconstruction.max_iterations = static_cast<int>(d);
        } else if (a == "--threads") {
            if (!number(d) || d < 1 || d > 256) return "--threads wants a number from 1 to 256";
            c.threads = static_cast<unsigned>(d);
        } else if (!a.empty() && a[0] == '-' && a.size() > 1) {
            return "unknown option " + a + " (firefly --help lists them)";
        } else {
            positional.push_back(a);
        }
    }
    if (positional.size() != 2) return "expected two inputs, HALF_A and HALF_B (firefly --help)";
    if (c.out.empty()) return "no output: give -o FILE";
    c.in_a = positional[0];
    c.in_b = positional[1];
    if (status st = check_options(c.o); !st) return std::string("bad option: ") + st.message();
    const bool pfm = ends_with(c.in_a, ".pfm") || ends_with(c.in_b, ".pfm");
    if (pfm && (c.var_a.empty() || c.var_b.empty()))
        return "PFM inputs hold colour only: give --variance-a and --variance-b PFM files";
    if (c.sequence && c.out.find('#') == std::string::npos)
        return "--frames needs '#' in the output name too, e.g. clean.####.exr";
    return {};
}

struct half_data {
    image img;       // colour (3) + variance (1 or 3) [+ alpha], interleaved
    int nc = 3, nv = 3;
    bool has_alpha = false;
};

std::string read_half(const cli& c, const std::string& path, const std::string& var_path, half_data& h) {
    if (ends_with(path, ".pfm")) {
        firefly_tools::pfm_image col, var;
        std::string e = firefly_tools::read_pfm(path, col);
        if (!e.empty()) return e;
        e = firefly_tools::read_pfm(var_path, var);
        if (!e.empty()) return e;
        if (col.channels != 3) return path + ": the colour PFM must have 3 channels";
        if (var.width != col.width || var.height != col.height)
            return var_path + ": variance and colour differ in size";
        h.nc = 3;
        h.nv = var.channels;
        h.has_alpha = false;
        h.img.width = col.width;
        h.img.height = col.height;
        h.img.channels = {"R", "G", "B"};
        for (int k = 0; k < h.nv; ++k) h.img.channels.push_back(h.nv == 1 ? "Variance.Y" : std::string("Variance.") + "RGB"[k]);
        const std::size_t np = static_cast<std::size_t>(col.width) * static_cast<std::size_t>(col.height);
        const std::size_t stride = static_cast<std::size_t>(3 + h.nv);
        h.img.pixels.resize(np * stride);
        for (std::size_t i = 0; i < np; ++i) {
            for (int k = 0; k < 3; ++k) h.img.pixels[i * stride + static_cast<std::size_t>(k)] = col.pixels[i * 3 + static_cast<std::size_t>(k)];
            for (int k = 0; k < h.nv; ++k)
                h.img.pixels[i * stride + 3 + static_cast<std::size_t>(k)] = var.pixels[i * static_cast<std::size_t>(h.nv) + static_cast<std::size_t>(k)];
        }
        return {};
    }
    std::vector<std::string> names = c.colour;
    for (const auto& v : c.variance) names.push_back(v);
    h.nc = 3;
    h.nv = static_cast<int>(c.variance.size());
    // Alpha when asked for and present: read with it; when the only complaint is a missing
    // channel, read again without it (a missing colour or variance channel is then reported).
    h.has_alpha = false;
    if (c.use_alpha) {
        std::vector<std::string> with = names;
        with.push_back(c.alpha);
        const std::string e = firefly_tools::read_exr(path, with, h.img);
        if (e.empty()) {
            h.has_alpha = true;
            return {};
        }
        if (e.find("missing channel") == std::string::npos) return e;
    }
    return firefly_tools::read_exr(path, names, h.img);
}

// Writes to a temporary name in the same folder, then renames.
std::string write_atomic(const std::string& path, const image& img) {
    const std::string tmp = path + ".tmp";
    const std::string e = firefly_tools::write_exr(tmp, img);
    if (!e.empty()) {
        std::remove(tmp.c_str());
        return e;
    }
    if (std::rename(tmp.c_str(), path.c_str()) != 0) {
        std::remove(tmp.c_str());
        return "cannot rename " + tmp + " to " + path;
    }
    return {};
}
std::string write_text_atomic(const std::string& path, const std::string& text) {
    const std::string tmp = path + ".tmp";
    std::FILE* f = std::fopen(tmp.c_str(), "wb");
    if (!f) return "cannot write " + tmp;
    const bool ok = std::fwrite(text.data(), 1, text.size(), f) == text.size();
    if (std::fclose(f) != 0 || !ok) {
        std::remove(tmp.c_str());
        return "write failed: " + tmp;
    }
    if (std::rename(tmp.c_str(), path.c_str()) != 0) {
        std::remove(tmp.c_str());
        return "cannot rename " + tmp + " to " + path;
    }
    return {};
}

std::string json_string(const std::string& s) {
    std::string o = "\"";
    for (char ch : s) {
        if (ch == '"' || ch == '\\') o += '\\', o += ch;
        else if (static_cast<unsigned char>(ch) < 0x20) {
            char buf[8];
            std::snprintf(buf, sizeof buf, "\\u%04x", ch);
            o += buf;
        } else o += ch;
    }
    return o + "\"";
}

const char* rule_name(highlight_rule r) {
    switch (r) {
        case highlight_rule::same_pixel: return "same_pixel";
        case highlight_rule::agree: return "agree";
        case highlight_rule::confident: return "confident";
        default: return "confident_and_agree";
    }
}

std::string half_json(const half_report& h) {
    char buf[1024];
    std::snprintf(buf, sizeof buf,
                  "{\"pixels\": %zu, \"valid\": %zu, \"ignored\": %zu, \"nonfinite\": %zu, \"negative_variance\": %zu, "
                  "\"median_sd\": %.9g, \"mad_sd\": %.9g, \"bound\": %zu, \"outliers\": %zu, \"highlights\": %zu, "
                  "\"consistent\": %zu, \"fireflies\": %zu, \"repaired\": %zu, \"phase1_rounds\": %d, "
                  "\"phase2_iterations\": %d, \"final_change\": %.6g}",
                  h.pixels, h.valid, h.ignored, h.nonfinite, h.negative_variance, h.median, h.mad, h.bound, h.outliers,
                  h.highlights, h.consistent, h.fireflies, h.repaired, h.phase1_rounds, h.phase2_iterations, h.final_change);
    return buf;
}

using clock_type = std::chrono::steady_clock;
double ms_since(clock_type::time_point t) {
    return std::chrono::duration<double, std::milli>(clock_type::now() - t).count();
}

// One frame: read, clean, write. Returns an empty string or the error; json gets the record.
std::string run_frame(const cli& c, detector& d, long frame, std::string& json) {
    const std::string pa = c.sequence ? frame_path(c.in_a, frame) : c.in_a;
    const std::string pb = c.sequence ? frame_path(c.in_b, frame) : c.in_b;
    const std::string va = c.sequence ? frame_path(c.var_a, frame) : c.var_a;
    const std::string vb = c.sequence ? frame_path(c.var_b, frame) : c.var_b;
    const std::string out = c.sequence ? frame_path(c.out, frame) : c.out;
    const auto t0 = clock_type::now();
    half_data h[2];
    std::string e = read_half(c, pa, va, h[0]);
    if (e.empty()) e = read_half(c, pb, vb, h[1]);
    if (!e.empty()) return e;
    if (h[0].img.width != h[1].img.width || h[0].img.height != h[1].img.height) {
        char buf[256];
        std::snprintf(buf, sizeof buf, "the halves differ in size: %dx%d and %dx%d", h[0].img.width, h[0].img.height,
                      h[1].img.width, h[1].img.height);
        return buf;
    }
    if (h[0].nv != h[1].nv || h[0].has_alpha != h[1].has_alpha) return "the halves differ in channels";
    const double read_ms = ms_since(t0);
    const int w = h[0].img.width, ht = h[0].img.height;
    half_buffer<float> hb[2];
    for (int i = 0; i < 2; ++i) {
        const std::ptrdiff_t ps = static_cast<std::ptrdiff_t>(h[i].img.channel_count() * sizeof(float));
        float* base = h[i].img.pixels.data();
        auto col = image_view<float>::create(base, w, ht, 3, ps);
        auto var = image_view<float>::create(base + 3, w, ht, h[i].nv, ps);
        if (!col || !var) return "internal: bad image layout";
        hb[i].color = *col;
        hb[i].variance = *var;
        if (h[i].has_alpha) {
            auto al = image_view<const float>::create(base + 3 + h[i].nv, w, ht, 1, ps);
            if (!al) return "internal: bad alpha layout";
            hb[i].alpha = *al;
        }
    }
    std::vector<std::uint8_t> mask[2];
    image_view<std::uint8_t> mv[2];
    if (!c.masks.empty())
        for (int i = 0; i < 2; ++i) {
            mask[i].assign(static_cast<std::size_t>(w) * static_cast<std::size_t>(ht), 0);
            mv[i] = *make_image_view(mask[i].data(), w, ht);
        }
    std::vector<float> before;  // the combined input, for the preview
    if (!c.preview.empty()) {
        before.resize(static_cast<std::size_t>(w) * static_cast<std::size_t>(ht) * 3);
        const std::size_t st = h[0].img.channels.size();
        for (std::size_t i = 0; i < before.size() / 3; ++i)
            for (int k = 0; k < 3; ++k)
                before[i * 3 + static_cast<std::size_t>(k)] = 0.5f * h[0].img.pixels[i * st + static_cast<std::size_t>(k)] +
                                                                0.5f * h[1].img.pixels[i * st + static_cast<std::size_t>(k)];
    }
    const auto t1 = clock_type::now();
    const frame_report r = d.process(hb[0], hb[1], mv[0], mv[1]);
    const double process_ms = ms_since(t1);
    if (!r.error) return std::string("cannot clean the frame: ") + r.error.message();
    for (int i = 0; i < 2; ++i)
        if (r.half[i].reconstruction.code() == errc::no_valid_pixels)
            return std::string("half ") + "AB"[i] + " has no valid pixel to rebuild from (every pixel is NaN/Inf, black or an outlier)";

    // Combined image: (A + B) / 2, variance of the mean (vA + vB) / 4, alpha averaged.
    const auto t2 = clock_type::now();
    image comb;
    comb.width = w;
    comb.height = ht;
    comb.channels = h[0].img.channels;  // colour, variance [, alpha], as read
    const std::size_t stride = comb.channels.size(), in_stride = h[0].img.channels.size();
    comb.pixels.resize(static_cast<std::size_t>(w) * static_cast<std::size_t>(ht) * stride);
    for (std::size_t i = 0; i < static_cast<std::size_t>(w) * static_cast<std::size_t>(ht); ++i) {
        const float* a = &h[0].img.pixels[i * in_stride];
        const float* b = &h[1].img.pixels[i * in_stride];
        float* o = &comb.pixels[i * stride];
        for (int k = 0; k < 3; ++k) o[k] = 0.5f * a[k] + 0.5f * b[k];
        for (int k = 0; k < h[0].nv; ++k) o[3 + k] = 0.25f * (a[3 + k] + b[3 + k]);
        if (h[0].has_alpha) o[3 + h[0].nv] = 0.5f * (a[3 + h[0].nv] + b[3 + h[0].nv]);
    }
    e = write_atomic(out, comb);
    if (!e.empty()) return e;
    for (int i = 0; i < 2 && !c.halves.empty(); ++i) {
        const std::string p = (c.sequence ? frame_path(c.halves, frame) : c.halves) + (i ? "_b.exr" : "_a.exr");
        e = write_atomic(p, h[i].img);
        if (!e.empty()) return e;
    }
    for (int i = 0; i < 2 && !c.masks.empty(); ++i) {
        const std::string p = (c.sequence ? frame_path(c.masks, frame) : c.masks) + (i ? "_b.exr" : "_a.exr");
        image m;
        m.width = w;
        m.height = ht;
        m.channels = {"firefly", "highlight", "consistent", "nonfinite"};
        m.pixels.resize(static_cast<std::size_t>(w) * static_cast<std::size_t>(ht) * 4);
        for (std::size_t k = 0; k < mask[i].size(); ++k) {
            m.pixels[k * 4 + 0] = (mask[i][k] & mask_bits::firefly) ? 1.0f : 0.0f;
            m.pixels[k * 4 + 1] = (mask[i][k] & mask_bits::highlight) ? 1.0f : 0.0f;
            m.pixels[k * 4 + 2] = (mask[i][k] & mask_bits::consistent) ? 1.0f : 0.0f;
            m.pixels[k * 4 + 3] = (mask[i][k] & mask_bits::nonfinite) ? 1.0f : 0.0f;
        }
        e = write_atomic(p, m);
        if (!e.empty()) return e;
    }
    if (!c.preview.empty()) {
        const std::string p = c.sequence ? frame_path(c.preview, frame) : c.preview;
        e = firefly_tools::write_png_preview(p + "_before.png", before.data(), w, ht, 3, c.exposure);
        if (e.empty()) e = firefly_tools::write_png_preview(p + "_after.png", comb.pixels.data(), w, ht, stride, c.exposure);
        if (!e.empty()) return e;
    }
    const double write_ms = ms_since(t2);
    char buf[512];
    std::snprintf(buf, sizeof buf,
                  "{\"frame\": %ld, \"half_a\": %s, \"half_b\": %s, \"output\": %s, \"width\": %d, \"height\": %d, "
                  "\"both_outliers\": %zu, \"variance_calibration\": %.6g, \"lambdas_computed\": %zu, "
                  "\"milliseconds\": {\"read\": %.2f, \"process\": %.2f, \"write\": %.2f}, ",
                  frame, json_string(pa).c_str(), json_string(pb).c_str(), json_string(out).c_str(), w, ht,
                  r.both_outliers, r.variance_calibration, r.lambdas_computed, read_ms, process_ms, write_ms);
    json = std::string(buf) + "\"a\": " + half_json(r.half[0]) + ", \"b\": " + half_json(r.half[1]) + "}";
    if (!c.quiet)
        std::printf("%s: %dx%d, fireflies %zu + %zu, highlights kept %zu, non-finite repaired %zu + %zu, %.1f ms\n",
                    out.c_str(), w, ht, r.half[0].fireflies, r.half[1].fireflies, r.half[0].highlights,
                    r.half[0].repaired, r.half[1].repaired, process_ms);
    return {};
}

}  // namespace

int main(int argc, char** argv) {
    cli c;
    bool done = false;
    const std::string perr = parse(argc, argv, c, done);
    if (done) return 0;
    if (!perr.empty()) {
        std::fprintf(stderr, "firefly: %s\n", perr.c_str());
        return 2;
    }
    detector d(c.o, executor::threads(c.threads));
    std::vector<std::string> frames_json;
    const long first = c.sequence ? c.first : 0, last = c.sequence ? c.last : 0;
    const long count = (last - first) / c.step + 1;
    long index = 0;
    for (long f = first; f <= last; f += c.step, ++index) {
        std::string json;
        const std::string e = run_frame(c, d, f, json);
        if (!e.empty()) {
            if (c.sequence) std::fprintf(stderr, "firefly: frame %ld: %s\n", f, e.c_str());
            else std::fprintf(stderr, "firefly: %s\n", e.c_str());
            return 1;
        }
        frames_json.push_back(json);
        if (c.sequence && !c.quiet) std::printf("  [%ld/%ld]\n", index + 1, count);
    }
    if (!c.report.empty()) {
        char opts[768];
        std::snprintf(opts, sizeof opts,
                      "{\"significance\": %g, \"bound\": %g, \"reduction\": \"%s\", \"lambdas\": \"%s\", "
                      "\"highlight_rule\": \"%s\", \"max_relative_error\": %g, \"max_ratio\": %g, \"min_excess_z\": %g, "
                      "\"cluster_relative_error\": %g, "
                      "\"kernel\": %d, \"sigma\": %g, \"tolerance\": %g, \"iterations\": %d, \"threads\": %u}",
                      c.o.alpha, c.o.bound_threshold,
                      c.o.reduction == variance_reduction::mean ? "mean" : c.o.reduction == variance_reduction::luminance ? "luminance" : "max",
                      c.o.lambdas == lambda_method::exact ? "exact" : c.o.lambdas == lambda_method::hill ? "hill" : "normal",
                      rule_name(c.o.highlight.rule), c.o.highlight.max_relative_error, c.o.highlight.max_ratio,
                      c.o.highlight.min_excess_z, c.o.highlight.cluster_relative_error, c.o.reconstruction.kernel_width, c.o.reconstruction.sigma,
                      c.o.reconstruction.tolerance, c.o.reconstruction.max_iterations, c.threads);
        std::string text = "{\n  \"firefly\": \"" + std::to_string(FIREFLY_VERSION_MAJOR) + "." +
                           std::to_string(FIREFLY_VERSION_MINOR) + "." + std::to_string(FIREFLY_VERSION_PATCH) +
                           "\",\n  \"options\": " + opts + ",\n  \"frames\": [\n";
        for (std::size_t i = 0; i < frames_json.size(); ++i)
            text += "    " + frames_json[i] + (i + 1 < frames_json.size() ? ",\n" : "\n");
        text += "  ]\n}\n";
        const std::string e = write_text_atomic(c.report, text);
        if (!e.empty()) {
            std::fprintf(stderr, "firefly: %s\n", e.c_str());
            return 1;
        }
    }
    return 0;
}
