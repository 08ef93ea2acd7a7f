// firefly: the command-line cleaner for real renderer output.
//
//   firefly half_a.exr half_b.exr -o clean.exr
//   firefly --buffers b_0.exr b_1.exr b_2.exr b_3.exr -o clean.exr
//   firefly --renders r_0.exr ... r_7.exr -o clean.exr
//   firefly beauty_a.####.exr beauty_b.####.exr --frames 1-240 -o clean.####.exr
//
// Reads the buffers of a frame: two half buffers or K buffers (colour R,G,B and the variance
// of each buffer's mean, Variance.R/G/B, the names pbrt-v4 and Blender write), or N colour-only
// renders with different seeds; optional alpha A. Two buffers are cleaned by firefly::detector,
// more by firefly::cross_buffer_detector (the same object: the first is inside the second). It
// writes the mean of the cleaned buffers with the variance of that mean (OpenEXR, or two PFM
// files, colour and variance, for an output named .pfm).
//
// Outputs: all files of a frame (-o, --halves, --masks, --preview; and --report for a single
// frame) are written to exclusive temporaries and renamed only when all are complete, so a
// failure leaves none of them; a frame's progress line follows its commit. An output that is
// an input, by file identity, two outputs of any frames that are one file and two inputs that
// are one file are refused before anything is written. A sequence goes on past a bad frame,
// records it in the report and exits 1 at the end.
#include <firefly/firefly.hpp>

#ifdef __GLIBC__
#include <malloc.h>
#endif

#include <atomic>
#include <chrono>
#include <functional>
#include <future>
#include <thread>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <new>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
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

using firefly_cli::input_mode;

// How files and messages name buffer i: _a/_b and HALF_A/HALF_B for two halves (as always),
// _0 ... _{K-1} for --buffers and --renders.
std::string buffer_suffix(const options& c, int i) {
    if (c.mode == input_mode::halves) return i ? "_b" : "_a";
    return "_" + std::to_string(i);
}
std::string input_label(const options& c, int i) {
    if (c.mode == input_mode::halves) return i ? "HALF_B" : "HALF_A";
    return (c.mode == input_mode::renders ? "render " : "buffer ") + std::to_string(i);
}
const char* inputs_noun(const options& c) {
    return c.mode == input_mode::halves ? "halves" : c.mode == input_mode::buffers ? "buffers" : "renders";
}

// Every file name of one frame.
struct frame_files {
    std::vector<std::string> in, var;        // one per buffer (var: PFM variance of a half, or empty)
    std::string out, out_variance, preview[2];  // outputs; empty when not asked for (out_variance: a PFM -o's)
    std::vector<std::string> halves, masks;  // one per buffer when asked for
};

// A PFM holds colour alone: the variance of a PFM output goes beside it, NAME_variance.pfm.
std::string pfm_variance_name(const std::string& out) {
    const std::size_t ext = out.size() - 4;  // ".pfm", any case
    return out.substr(0, ext) + "_variance" + out.substr(ext);
}

frame_files files_of(const options& c, long long frame) {
    auto p = [&](const std::string& s) { return c.sequence ? frame_path(s, frame) : s; };
    frame_files f;
    f.out = p(c.out);
    if (firefly_cli::ends_with_ci(f.out, ".pfm")) f.out_variance = pfm_variance_name(f.out);
    for (int i = 0; i < c.buffers(); ++i) {
        f.in.push_back(p(c.inputs[static_cast<std::size_t>(i)]));
        f.var.push_back(c.mode == input_mode::halves ? p(i ? c.var_b : c.var_a) : std::string());
        if (!c.halves.empty()) f.halves.push_back(p(c.halves) + buffer_suffix(c, i) + ".exr");
        if (!c.masks.empty()) f.masks.push_back(p(c.masks) + buffer_suffix(c, i) + ".exr");
    }
    if (!c.preview.empty()) {
        f.preview[0] = p(c.preview) + "_before.png";
        f.preview[1] = p(c.preview) + "_after.png";
    }
    return f;
}

using firefly_tools::file_id;
using id_map = std::map<file_id, std::string>;

// The identity of an existing file; false for a path that names none.
bool existing_id(const std::string& path, file_id& id) {
    return !path.empty() && firefly_tools::identify(path, id) && id.leaf.empty();
}

