// firefly: the command-line cleaner for real renderer output.
//
//   firefly half_a.exr half_b.exr -o clean.exr
//   firefly beauty_a.####.exr beauty_b.####.exr --frames 1-240 -o clean.####.exr
//
// Reads the two half buffers of a frame (colour R,G,B and variance Variance.R/G/B, the names
// pbrt-v4 and Blender write; optional alpha A), cleans them with firefly::detector and writes
// the combined image (A + B) / 2 with the variance of that mean.
//
// Outputs: all files of a frame (-o, --halves, --masks, --preview; and --report for a single
// frame) are written to exclusive temporaries and renamed only when all are complete, so a
// failure leaves none of them. An output that is an input, by file identity, is refused
// before anything is written. A sequence goes on past a bad frame, records it in the report
// and exits 1 at the end.
#include <firefly/firefly.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <new>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cli_options.hpp"
#include "image_io.hpp"
#include "output_files.hpp"

using namespace firefly;
using firefly_cli::options;
using firefly_tools::image;
using json = nlohmann::ordered_json;

namespace {

// Replaces each run of '#' by the frame number, zero-padded to the run's length.
std::string frame_path(const std::string& pattern, long long frame) {
    std::string out;
    for (std::size_t i = 0; i < pattern.size();) {
        if (pattern[i] != '#') {
            out += pattern[i++];
            continue;
        }
        std::size_t j = i;
        while (j < pattern.size() && pattern[j] == '#') ++j;
        char buf[48];
        std::snprintf(buf, sizeof buf, "%0*lld", static_cast<int>(std::min<std::size_t>(j - i, 20)), frame);
        out += buf;
        i = j;
    }
    return out;
}

// Every file name of one frame.
struct frame_files {
    std::string a, b, va, vb;                           // inputs (va, vb: PFM variance)
    std::string out, halves[2], masks[2], preview[2];   // outputs; empty when not asked for
};

frame_files files_of(const options& c, long long frame) {
    auto p = [&](const std::string& s) { return c.sequence ? frame_path(s, frame) : s; };
    frame_files f{p(c.in_a), p(c.in_b), p(c.var_a), p(c.var_b), p(c.out), {}, {}, {}};
    for (int i = 0; i < 2; ++i) {
        if (!c.halves.empty()) f.halves[i] = p(c.halves) + (i ? "_b.exr" : "_a.exr");
        if (!c.masks.empty()) f.masks[i] = p(c.masks) + (i ? "_b.exr" : "_a.exr");
        if (!c.preview.empty()) f.preview[i] = p(c.preview) + (i ? "_after.png" : "_before.png");
    }
    return f;
}

// Refuses, before anything is written, an output that is an input of any frame (same
// device and inode, whatever the spelling), an output named twice in a frame, and a file
// given as both halves.
std::string check_files(const options& c) {
    using firefly_tools::file_id;
    const long long first = c.sequence ? c.first : 0, last = c.sequence ? c.last : 0;
    std::vector<std::pair<file_id, std::string>> inputs;
    auto find = [](const std::vector<std::pair<file_id, std::string>>& v, const file_id& id) -> const std::string* {
        for (const auto& e : v)
            if (e.first == id) return &e.second;
        return nullptr;
    };
    for (long long fr = first; fr <= last; fr += c.step) {
        const frame_files f = files_of(c, fr);
        file_id ia, ib;
        const bool ha = firefly_tools::identify(f.a, ia) && ia.leaf.empty();
        const bool hb = firefly_tools::identify(f.b, ib) && ib.leaf.empty();
        if (ha && hb && ia == ib) return "HALF_A and HALF_B are the same file (" + f.a + ", " + f.b + ")";
        for (const std::string* p : {&f.a, &f.b, &f.va, &f.vb}) {
            file_id id;
            if (!p->empty() && firefly_tools::identify(*p, id) && id.leaf.empty()) inputs.push_back({id, *p});
        }
    }
    for (long long fr = first; fr <= last; fr += c.step) {
        const frame_files f = files_of(c, fr);
        std::vector<std::pair<file_id, std::string>> outs;
        for (const std::string* p : {&f.out, &f.halves[0], &f.halves[1], &f.masks[0], &f.masks[1], &f.preview[0],
                                     &f.preview[1], &c.report}) {
            file_id id;
            if (p->empty()) continue;
            if (!firefly_tools::identify(*p, id)) continue;  // no such folder: the write will say so
            if (const std::string* in = find(inputs, id)) return "output " + *p + " is the input " + *in + ": refused";
            if (const std::string* o = find(outs, id)) return "outputs " + *o + " and " + *p + " are the same file";
            outs.push_back({id, *p});
        }
    }
    return {};
}

struct half_data {
    image img;  // colour (3) + variance (1 or 3) [+ alpha], interleaved
    int nv = 3;
    bool has_alpha = false;
};

std::string read_pfm_half(const std::string& path, const std::string& var_path, half_data& h) {
    firefly_tools::pfm_image col, var;
    std::string e = firefly_tools::read_pfm(path, col);
    if (e.empty()) e = firefly_tools::read_pfm(var_path, var);
    if (!e.empty()) return e;
    if (col.channels != 3) return path + ": the colour PFM must have 3 channels";
    if (var.width != col.width || var.height != col.height) return var_path + ": variance and colour differ in size";
    h.nv = var.channels;
    h.has_alpha = false;
    h.img = image{};
    h.img.width = col.width;
    h.img.height = col.height;
    h.img.channels = {"R", "G", "B"};
    for (int k = 0; k < h.nv; ++k) h.img.channels.push_back(h.nv == 1 ? "Variance.Y" : std::string("Variance.") + "RGB"[k]);
    const std::size_t np = static_cast<std::size_t>(col.width) * static_cast<std::size_t>(col.height);
    const std::size_t stride = static_cast<std::size_t>(3 + h.nv), nv = static_cast<std::size_t>(h.nv);
    h.img.pixels.resize(np * stride);
    for (std::size_t i = 0; i < np; ++i) {
        for (std::size_t k = 0; k < 3; ++k) h.img.pixels[i * stride + k] = col.pixels[i * 3 + k];
        for (std::size_t k = 0; k < nv; ++k) h.img.pixels[i * stride + 3 + k] = var.pixels[i * nv + k];
    }
    return {};
}

std::string read_half(const options& c, const std::string& path, const std::string& var_path, half_data& h) {
    if (firefly_cli::ends_with_ci(path, ".pfm")) return read_pfm_half(path, var_path, h);
    std::vector<std::string> names = c.colour;
    for (const auto& v : c.variance) names.push_back(v);
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

bool same_window(const firefly_tools::window& a, const firefly_tools::window& b) {
    return a.min_x == b.min_x && a.min_y == b.min_y && a.max_x == b.max_x && a.max_y == b.max_y;
}

// The halves must match in size, windows and channels; the messages say how they differ.
std::string check_halves(const options& c, const frame_files& f, const half_data (&h)[2]) {
    const image &a = h[0].img, &b = h[1].img;
    if (a.width != b.width || a.height != b.height)
        return "the halves differ in size: " + std::to_string(a.width) + "x" + std::to_string(a.height) + " and " +
               std::to_string(b.width) + "x" + std::to_string(b.height);
    if (!same_window(a.data_window, b.data_window) || !same_window(a.display_window, b.display_window))
        return "the halves differ in data or display window";
    if (h[0].has_alpha != h[1].has_alpha) {
        const std::string& with = h[0].has_alpha ? f.a : f.b;
        const std::string& without = h[0].has_alpha ? f.b : f.a;
        return "alpha channel " + c.alpha + " is in " + with + " but not in " + without + " (--no-alpha ignores it)";
    }
    if (h[0].nv != h[1].nv) return "the halves differ in variance channels";
    return {};
}

// Views over an interleaved half: colour, variance, alpha.
std::string views_of(half_data& h, half_buffer<float>& hb) {
    const int w = h.img.width, ht = h.img.height;
    const std::ptrdiff_t ps = static_cast<std::ptrdiff_t>(h.img.channel_count() * sizeof(float));
    float* base = h.img.pixels.data();
    auto col = image_view<float>::create(base, w, ht, 3, ps);
    auto var = image_view<float>::create(base + 3, w, ht, h.nv, ps);
    if (!col.ok() || !var.ok()) return "internal: bad image layout";
    hb.color = *col;
    hb.variance = *var;
    if (h.has_alpha) {
        auto al = image_view<const float>::create(base + 3 + h.nv, w, ht, 1, ps);
        if (!al.ok()) return "internal: bad alpha layout";
        hb.alpha = *al;
    }
    return {};
}

// Combined image: (A + B) / 2, variance of the mean vA / 4 + vB / 4, alpha averaged. The
// variance sum is taken in double: for finite inputs it is at most FLT_MAX / 2, so FLT_MAX
// variances stay finite (0.25f * (a + b) in float overflowed to Inf); Inf and NaN pass as is.
image combine(const half_data (&h)[2]) {
    image comb;
    comb.width = h[0].img.width;
    comb.height = h[0].img.height;
    comb.channels = h[0].img.channels;  // colour, variance [, alpha], as read
    comb.data_window = h[0].img.data_window;
    comb.display_window = h[0].img.display_window;
    const std::size_t stride = comb.channels.size(), nv = static_cast<std::size_t>(h[0].nv);
    const std::size_t np = static_cast<std::size_t>(comb.width) * static_cast<std::size_t>(comb.height);
    comb.pixels.resize(np * stride);
    for (std::size_t i = 0; i < np; ++i) {
        const float* a = &h[0].img.pixels[i * stride];
        const float* b = &h[1].img.pixels[i * stride];
        float* o = &comb.pixels[i * stride];
        for (std::size_t k = 0; k < 3; ++k) o[k] = 0.5f * a[k] + 0.5f * b[k];
        for (std::size_t k = 3; k < 3 + nv; ++k) o[k] = static_cast<float>(0.25 * a[k] + 0.25 * b[k]);
        if (h[0].has_alpha) o[3 + nv] = 0.5f * a[3 + nv] + 0.5f * b[3 + nv];
    }
    return comb;
}

image mask_image(const std::vector<std::uint8_t>& mask, const image& like) {
    image m;
    m.width = like.width;
    m.height = like.height;
    m.data_window = like.data_window;
    m.display_window = like.display_window;
    m.channels = {"firefly", "highlight", "consistent", "nonfinite"};
    m.pixels.resize(mask.size() * 4);
    const std::uint8_t bits[4] = {mask_bits::firefly, mask_bits::highlight, mask_bits::consistent, mask_bits::nonfinite};
    for (std::size_t k = 0; k < mask.size(); ++k)
        for (std::size_t b = 0; b < 4; ++b) m.pixels[k * 4 + b] = (mask[k] & bits[b]) ? 1.0f : 0.0f;
    return m;
}

std::string write_exr_to(firefly_tools::output_set& set, const std::string& path, const image& img) {
    int fd = -1;
    std::string e = set.open(path, fd);
    if (!e.empty()) return e;
    firefly_tools::fd_ostream os(fd, path);
    return firefly_tools::write_exr(os, img);
}

std::string write_png_to(firefly_tools::output_set& set, const std::string& path, const float* rgb, int w, int h,
                         std::size_t stride, float exposure) {
    int fd = -1;
    std::string e = set.open(path, fd);
    if (!e.empty()) return e;
    const int dup = ::dup(fd);
    std::FILE* f = dup >= 0 ? ::fdopen(dup, "wb") : nullptr;
    if (!f) {
        if (dup >= 0) ::close(dup);
        return "cannot write " + path;
    }
    e = firefly_tools::write_png_preview(f, path, rgb, w, h, stride, exposure);
    if (std::fclose(f) != 0 && e.empty()) e = "write failed: " + path;
    return e;
}

json half_json(const half_report& h) {
    return json{{"pixels", h.pixels},       {"valid", h.valid},
                {"ignored", h.ignored},     {"nonfinite", h.nonfinite},
                {"negative_variance", h.negative_variance},
                {"median_sd", h.median},    {"mad_sd", h.mad},
                {"bound", h.bound},         {"outliers", h.outliers},
                {"highlights", h.highlights}, {"consistent", h.consistent},
                {"fireflies", h.fireflies}, {"repaired", h.repaired},
                {"phase1_rounds", h.phase1_rounds}, {"phase2_iterations", h.phase2_iterations},
                {"final_change", h.final_change}};
}

using clock_type = std::chrono::steady_clock;
double ms_since(clock_type::time_point t) { return std::chrono::duration<double, std::milli>(clock_type::now() - t).count(); }

// One frame's result: the outputs (written to temporaries, not yet renamed), the report
// record and the error, if any.
struct frame_result {
    firefly_tools::output_set outputs;
    json record;
    std::string error;
};

// Cleans a frame read into h[0], h[1] and writes its outputs to temporaries.
std::string clean_frame(const options& c, detector& d, const frame_files& f, half_data (&h)[2], frame_result& fr) {
    const int w = h[0].img.width, ht = h[0].img.height;
    const std::size_t np = static_cast<std::size_t>(w) * static_cast<std::size_t>(ht);
    half_buffer<float> hb[2];
    for (int i = 0; i < 2; ++i)
        if (std::string e = views_of(h[i], hb[i]); !e.empty()) return e;
    std::vector<std::uint8_t> mask[2];
    image_view<std::uint8_t> mv[2];
    for (int i = 0; i < 2 && !c.masks.empty(); ++i) {
        mask[i].assign(np, 0);
        mv[i] = *make_image_view(mask[i].data(), w, ht);
    }
    image before;  // the combined input, for the preview
    if (!c.preview.empty()) before = combine(h);
    const auto t1 = clock_type::now();
    const frame_report r = d.process(hb[0], hb[1], mv[0], mv[1]);
    const double process_ms = ms_since(t1);
    if (!r.error.ok() && r.error.code() == errc::no_valid_pixels)
        return std::string("no valid pixel to rebuild from (every pixel is NaN/Inf, black or an outlier): ") +
               r.error.message();
    if (!r.error.ok()) return std::string("cannot clean the frame: ") + r.error.message();
    for (int i = 0; i < 2; ++i)
        if (!r.half[i].reconstruction.ok())
            return std::string("half ") + "AB"[i] +
                   (r.half[i].reconstruction.code() == errc::no_valid_pixels
                        ? " has no valid pixel to rebuild from (every pixel is NaN/Inf, black or an outlier)"
                        : std::string(": reconstruction failed: ") + r.half[i].reconstruction.message());
    const auto t2 = clock_type::now();
    const image comb = combine(h);
    // The main output is opened first so that it is renamed last.
    std::string e = write_exr_to(fr.outputs, f.out, comb);
    for (int i = 0; i < 2 && e.empty() && !c.halves.empty(); ++i) e = write_exr_to(fr.outputs, f.halves[i], h[i].img);
    for (int i = 0; i < 2 && e.empty() && !c.masks.empty(); ++i)
        e = write_exr_to(fr.outputs, f.masks[i], mask_image(mask[i], comb));
    const std::size_t stride = comb.channels.size();
    if (e.empty() && !c.preview.empty()) e = write_png_to(fr.outputs, f.preview[0], before.pixels.data(), w, ht, stride, c.exposure);
    if (e.empty() && !c.preview.empty()) e = write_png_to(fr.outputs, f.preview[1], comb.pixels.data(), w, ht, stride, c.exposure);
    if (e.empty()) e = fr.outputs.close_all();
    if (!e.empty()) return e;
    fr.record["width"] = w;
    fr.record["height"] = ht;
    fr.record["both_outliers"] = r.both_outliers;
    fr.record["variance_calibration"] = r.variance_calibration;
    fr.record["lambdas_computed"] = r.lambdas_computed;
    fr.record["milliseconds"] = json{{"read", fr.record["milliseconds"]["read"]}, {"process", process_ms}, {"write", ms_since(t2)}};
    fr.record["a"] = half_json(r.half[0]);
    fr.record["b"] = half_json(r.half[1]);
    if (!c.quiet)
        std::printf("%s: %dx%d, fireflies %zu + %zu, highlights kept %zu, non-finite repaired %zu + %zu, %.1f ms\n",
                    f.out.c_str(), w, ht, r.half[0].fireflies, r.half[1].fireflies, r.half[0].highlights,
                    r.half[0].repaired, r.half[1].repaired, process_ms);
    return {};
}

// One frame: read, check, clean, write to temporaries. fr.error is empty on success.
void run_frame(const options& c, detector& d, long long frame, frame_result& fr) {
    const frame_files f = files_of(c, frame);
    fr.record = json{{"frame", frame}, {"half_a", f.a}, {"half_b", f.b}, {"output", f.out}};
    const auto t0 = clock_type::now();
    half_data h[2];
    fr.error = read_half(c, f.a, f.va, h[0]);
    if (fr.error.empty()) fr.error = read_half(c, f.b, f.vb, h[1]);
    if (fr.error.empty()) fr.error = check_halves(c, f, h);
    fr.record["milliseconds"]["read"] = ms_since(t0);
    if (fr.error.empty()) fr.error = clean_frame(c, d, f, h, fr);
    if (!fr.error.empty()) fr.outputs.discard();
}

json options_json(const options& c) {
    static const char* reductions[] = {"mean", "luminance", "max"};
    static const char* lambdas[] = {"exact", "hill", "normal"};
    static const char* rules[] = {"same_pixel", "agree", "confident", "confident_and_agree"};
    const auto& o = c.o;
    return json{{"significance", o.alpha},
                {"bound", o.bound_threshold},
                {"reduction", reductions[static_cast<int>(o.reduction) % 3]},
                {"lambdas", lambdas[static_cast<int>(o.lambdas) % 3]},
                {"highlight_rule", rules[static_cast<int>(o.highlight.rule) % 4]},
                {"max_relative_error", o.highlight.max_relative_error},
                {"max_ratio", o.highlight.max_ratio},
                {"min_excess_z", o.highlight.min_excess_z},
                {"cluster_relative_error", o.highlight.cluster_relative_error},
                {"kernel", o.reconstruction.kernel_width},
                {"sigma", o.reconstruction.sigma},
                {"tolerance", o.reconstruction.tolerance},
                {"iterations", o.reconstruction.max_iterations},
                {"threads", c.threads}};
}

// The report as text. Paths are not always UTF-8: invalid bytes become U+FFFD.
std::string report_text(const options& c, const json& frames, std::size_t failed) {
    const std::string version = std::to_string(FIREFLY_VERSION_MAJOR) + "." + std::to_string(FIREFLY_VERSION_MINOR) +
                                "." + std::to_string(FIREFLY_VERSION_PATCH);
    const json report{{"firefly", version},
                      {"options", options_json(c)},
                      {"frames", frames},
                      {"frames_failed", failed},
                      {"status", failed ? "failed" : "ok"}};
    return report.dump(2, ' ', false, json::error_handler_t::replace) + "\n";
}

void complain(const options& c, long long frame, const std::string& e) {
    if (c.sequence) std::fprintf(stderr, "firefly: frame %lld: %s\n", frame, e.c_str());
    else std::fprintf(stderr, "firefly: %s\n", e.c_str());
}

// Runs every frame; returns the exit code. The report's temporary is opened first, so an
// unwritable report is found before any output is written.
int run(const options& c) {
    firefly_tools::output_set report_set;
    int report_fd = -1;
    if (!c.report.empty())
        if (std::string e = report_set.open(c.report, report_fd); !e.empty()) {
            std::fprintf(stderr, "firefly: %s\n", e.c_str());
            return 1;
        }
    detector d(c.o, executor::threads(c.threads));
    json frames = json::array();
    std::size_t failed = 0;
    firefly_tools::output_set pending;  // a single frame's outputs wait for the report
    const long long first = c.sequence ? c.first : 0, last = c.sequence ? c.last : 0;
    const long long count = (last - first) / c.step + 1;
    long long index = 0;
    for (long long f = first; f <= last; f += c.step, ++index) {
        frame_result fr;
        run_frame(c, d, f, fr);
        if (fr.error.empty() && c.sequence) fr.error = fr.outputs.commit();
        if (!fr.error.empty()) {
            ++failed;
            fr.record["error"] = fr.error;
            complain(c, f, fr.error);
        }
        frames.push_back(fr.record);
        if (!c.sequence) pending = std::move(fr.outputs);
        if (c.sequence && !c.quiet) std::printf("  [%lld/%lld]%s\n", index + 1, count, fr.error.empty() ? "" : " failed");
    }
    std::string e;
    if (!c.report.empty()) {
        e = firefly_tools::write_all(report_fd, report_text(c, frames, failed), c.report);
        if (e.empty()) e = report_set.close_all();
    }
    if (e.empty()) e = pending.commit();
    if (e.empty()) e = report_set.commit();
    if (!e.empty()) {
        std::fprintf(stderr, "firefly: %s\n", e.c_str());
        return 1;
    }
    return failed ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
    // Readers check sizes before allocating; this catch is for the rest (an image that fits
    // the limits but not the machine's memory): one line and exit 1, never an abort.
    try {
        options c;
        bool done = false;
        std::string e = firefly_cli::parse(argc, argv, c, done);
        if (done) return 0;
        if (e.empty()) e = check_files(c);
        if (!e.empty()) {
            std::fprintf(stderr, "firefly: %s\n", e.c_str());
            return 2;
        }
        return run(c);
    } catch (const std::bad_alloc&) {
        std::fprintf(stderr, "firefly: out of memory\n");
    } catch (const std::exception& ex) {
        std::fprintf(stderr, "firefly: %s\n", ex.what());
    }
    return 1;
}