// Two inputs of one frame that are one file (same device and inode, whatever the spelling):
// the buffers' files and the halves' PFM variances alike.
std::string duplicate_input(const options& c, const frame_files& f) {
    std::vector<std::pair<std::string, std::string>> files;  // label, path
    for (std::size_t i = 0; i < f.in.size(); ++i) files.emplace_back(input_label(c, static_cast<int>(i)), f.in[i]);
    for (std::size_t i = 0; i < f.var.size(); ++i)
        if (!f.var[i].empty()) files.emplace_back(i ? "--variance-b" : "--variance-a", f.var[i]);
    std::map<file_id, std::size_t> seen;
    for (std::size_t i = 0; i < files.size(); ++i) {
        file_id id;
        if (!existing_id(files[i].second, id)) continue;
        const auto [it, fresh] = seen.emplace(id, i);
        if (!fresh)
            return files[it->second].first + " and " + files[i].first + " are the same file (" + files[it->second].second +
                   ", " + files[i].second + ")";
    }
    return {};
}

// An output name the final rename cannot take: an existing directory, device, FIFO or socket
// (a rename would replace the node itself: as root, -o /dev/null would replace the system's),
// or a name longer than its folder allows. Found before anything is written, so that a frame
// never fails half committed.
std::string output_target_problem(const std::string& path) {
    struct stat st {};
    if (::stat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode))
        return "output " + path + " exists and is not a regular file (a directory, device or pipe): refused";
    const long name_max = ::pathconf(firefly_tools::parent_dir(path).c_str(), _PC_NAME_MAX);
    const long limit = name_max > 0 ? name_max : 255;
    if (static_cast<long>(firefly_tools::leaf_name(path).size()) > limit)
        return "output name too long (over " + std::to_string(limit) + " bytes): " + firefly_tools::leaf_name(path);
    return {};
}

// An output that is an input of any frame, or an output already seen (`outs`: every output of
// the frames checked so far, so that outputs of different frames are compared too). `label`
// names the output in the message: its option, and its frame in a sequence.
std::string output_collision(const std::string& path, const std::string& label, const id_map& inputs,
                             id_map& outs) {
    if (path.empty()) return {};
    if (std::string e = output_target_problem(path); !e.empty()) return e;
    file_id id;
    if (!firefly_tools::identify(path, id)) return {};  // no such folder: the write will say so
    if (const auto in = inputs.find(id); in != inputs.end())
        return "output " + path + " is the input " + in->second + ": refused";
    const std::string named = path + " (" + label + ")";
    if (const auto o = outs.find(id); o != outs.end())
        return "outputs " + o->second + " and " + named + " are the same file";
    outs.emplace(id, named);
    return {};
}

// The outputs of one frame with their options (the report, one for the whole run, is not
// among them).
std::vector<std::pair<std::string, std::string>> frame_outputs(const frame_files& f) {
    std::vector<std::pair<std::string, std::string>> outs = {
        {"-o", f.out}, {"-o (its variance)", f.out_variance}, {"--preview", f.preview[0]}, {"--preview", f.preview[1]}};
    for (const std::string& p : f.halves) outs.emplace_back("--halves", p);
    for (const std::string& p : f.masks) outs.emplace_back("--masks", p);
    return outs;
}

// Refuses, before anything is written, two inputs of a frame that are one file, an output
// that is an input of any frame and two outputs (of any frames) that are one file.
std::string check_files(const options& c) {
    const long long first = c.sequence ? c.first : 0, last = c.sequence ? c.last : 0;
    id_map inputs;
    for (long long fr = first; fr <= last; fr += c.step) {
        const frame_files f = files_of(c, fr);
        if (std::string e = duplicate_input(c, f); !e.empty()) return e;
        for (const auto* list : {&f.in, &f.var})
            for (const std::string& p : *list) {
                file_id id;
                if (existing_id(p, id)) inputs.emplace(id, p);
            }
    }
    id_map outs;
    for (long long fr = first; fr <= last; fr += c.step)
        for (const auto& [flag, path] : frame_outputs(files_of(c, fr))) {
            const std::string label = c.sequence ? flag + ", frame " + std::to_string(fr) : flag;
            if (std::string e = output_collision(path, label, inputs, outs); !e.empty()) return e;
        }
    return output_collision(c.report, "--report", inputs, outs);
}

// One buffer of a frame as read: colour (3) [+ alpha] [+ variance (1 or 3)], interleaved.
struct buffer_data {
    image img;
    int nv = 0;  // variance channels; 0 for a render
    bool has_alpha = false;
};

// A PFM colour file, with its variance PFM when var_path is given (two halves).
std::string read_pfm_buffer(const std::string& path, const std::string& var_path, buffer_data& h) {
    firefly_tools::pfm_image col, var;
    std::string e = firefly_tools::read_pfm(path, col);
    if (e.empty() && !var_path.empty()) e = firefly_tools::read_pfm(var_path, var);
    if (!e.empty()) return e;
    if (col.channels != 3) return path + ": the colour PFM must have 3 channels";
    if (!var_path.empty() && (var.width != col.width || var.height != col.height))
        return var_path + ": variance and colour differ in size";
    h.nv = var_path.empty() ? 0 : var.channels;
    h.has_alpha = false;
    h.img = image{};
    h.img.width = col.width;
    h.img.height = col.height;
    h.img.channels = {"R", "G", "B"};
    // A PFM has no windows: it lies at the origin, as an EXR whose windows are its size there.
    h.img.data_window = h.img.display_window = {0, 0, col.width - 1, col.height - 1};
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

// One buffer: colour, alpha when present, and variance unless it is a render.
std::string read_buffer(const options& c, const std::string& path, const std::string& var_path, buffer_data& h) {
    if (firefly_cli::ends_with_ci(path, ".pfm")) return read_pfm_buffer(path, var_path, h);
    const std::vector<std::string> none;
    const std::vector<std::string>& variance = c.mode == input_mode::renders ? none : c.variance;
    h.nv = static_cast<int>(variance.size());
    auto names = [&](bool alpha) {
        std::vector<std::string> n = c.colour;
        if (alpha) n.push_back(c.alpha);
        n.insert(n.end(), variance.begin(), variance.end());
        return n;
    };
    // Alpha when asked for and present: read with it; when the only complaint is a missing
    // channel, read again without it (a missing colour or variance channel is then reported).
    h.has_alpha = false;
    if (c.use_alpha) {
        const std::string e = firefly_tools::read_exr(path, names(true), h.img);
        if (e.empty()) {
            h.has_alpha = true;
            return {};
        }
        if (e.find("missing channel") == std::string::npos) return e;
    }
    return firefly_tools::read_exr(path, names(false), h.img);
}

bool same_window(const firefly_tools::window& a, const firefly_tools::window& b) {
    return a.min_x == b.min_x && a.min_y == b.min_y && a.max_x == b.max_x && a.max_y == b.max_y;
}

std::string size_text(const image& m) { return std::to_string(m.width) + "x" + std::to_string(m.height); }

// The buffers must match the first in size, windows and channels; the messages name the files.
std::string check_buffers(const options& c, const frame_files& f, const std::vector<buffer_data>& h) {
    const std::string the = std::string("the ") + inputs_noun(c) + " differ in ";
    const image& a = h[0].img;
    for (std::size_t i = 1; i < h.size(); ++i) {
        const image& b = h[i].img;
        if (a.width != b.width || a.height != b.height)
            return the + "size: " + f.in[0] + " is " + size_text(a) + ", " + f.in[i] + " is " + size_text(b);
        if (!same_window(a.data_window, b.data_window) || !same_window(a.display_window, b.display_window))
            return the + "data or display window: " + f.in[0] + " and " + f.in[i];
        if (h[0].has_alpha != h[i].has_alpha) {
            const std::string& with = h[0].has_alpha ? f.in[0] : f.in[i];
            const std::string& without = h[0].has_alpha ? f.in[i] : f.in[0];
            return "alpha channel " + c.alpha + " is in " + with + " but not in " + without + " (--no-alpha ignores it)";
        }
        if (h[0].nv != h[i].nv) return the + "variance channels: " + f.in[0] + " and " + f.in[i];
    }
    return {};
}

// A view of n channels of an interleaved buffer, from channel `first`.
template <class T>
bool channel_view(buffer_data& h, int first, int n, image_view<T>& v) {
    const std::ptrdiff_t ps = static_cast<std::ptrdiff_t>(h.img.channel_count() * sizeof(float));
    auto r = image_view<T>::create(h.img.pixels.data() + first, h.img.width, h.img.height, n, ps);
    if (!r.ok()) return false;
    v = *r;
    return true;
}

// Two halves: colour, variance, alpha, as firefly::detector takes them.
std::string pair_views(buffer_data& h, half_buffer<float>& hb) {
    const int a = h.has_alpha ? 1 : 0;
    bool ok = channel_view(h, 0, 3, hb.color) && channel_view(h, 3 + a, h.nv, hb.variance);
    if (ok && a) ok = channel_view(h, 3, 1, hb.alpha);
    return ok ? std::string() : "internal: bad image layout";
}

// 3 or more buffers. A render's alpha goes to the detector as a 4th colour channel (carried
// along: checked for NaN/Inf and rebuilt with the colour). With variance it cannot (the
// detector wants 1 variance channel or one per colour channel), so there it is averaged as read.
std::string cross_views(buffer_data& h, buffer_view<float>& v) {
    const int a = h.has_alpha ? 1 : 0;
    bool ok = channel_view(h, 0, h.nv == 0 ? 3 + a : 3, v.color);
    if (ok && h.nv > 0) ok = channel_view(h, 3 + a, h.nv, v.variance);
    return ok ? std::string() : "internal: bad image layout";
}

// Mean of sample s over the buffers. Two keep the half-buffer mode's float formula
// 0.5 a + 0.5 b, bit for bit; more are summed in double.
float mean_at(const std::vector<buffer_data>& h, std::size_t s) {
    if (h.size() == 2) return 0.5f * h[0].img.pixels[s] + 0.5f * h[1].img.pixels[s];
    double sum = 0;
    for (const buffer_data& b : h) sum += b.img.pixels[s];
    return static_cast<float>(sum / static_cast<double>(h.size()));
}

// The variance of the mean of K buffers that each carry the variance of their own mean:
// sum / K^2, in double, so FLT_MAX variances stay finite (two halves: vA / 4 + vB / 4, as the
// half-buffer mode always wrote; 0.25f * (a + b) in float overflowed). Inf and NaN pass as is.
float summed_variance_at(const std::vector<buffer_data>& h, std::size_t s) {
    double sum = 0;
    for (const buffer_data& b : h) sum += b.img.pixels[s];
    const double k = static_cast<double>(h.size());
    return static_cast<float>(sum / (k * k));
}

// Renders carry no variance: that of their mean comes from their spread, the sample
// variance / N, in double.
float spread_variance_at(const std::vector<buffer_data>& h, std::size_t s) {
    const double n = static_cast<double>(h.size());
    double sum = 0, ss = 0;
    for (const buffer_data& b : h) sum += b.img.pixels[s];
    const double mean = sum / n;
    for (const buffer_data& b : h) ss += (b.img.pixels[s] - mean) * (b.img.pixels[s] - mean);
    return static_cast<float>(ss / (n - 1) / n);
}

// The output: the mean of the buffers and the variance of that mean; channels colour,
// variance (the inputs', or for renders --variance's names), alpha (averaged) if present.
image combine(const options& c, const std::vector<buffer_data>& h) {
    const buffer_data& first = h[0];
    const std::vector<std::string>& in = first.img.channels;
    const std::size_t a = first.has_alpha ? 1 : 0, nv = first.nv == 0 ? 3 : static_cast<std::size_t>(first.nv);
    const bool spread = first.nv == 0;
    image comb;
    comb.width = first.img.width;
    comb.height = first.img.height;
    comb.data_window = first.img.data_window;
    comb.display_window = first.img.display_window;
    comb.channels.assign(in.begin(), in.begin() + 3);
    if (spread) comb.channels.insert(comb.channels.end(), c.variance.begin(), c.variance.end());
    else comb.channels.insert(comb.channels.end(), in.begin() + 3 + a, in.begin() + 3 + a + nv);
    if (a) comb.channels.push_back(in[3]);
    const std::size_t in_stride = in.size(), out_stride = comb.channels.size();
    const std::size_t np = static_cast<std::size_t>(comb.width) * static_cast<std::size_t>(comb.height);
    comb.pixels.resize(np * out_stride);
    for (std::size_t i = 0; i < np; ++i) {
        const std::size_t s = i * in_stride;
        float* o = &comb.pixels[i * out_stride];
        for (std::size_t k = 0; k < 3; ++k) o[k] = mean_at(h, s + k);
        for (std::size_t k = 0; k < nv; ++k)
            o[3 + k] = spread ? spread_variance_at(h, s + k) : summed_variance_at(h, s + 3 + a + k);
        if (a) o[3 + nv] = mean_at(h, s + 3);
    }
    return comb;
}

// A mask file, one 0/1 channel per bit: firefly::detector's six for two buffers, the
// K-buffer detector's three (firefly, nonfinite, dropped) for more.
image mask_image(const std::vector<std::uint8_t>& mask, const image& like, bool pair) {
    static const char* const names[6] = {"firefly", "highlight", "consistent", "nonfinite", "energy", "dropped"};
    static const std::uint8_t bits[6] = {mask_bits::firefly, mask_bits::highlight, mask_bits::consistent,
                                         mask_bits::nonfinite, mask_bits::energy, mask_bits::dropped};
    const std::vector<std::size_t> used = pair ? std::vector<std::size_t>{0, 1, 2, 3, 4, 5} : std::vector<std::size_t>{0, 3, 5};
    image m;
    m.width = like.width;
    m.height = like.height;
    m.data_window = like.data_window;
    m.display_window = like.display_window;
    for (std::size_t b : used) m.channels.push_back(names[b]);
    const std::size_t n = used.size();
    m.pixels.resize(mask.size() * n);
    for (std::size_t k = 0; k < mask.size(); ++k)
        for (std::size_t j = 0; j < n; ++j) m.pixels[k * n + j] = (mask[k] & bits[used[j]]) ? 1.0f : 0.0f;
    return m;
}

std::string write_exr_to(firefly_tools::output_set& set, const std::string& path, const image& img) {
    int fd = -1;
    std::string e = set.open(path, fd);
    if (!e.empty()) return e;
    firefly_tools::fd_ostream os(fd, path);
    return firefly_tools::write_exr(os, img);
}

// Writes one output of the set through a stdio stream: write(FILE*) returns an error or "".
template <class Write>
std::string write_stream_to(firefly_tools::output_set& set, const std::string& path, Write write) {
    int fd = -1;
    std::string e = set.open(path, fd);
    if (!e.empty()) return e;
    const int dup = ::dup(fd);
    std::FILE* f = dup >= 0 ? ::fdopen(dup, "wb") : nullptr;
    if (!f) {
        if (dup >= 0) ::close(dup);
        return "cannot write " + path;
    }
    e = write(f);
    if (std::fclose(f) != 0 && e.empty()) e = "write failed: " + path;
    return e;
}

std::string write_png_to(firefly_tools::output_set& set, const std::string& path, const float* rgb, int w, int h,
                         std::size_t stride, float exposure) {
    return write_stream_to(set, path, [&](std::FILE* f) {
        return firefly_tools::write_png_preview(f, path, rgb, w, h, stride, exposure);
    });
}

// Channels [first, first + n) of img as a PFM (n: 1 or 3).
std::string write_pfm_to(firefly_tools::output_set& set, const std::string& path, const image& img, std::size_t first,
                         std::size_t n) {
    firefly_tools::pfm_image p;
    p.width = img.width;
    p.height = img.height;
    p.channels = static_cast<int>(n);
    const std::size_t stride = img.channels.size(), np = img.pixels.size() / stride;
    p.pixels.resize(np * n);
    for (std::size_t i = 0; i < np; ++i)
        for (std::size_t k = 0; k < n; ++k) p.pixels[i * n + k] = img.pixels[i * stride + first + k];
    return write_stream_to(set, path, [&](std::FILE* f) { return firefly_tools::write_pfm(f, path, p); });
}

// The main output: OpenEXR, or for a name ending .pfm colour there and the variance of the
// mean beside it. A PFM has no alpha and no windows, so a frame with alpha, or whose data
// window is not its display window at the origin, is refused rather than cut or moved.
std::string write_main_to(firefly_tools::output_set& set, const frame_files& f, const image& comb, bool alpha) {
    if (f.out_variance.empty()) return write_exr_to(set, f.out, comb);
    if (alpha) return "-o " + f.out + ": a PFM holds no alpha; name the output .exr, or give --no-alpha";
    const firefly_tools::window& d = comb.data_window;
    const firefly_tools::window& s = comb.display_window;
    const bool placed = d.min_x != 0 || d.min_y != 0 || d.min_x != s.min_x || d.min_y != s.min_y ||
                        d.max_x != s.max_x || d.max_y != s.max_y;
    if (placed && !d.empty() && !s.empty())
        return "-o " + f.out + ": a PFM holds no data or display window, and this frame's data window is not its "
               "display window at the origin; name the output .exr";
    std::string e = write_pfm_to(set, f.out, comb, 0, 3);
    return e.empty() ? write_pfm_to(set, f.out_variance, comb, 3, comb.channels.size() - 3) : e;
}

json half_json(const half_report& h) {
    return json{{"pixels", h.pixels},       {"valid", h.valid},
                {"ignored", h.ignored},     {"nonfinite", h.nonfinite},
                {"dropped", h.dropped},     {"implausible", h.implausible},
                {"negative_variance", h.negative_variance},
                {"median_sd", h.median},    {"mad_sd", h.mad},
                {"bound", h.bound},         {"outliers", h.outliers},
                {"highlights", h.highlights}, {"consistent", h.consistent},
                {"fireflies", h.fireflies}, {"repaired", h.repaired},
                {"phase1_rounds", h.phase1_rounds}, {"phase2_iterations", h.phase2_iterations},
                {"final_change", h.final_change}};
}

// The counts every mode reports, in the K-buffer detector's terms.
void put_counts(json& rec, const cross_buffer_report& r) {
    rec["buffers"] = r.buffers;
    rec["pixels"] = r.pixels;
    rec["tested"] = r.tested;
    rec["fireflies"] = r.fireflies;
    rec["nonfinite"] = r.nonfinite;
    rec["dropped"] = r.dropped;
    rec["implausible"] = r.implausible;
    rec["left"] = r.left;
    rec["per_buffer"] = r.per_buffer;
    rec["energy_removed"] = r.energy_removed;
    rec["energy_returned"] = r.energy_returned;
}

// Two halves' report in those terms (as cross_buffer_detector does for K = 2).
cross_buffer_report pair_counts(const frame_report& r) {
    cross_buffer_report c;
    c.buffers = 2;
    c.pixels = r.half[0].pixels;
    c.tested = r.half[0].valid;
    for (const half_report& h : r.half) {
        c.fireflies += h.fireflies;
        c.nonfinite += h.nonfinite;
        c.dropped += h.dropped;
        c.implausible += h.implausible;
        c.left += h.unreachable;
        c.per_buffer.push_back(h.found());
        c.energy_removed += h.energy_removed;
        c.energy_returned += h.energy_returned;
    }
    return c;
}

using mask_list = std::vector<std::vector<std::uint8_t>>;

image_view<std::uint8_t> mask_view(std::vector<std::uint8_t>& m, const image& like) {
    return *make_image_view(m.data(), like.width, like.height);
}

// Two buffers: firefly::detector (the one inside the K-buffer detector, whose lambda cache
// serves the whole sequence), with alpha. Fills the report record and the progress text.
std::string clean_pair(detector& d, std::vector<buffer_data>& h, mask_list& masks, json& rec, std::string& line) {
    half_buffer<float> hb[2];
    image_view<std::uint8_t> mv[2];
    for (std::size_t i = 0; i < 2; ++i) {
        if (std::string e = pair_views(h[i], hb[i]); !e.empty()) return e;
        if (!masks.empty()) mv[i] = mask_view(masks[i], h[i].img);
    }
    const frame_report r = d.process(hb[0], hb[1], mv[0], mv[1]);
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
    rec["both_outliers"] = r.both_outliers;
    rec["variance_calibration"] = r.variance_calibration;
    rec["lambdas_computed"] = r.lambdas_computed;
    rec["a"] = half_json(r.half[0]);
    rec["b"] = half_json(r.half[1]);
    put_counts(rec, pair_counts(r));
    char text[160];
    std::snprintf(text, sizeof text, "fireflies %zu + %zu, highlights kept %zu, repaired (non-finite, dropped, implausible) %zu + %zu",
                  r.half[0].fireflies, r.half[1].fireflies, r.half[0].highlights, r.half[0].repaired, r.half[1].repaired);
    line = text;
    return {};
}

// 3 or more buffers: firefly::cross_buffer_detector.
std::string clean_cross(const options& c, cross_buffer_detector& xd, std::vector<buffer_data>& h, mask_list& masks,
                        json& rec, std::string& line) {
    std::vector<buffer_view<float>> views(h.size());
    std::vector<image_view<std::uint8_t>> mv;
    for (std::size_t i = 0; i < h.size(); ++i) {
        if (std::string e = cross_views(h[i], views[i]); !e.empty()) return e;
        if (!masks.empty()) mv.push_back(mask_view(masks[i], h[i].img));
    }
    const cross_buffer_report r = xd.process(views, mv);
    if (r.left > 0)
        return std::to_string(r.left) + " pixels have NaN/Inf, a dropped (black) bucket or implausible values in more than half of the " +
               inputs_noun(c) + ": nothing to rebuild them from";
    if (!r.ok()) return std::string("cannot clean the frame: ") + r.error.message();
    put_counts(rec, r);
    line = "fireflies " + std::to_string(r.fireflies) + " (per " + (c.mode == input_mode::renders ? "render" : "buffer") + ":";
    for (std::size_t n : r.per_buffer) line += " " + std::to_string(n);
    line += "), non-finite repaired " + std::to_string(r.nonfinite);
    if (r.implausible > 0) line += ", implausible repaired " + std::to_string(r.implausible);
    return {};
}

// Writes a cleaned frame's files to temporaries: the main output first, so that it is
// renamed last.
std::string write_outputs(const options& c, const frame_files& f, const std::vector<buffer_data>& h,
                          const mask_list& masks, const image& before, firefly_tools::output_set& set) {
    const image comb = combine(c, h);
    std::string e = write_main_to(set, f, comb, h[0].has_alpha);
    for (std::size_t i = 0; i < f.halves.size() && e.empty(); ++i) e = write_exr_to(set, f.halves[i], h[i].img);
    for (std::size_t i = 0; i < f.masks.size() && e.empty(); ++i)
        e = write_exr_to(set, f.masks[i], mask_image(masks[i], comb, h.size() == 2));
    const std::size_t stride = comb.channels.size();
    const int w = comb.width, ht = comb.height;
    if (e.empty() && !c.preview.empty()) e = write_png_to(set, f.preview[0], before.pixels.data(), w, ht, stride, c.exposure);
    if (e.empty() && !c.preview.empty()) e = write_png_to(set, f.preview[1], comb.pixels.data(), w, ht, stride, c.exposure);
    if (e.empty()) e = set.close_all();
    return e;
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

// A frame's inputs, read and checked. The files of a frame are read in parallel, and the
// next frame while this one is cleaned, when --threads allows (errors in file order either way).
struct frame_input {
    frame_files files;
    std::vector<buffer_data> h;
    std::string error;
    double read_ms = 0;
};

frame_input read_frame(const options& c, long long frame) {
    frame_input in{files_of(c, frame), {}, {}, 0};
    const auto t0 = clock_type::now();
    const std::size_t n = in.files.in.size();
    in.h.resize(n);
    std::vector<std::string> errors(n);
    std::atomic<std::size_t> next{0};
    auto worker = [&] {
        for (std::size_t i; (i = next.fetch_add(1)) < n;) errors[i] = read_buffer(c, in.files.in[i], in.files.var[i], in.h[i]);
    };
    std::vector<std::thread> pool;
    for (unsigned t = 1; t < std::min<std::size_t>(c.threads, n); ++t) pool.emplace_back(worker);
    worker();
    for (std::thread& t : pool) t.join();
    for (const std::string& e : errors)
        if (!e.empty()) {
            in.error = e;
            break;
        }
    if (in.error.empty()) in.error = check_buffers(c, in.files, in.h);
    in.read_ms = ms_since(t0);
    return in;
}

// A frame between its steps: read, cleaned, written to temporaries (with threads, in the
// background while the next frame is cleaned), then committed in frame order.
struct frame_job {
    long long frame = 0, index = 0;
    frame_input in;
    mask_list masks;
    image before;  // the mean of the inputs, for the preview
    frame_result fr;
    std::string line;
    double process_ms = 0;
};

// Cleans the frame read into j.in: the buffers in place, the masks, the record.
std::string clean_frame(const options& c, cross_buffer_detector& xd, frame_job& j) {
    std::vector<buffer_data>& h = j.in.h;
    const image& first = h[0].img;
    const std::size_t np = static_cast<std::size_t>(first.width) * static_cast<std::size_t>(first.height);
    j.masks.assign(c.masks.empty() ? 0 : h.size(), std::vector<std::uint8_t>(c.masks.empty() ? 0 : np, 0));
    if (!c.preview.empty()) j.before = combine(c, h);
    j.fr.record["width"] = first.width;
    j.fr.record["height"] = first.height;
    const auto t1 = clock_type::now();
    std::string e = h.size() == 2 ? clean_pair(xd.pair_detector(), h, j.masks, j.fr.record, j.line)
                                  : clean_cross(c, xd, h, j.masks, j.fr.record, j.line);
    j.process_ms = ms_since(t1);
    return e;
}

// One frame, read: clean. fr.error is empty on success.
void run_frame(const options& c, cross_buffer_detector& xd, frame_job& j) {
    const frame_files& f = j.in.files;
    json& rec = j.fr.record;
    rec = json{{"frame", j.frame}};
    if (c.mode == input_mode::halves) {
        rec["half_a"] = f.in[0];
        rec["half_b"] = f.in[1];
    } else {
        rec["inputs"] = f.in;
    }
    rec["output"] = f.out;
    if (!f.out_variance.empty()) rec["output_variance"] = f.out_variance;
    j.fr.error = j.in.error;
    rec["milliseconds"]["read"] = j.in.read_ms;
    if (j.fr.error.empty()) j.fr.error = clean_frame(c, xd, j);
}

// Writes a cleaned frame's outputs to temporaries (nothing for a failed frame).
void write_frame(const options& c, frame_job& j) {
    if (j.fr.error.empty()) {
        const auto t2 = clock_type::now();
        j.fr.error = write_outputs(c, j.in.files, j.in.h, j.masks, j.before, j.fr.outputs);
        j.fr.record["milliseconds"] = json{
            {"read", j.in.read_ms}, {"process", j.process_ms}, {"write", ms_since(t2)}};
    }
    if (!j.fr.error.empty()) j.fr.outputs.discard();
}

// A frame's progress line: printed once its outputs are committed, never for a frame that
// leaves none.
void print_progress(const options& c, const frame_job& j) {
    if (c.quiet || !j.fr.error.empty()) return;
    const image& first = j.in.h[0].img;
    std::printf("%s: %dx%d, %s, %.1f ms\n", j.in.files.out.c_str(), first.width, first.height, j.line.c_str(),
                j.process_ms);
}

// The options of the detector that ran: firefly::detector's for two buffers, the K-buffer
// detector's for more.
json options_json(const options& c) {
    static const char* reductions[] = {"mean", "luminance", "max"};
    static const char* lambdas[] = {"exact", "hill", "normal"};
    static const char* rules[] = {"same_pixel", "agree", "confident", "confident_and_agree"};
    static const char* modes[] = {"halves", "buffers", "renders"};
    json j{{"mode", modes[static_cast<int>(c.mode)]}, {"buffers", c.buffers()}};
    if (c.buffers() > 2) {
        j["significance"] = c.o.alpha;
        j["false_alarm"] = c.x.false_alarm;
        j["radius"] = c.x.radius;
        j["use_variance"] = c.x.use_variance;
        j["refine_noise"] = c.x.refine_noise;
        j["return_energy"] = c.x.return_energy;
        j["find_dropped"] = c.x.find_dropped;
        j["find_implausible"] = c.x.find_implausible;
        j["energy_sigma"] = c.x.energy_sigma;
        j["energy_coarse_sigma"] = c.x.energy_coarse_sigma;
        j["energy_density_evidence"] = c.x.energy_density_evidence;
        j["threads"] = c.threads;
        return j;
    }
    const auto& o = c.o;
    j.update(json{{"significance", o.alpha},
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
                  {"return_energy", o.return_energy},
                  {"find_dropped", o.find_dropped},
                  {"find_implausible", o.find_implausible},
                  {"energy_sigma", o.energy_sigma},
                  {"energy_coarse_sigma", o.energy_coarse_sigma},
                  {"energy_density_evidence", o.energy_density_evidence},
                  {"threads", c.threads}});
    return j;
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
    cross_buffer_options xo = c.x;
    xo.alpha = c.o.alpha;
    xo.pair = c.o;
    cross_buffer_detector xd(xo, executor::threads(c.threads));
    json frames = json::array();
    std::size_t failed = 0;
    firefly_tools::output_set pending;  // a single frame's outputs wait for the report
    const long long first = c.sequence ? c.first : 0, last = c.sequence ? c.last : 0;
    const long long count = (last - first) / c.step + 1;
    long long index = 0;
    firefly_tools::set_exr_threads(c.threads);
    // With threads, the next frame is read while this one is cleaned, and the previous one is
    // written meanwhile.
    const auto policy = c.threads > 1 ? std::launch::async : std::launch::deferred;
    std::future<frame_input> ahead = std::async(policy, read_frame, std::cref(c), first);
    // A written frame is committed (or its error recorded) in frame order.
    auto settle = [&](frame_job& j) {
        frame_result& fr = j.fr;
        if (fr.error.empty() && c.sequence) fr.error = fr.outputs.commit();
        if (c.sequence) print_progress(c, j);
        if (!fr.error.empty()) {
            ++failed;
            fr.record["error"] = fr.error;
            complain(c, j.frame, fr.error);
        }
        frames.push_back(fr.record);
        if (!c.sequence) pending = std::move(fr.outputs);
        if (c.sequence && !c.quiet) std::printf("  [%lld/%lld]%s\n", j.index + 1, count, fr.error.empty() ? "" : " failed");
    };
    std::unique_ptr<frame_job> previous;
    std::future<void> writing;  // the previous frame's outputs
    for (long long f = first; f <= last; f += c.step, ++index) {
        auto job = std::make_unique<frame_job>();
        job->frame = f;
        job->index = index;
        job->in = ahead.get();
        if (f <= last - c.step) ahead = std::async(policy, read_frame, std::cref(c), f + c.step);
        run_frame(c, xd, *job);
        if (writing.valid()) {
            writing.get();
            settle(*previous);
        }
        frame_job* j = job.get();
        writing = std::async(policy, [&c, j] { write_frame(c, *j); });
        previous = std::move(job);
    }
    if (writing.valid()) {
        writing.get();
        settle(*previous);
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
    if (!c.sequence) print_progress(c, *previous);
    return failed ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
#ifdef __GLIBC__
    // A frame's buffers (tens of MB each) come back every frame: kept in the heap instead of
    // mapped and unmapped each time, they cost no fresh page faults after the first frame.
    mallopt(M_MMAP_THRESHOLD, 1 << 30);
    mallopt(M_TRIM_THRESHOLD, 1 << 30);
#endif
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
