// The command line of `firefly`, parsed with CLI11: every number is checked for its form
// (a whole number where one is wanted, finite) and its range before it is used.
#pragma once

#include <CLI/CLI.hpp>
#include <firefly/firefly.hpp>

#include <cerrno>
#include <cfloat>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "image_io.hpp"

namespace firefly_cli {

// Where the buffers of a frame come from: two half buffers (positional HALF_A HALF_B),
// --buffers (K files with variance) or --renders (N colour-only renders with different seeds).
enum class input_mode { halves, buffers, renders };

struct options {
    input_mode mode = input_mode::halves;
    std::vector<std::string> inputs;  // one path (or '#' pattern) per buffer
    std::string out, halves, masks, report, preview;
    float exposure = 1.0f;
    std::string var_a, var_b;  // PFM variance files
    std::vector<std::string> colour = {"R", "G", "B"};
    std::vector<std::string> variance = {"Variance.R", "Variance.G", "Variance.B"};
    std::string alpha = "A";
    bool use_alpha = true, quiet = false;
    bool sequence = false;
    long long first = 0, last = 0, step = 1;
    firefly::detector_options o;       // two buffers: firefly::detector
    firefly::cross_buffer_options x;   // 3 or more: firefly::cross_buffer_detector (x.pair unused)
    unsigned threads = 1;
    int buffers() const { return static_cast<int>(inputs.size()); }
};

// firefly::cross_buffer_detector's limits: without variance the noise comes from the spread of
// the buffers, and it refuses fewer than 3 buffers without variance ("2 buffers need
// variance"); it takes at most 64.
inline constexpr int min_renders = 3;
inline constexpr int max_buffers = 64;

// Option groups: the two-half detector's options mean nothing to the K-buffer one and the
// other way round; giving one to the wrong detector is refused rather than ignored.
inline const char* const pair_group = "two-half detector (HALF_A HALF_B, or --buffers with 2 files)";
inline const char* const cross_group = "K-buffer detector (--renders, or --buffers with 3 or more files)";

// Frame numbers and counts the tool accepts: far from any overflow of `long long`.
inline constexpr long long max_frame = 999999999;
inline constexpr long long max_frames = 1000000;

inline bool ends_with_ci(const std::string& s, const char* suffix) {
    const std::size_t n = std::strlen(suffix);
    if (s.size() < n) return false;
    for (std::size_t i = 0; i < n; ++i)
        if (std::tolower(static_cast<unsigned char>(s[s.size() - n + i])) != suffix[i]) return false;
    return true;
}

inline std::vector<std::string> split(const std::string& s) {
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

// A whole decimal number (optional sign, digits only) within [lo, hi].
inline bool parse_whole(const std::string& s, long long lo, long long hi, long long& v) {
    if (s.empty() || s.size() > 19) return false;
    std::size_t i = (s[0] == '-' || s[0] == '+') ? 1 : 0;
    if (i == s.size()) return false;
    for (std::size_t k = i; k < s.size(); ++k)
        if (s[k] < '0' || s[k] > '9') return false;
    errno = 0;
    char* end = nullptr;
    v = std::strtoll(s.c_str(), &end, 10);
    return errno == 0 && *end == '\0' && v >= lo && v <= hi;
}

// FIRST-LAST[:STEP]; FIRST may be negative.
inline std::string parse_frames(const std::string& s, options& c) {
    const char* form = "--frames wants FIRST-LAST or FIRST-LAST:STEP with FIRST <= LAST, frame numbers within "
                       "+-999999999 and at most 1000000 frames";
    const std::size_t dash = s.find('-', 1);
    if (dash == std::string::npos) return form;
    const std::size_t colon = s.find(':', dash);
    long long f = 0, l = 0, st = 1;
    if (!parse_whole(s.substr(0, dash), -max_frame, max_frame, f) ||
        !parse_whole(s.substr(dash + 1, colon == std::string::npos ? std::string::npos : colon - dash - 1), -max_frame,
                     max_frame, l) ||
        (colon != std::string::npos && !parse_whole(s.substr(colon + 1), 1, max_frame, st)) || l < f ||
        (l - f) / st + 1 > max_frames)
        return form;
    c.sequence = true;
    c.first = f;
    c.last = l;
    c.step = st;
    return {};
}

// Validators: a finite number in a range (open or closed ends), a whole number in a range.
// A default as --help shows it (8, 32, 1e-04).
inline std::string number_text(double v) {
    char text[32];
    std::snprintf(text, sizeof text, "%g", v);
    return text;
}

inline CLI::Validator number_in(double lo, double hi, bool open_lo, bool open_hi, const std::string& what) {
    return CLI::Validator(
        [=](std::string& s) -> std::string {
            char* end = nullptr;
            errno = 0;
            const double v = std::strtod(s.c_str(), &end);
            // ERANGE with a result no larger than DBL_MIN is an underflow (a denormal or 0): the
            // number as near as a double holds it. An overflow (HUGE_VAL) stays refused.
            const bool in_range = errno == 0 || (errno == ERANGE && std::fabs(v) <= DBL_MIN);
            const bool ok = !s.empty() && *end == '\0' && in_range && std::isfinite(v) &&
                            (open_lo ? v > lo : v >= lo) && (open_hi ? v < hi : v <= hi);
            return ok ? std::string() : "wants " + what + ", not '" + s + "'";
        },
        "");
}
inline CLI::Validator whole_in(long long lo, long long hi, const std::string& what) {
    return CLI::Validator(
        [=](std::string& s) -> std::string {
            long long v = 0;
            return parse_whole(s, lo, hi, v) ? std::string() : "wants " + what + ", not '" + s + "'";
        },
        "");
}

const char* const description =
    "Removes fireflies from a Monte Carlo render and writes the cleaned image. The input is one of:\n"
    "  two half buffers (each holding half of every pixel's samples) with per-pixel variance:\n"
    "    firefly half_a.exr half_b.exr -o clean.exr\n"
    "  K >= 2 buffers with variance (K = 2 is the same as two halves):\n"
    "    firefly --buffers b_0.exr b_1.exr b_2.exr b_3.exr -o clean.exr\n"
    "  N >= 3 colour-only renders of one frame with different seeds (EXR or PFM):\n"
    "    firefly --renders r_0.exr r_1.exr r_2.exr r_3.exr r_4.exr r_5.exr r_6.exr r_7.exr -o clean.exr\n"
    "  a sequence: '#' runs in every path, e.g.\n"
    "    firefly beauty_a.####.exr beauty_b.####.exr --frames 1-240 -o clean.####.exr\n"
    "The output is the mean of the cleaned buffers and the variance of that mean: the sum of the\n"
    "buffers' variances / K^2, or for renders their sample variance / N.\n";

const char* const footer =
    "Outputs: every file of a frame is first written to an exclusive temporary in its folder and\n"
    "renamed only when all of them are complete; a failure leaves none of them. An output that is\n"
    "an input, two outputs that are one file (in any frames), two inputs that are one file (under\n"
    "any names), an output that is a directory, device or pipe, an input that is not a regular\n"
    "file, an empty option value, and a sequence's --halves, --masks or --preview without '#' are\n"
    "refused. A replaced output keeps its permission bits. A sequence goes on past a bad frame,\n"
    "reports it (stderr and --report) and exits 1 at the end.\n";

// An option taking one of a few words (name -> value).
template <class E>
void add_choice(CLI::App& app, const char* name, E& target, const std::map<std::string, E>& values, const char* text,
                const char* group) {
    std::string words, current;
    for (const auto& kv : values) {
        words += (words.empty() ? "" : ", ") + kv.first;
        if (kv.second == target) current = kv.first;
    }
    app.add_option_function<std::string>(
           name, [&target, values](const std::string& s) { target = values.at(s); }, text)
        ->check(CLI::Validator(
            [values, words](std::string& s) {
                return values.count(s) ? std::string() : "wants one of " + words + ", not '" + s + "'";
            },
            ""))
        ->default_str(current)
        ->type_name("WORD")
        ->group(group);
}

// What the command line names before it is checked: inputs as given, and the texts parsed later.
struct raw_args {
    std::vector<std::string> positional, buffers, renders;
    std::string frames, channels, variance;
};

inline void add_io_options(CLI::App& app, options& c, raw_args& r) {
    app.add_option("inputs", r.positional,
                   "OpenEXR files, one per half: colour and variance channels (PFM colour files work too, with "
                   "--variance-a/--variance-b)")
        ->type_name("HALF_A HALF_B")
        ->group("inputs");
    app.add_option("--buffers", r.buffers,
                   "K = 2 to 64 OpenEXR files of one frame, each with colour and the variance of its mean "
                   "(--channels, --variance); every file after it is a buffer")
        ->type_name("FILE...")
        ->group("inputs");
    app.add_option("--renders", r.renders,
                   "N = 3 to 64 colour-only renders of one frame with different seeds (OpenEXR or PFM); every "
                   "file after it is a render; the output's variance channels are named by --variance")
        ->type_name("FILE...")
        ->group("inputs");
    app.add_option("--channels", r.channels, "colour channel names (three; in a multi-part EXR, PART.NAME where two parts hold NAME)")->type_name("NAMES")->default_str("R,G,B")->group("inputs");
    app.add_option("--variance", r.variance, "variance channel names (1 or 3; --renders: 3, written to the output)")->type_name("NAMES")
        ->default_str("Variance.R,Variance.G,Variance.B")
        ->group("inputs");
    app.add_option("--alpha-channel", c.alpha, "alpha channel; used when present")->type_name("NAME")->group("inputs");
    app.add_flag_callback("--no-alpha", [&c] { c.use_alpha = false; }, "ignore alpha even when present")->group("inputs");
    app.add_option("--variance-a", c.var_a, "variance PFM file of half A (PFM colour inputs)")->type_name("FILE")->group("inputs");
    app.add_option("--variance-b", c.var_b, "variance PFM file of half B (PFM colour inputs)")->type_name("FILE")->group("inputs");
    app.add_option("--frames", r.frames,
                   "FIRST-LAST[:STEP] frame sequence: '#' runs in every path become the frame number, zero-padded "
                   "to the run's length")->type_name("FIRST-LAST[:STEP]")
        ->group("inputs");
    app.add_option("-o,--output", c.out, "the mean of the cleaned buffers: OpenEXR (colour, Variance.* of the mean, alpha), or for a "
                   "NAME.pfm colour there and the variance in NAME_variance.pfm (no alpha: --no-alpha)")->type_name("FILE")->group("outputs");
    app.add_option("--halves", c.halves,
                   "also write the cleaned buffers: PREFIX_a.exr and PREFIX_b.exr (two halves), PREFIX_0.exr ... "
                   "(--buffers, --renders)")->type_name("PREFIX")->group("outputs");
    app.add_option("--masks", c.masks,
                   "also write masks, named as --halves: channels firefly, highlight, consistent, nonfinite, energy, "
                   "dropped (0 or 1) for two buffers; firefly, nonfinite, dropped for 3 or more")->type_name("PREFIX")
        ->group("outputs");
    app.add_option("--report", c.report,
                   "JSON report: options, per-frame counts (buffers, pixels, tested, fireflies, nonfinite, dropped, "
                   "implausible, left, "
                   "per_buffer; two halves also per half), timings and errors")->type_name("FILE")->group("outputs");
    app.add_option("--preview", c.preview,
                   "PNG previews PREFIX_before.png (mean of the inputs), PREFIX_after.png (the output), sRGB")->type_name("PREFIX")->group("outputs");
    app.add_option("--exposure", c.exposure, "preview exposure multiplier")->type_name("X")
        ->check(number_in(0, 1e30, true, false, "a positive number"))
        ->group("outputs");
    app.add_flag("-q,--quiet", c.quiet, "no progress lines")->group("outputs");
}

inline void add_detector_options(CLI::App& app, options& c) {
    const char* g = pair_group;
    auto& o = c.o;
    app.add_option("--significance", o.alpha,
                   "the frame's significance: the generalized ESD's alpha, and the level of the frame-level "
                   "decision on one-half and K-buffer fireflies (a frame without fireflies is left alone in "
                   "1 - X of cases)")
        ->type_name("X")->check(number_in(firefly::min_alpha, 1, false, true, "a number in [1e-280, 1)"))->group("detector (every mode)");
    app.add_flag_callback("--no-energy-return", [&c] { c.o.return_energy = c.x.return_energy = false; },
                          "remove fireflies only: do not give back the energy of fireflies that fell densely "
                          "(firefly/energy.hpp)")
        ->group("detector (every mode)");
    app.add_flag_callback("--keep-black", [&c] { c.o.find_dropped = c.x.find_dropped = false; },
                          "leave pixels black in one buffer as they are, even where the others show they "
                          "cannot be black by chance (a bucket or render written black; firefly/dropped.hpp)")
        ->group("detector (every mode)");
    app.add_flag_callback("--keep-implausible", [&c] { c.o.find_implausible = c.x.find_implausible = false; },
                          "leave finite values as they are, even where the other buffers show no estimate can "
                          "hold them (a bucket of 1e30 with a sane variance; firefly/implausible.hpp)")
        ->group("detector (every mode)");
    app.add_option_function<double>("--energy-sigma", [&c](double v) { c.o.energy_sigma = c.x.energy_sigma = v; },
                                    "width in pixels of the energy return's Gaussian")
        ->type_name("X")
        ->default_str(number_text(c.o.energy_sigma))
        ->check(number_in(1, 64, false, false, "a number from 1 to 64"))
        ->group("detector (every mode)");
    app.add_option_function<double>("--energy-coarse-sigma",
                                    [&c](double v) { c.o.energy_coarse_sigma = c.x.energy_coarse_sigma = v; },
                                    "width in pixels of the energy return's wider scale, used where sparse fireflies "
                                    "agree with it (0: none; not above --energy-sigma: none)")
        ->type_name("X")
        ->default_str(number_text(c.o.energy_coarse_sigma))
        ->check(number_in(0, 0, false, false, "0") | number_in(2, 256, false, false, "a number from 2 to 256"))
        ->group("detector (every mode)");
    app.add_option_function<double>("--energy-density-evidence",
                                    [&c](double v) { c.o.energy_density_evidence = c.x.energy_density_evidence = v; },
                                    "the energy return's finest scale: removed light given back where it fell, where "
                                    "more than X equal removed samples agree (both halves', or the buffers' pooled; a "
                                    "bokeh disc lit by rare samples; 0: none; default 8 for two halves, 0 for 3 or more "
                                    "buffers)")
        ->type_name("X")
        ->check(number_in(0, 0, false, false, "0") | number_in(1, 1e6, false, false, "a number from 1 to 1e6"))
        ->group("detector (every mode)");
    app.add_option("--bound", o.bound_threshold, "modified Z-score threshold")->type_name("X")->check(number_in(0, 1e30, false, false, "a number >= 0"))->group(g);
    add_choice(app, "--reduction", o.reduction,
               std::map<std::string, firefly::variance_reduction>{{"mean", firefly::variance_reduction::mean},
                                                                  {"luminance", firefly::variance_reduction::luminance},
                                                                  {"max", firefly::variance_reduction::max}},
               "channel variances to one number: mean, luminance or max", g);
    add_choice(app, "--lambdas", o.lambdas,
               std::map<std::string, firefly::lambda_method>{{"exact", firefly::lambda_method::exact},
                                                             {"hill", firefly::lambda_method::hill},
                                                             {"normal", firefly::lambda_method::normal}},
               "Student-t method for the critical values: exact, hill or normal", g);
    add_choice(app, "--highlight-rule", o.highlight.rule,
               std::map<std::string, firefly::highlight_rule>{
                   {"same_pixel", firefly::highlight_rule::same_pixel},
                   {"agree", firefly::highlight_rule::agree},
                   {"confident", firefly::highlight_rule::confident},
                   {"confident_and_agree", firefly::highlight_rule::confident_and_agree}},
               "same_pixel, agree, confident or confident_and_agree", g);
    app.add_option("--max-relative-error", o.highlight.max_relative_error, "confident rule threshold")->type_name("X")->check(number_in(0, 1e30, false, false, "a number >= 0"))->group(g);
    app.add_option("--max-ratio", o.highlight.max_ratio, "agree rule factor")->type_name("X")->check(number_in(1, 1e30, false, false, "a number >= 1"))->group(g);
    app.add_option("--min-excess-z", o.highlight.min_excess_z, "one-half outliers must exceed the other half by X sd; 0: off")->type_name("X")
        ->check(number_in(0, 1e30, false, false, "a number >= 0"))->group(g);
    app.add_option("--cluster-relative-error", o.highlight.cluster_relative_error,
                   "confident rule bound for pixels next to another both-half outlier; 0: off")
        ->type_name("X")->check(number_in(0, 1e30, false, false, "a number >= 0"))->group(g);
    app.add_option("--kernel", o.reconstruction.kernel_width, "reconstruction kernel width, odd, 3 to 63")->type_name("N")
        ->check(whole_in(3, 63, "an odd whole number from 3 to 63") &
                CLI::Validator([](std::string& s) { return std::atoll(s.c_str()) % 2 ? "" : "wants an odd whole number, not '" + s + "'"; }, ""))
        ->group(g);
    app.add_option("--sigma", o.reconstruction.sigma, "reconstruction Gaussian sigma (>= 0.1)")->type_name("X")->check(number_in(0.1, 1e30, false, false, "a number >= 0.1"))->group(g);
    app.add_option("--tolerance", o.reconstruction.tolerance, "phase 2 relative tolerance")->type_name("X")->check(number_in(0, 1e30, false, false, "a number >= 0"))->group(g);
    app.add_option("--iterations", o.reconstruction.max_iterations, "phase 2 iteration cap")->type_name("N")
        ->check(whole_in(0, 1000000, "a whole number from 0 to 1000000"))->group(g);
    app.add_option("--threads", c.threads, "threads; results are identical for any count")->type_name("N")
        ->check(whole_in(1, 256, "a whole number from 1 to 256"))->group("detector (every mode)");
}

inline void add_cross_options(CLI::App& app, options& c) {
    app.add_option("--false-alarm", c.x.false_alarm,
                   "the per-pixel level's cap: at most this share of pixel-buffers flagged in a frame dense "
                   "with fireflies that are not")
        ->type_name("X")
        ->check(number_in(0, 0.5, true, true, "a number in (0, 0.5)"))
        ->group(cross_group);
    app.add_option("--radius", c.x.radius, "the noise is pooled over (2 N + 1)^2 pixels")
        ->type_name("N")
        ->check(whole_in(1, 8, "a whole number from 1 to 8"))
        ->group(cross_group);
    app.add_flag_callback("--no-refine-noise", [&c] { c.x.refine_noise = false; },
                          "pool the neighbours' noise with their flagged buffers (no second look next to "
                          "fireflies found at the cap: faster where fireflies are dense, misses more there)")
        ->group(cross_group);
    app.add_flag("--use-variance", c.x.use_variance,
                 "--buffers with 4 or more files: the noise from the files' variances instead of the spread of "
                 "the buffers (3 files always use them)")
        ->group(cross_group);
}

// Channel names must be distinct: a colour, variance or alpha channel read twice would be
// written twice.
inline std::string check_channel_names(const options& c) {
    std::set<std::string> seen;
    std::vector<std::string> all = c.colour;
    all.insert(all.end(), c.variance.begin(), c.variance.end());
    if (c.use_alpha) all.push_back(c.alpha);
    for (const auto& n : all) {
        if (n.empty()) return "empty channel name in --channels, --variance or --alpha-channel";
        if (!seen.insert(n).second)
            return "channel " + n + " is named twice (--channels, --variance and --alpha-channel must differ)";
    }
    return {};
}

// The input mode and its files: positional halves, --buffers or --renders, never mixed.
inline std::string choose_inputs(options& c, const raw_args& r) {
    const bool buffers = !r.buffers.empty(), renders = !r.renders.empty();
    if (buffers && renders) return "--buffers and --renders cannot be combined";
    if (!buffers && !renders) {
        if (r.positional.size() != 2) return "expected two inputs, HALF_A and HALF_B (firefly --help)";
        c.mode = input_mode::halves;
        c.inputs = r.positional;
        return {};
    }
    const std::string flag = buffers ? "--buffers" : "--renders";
    if (!r.positional.empty())
        return flag + " cannot be mixed with positional inputs (" + r.positional[0] +
               "): give every file after " + flag;
    c.mode = buffers ? input_mode::buffers : input_mode::renders;
    c.inputs = buffers ? r.buffers : r.renders;
    const int k = c.buffers();
    if (renders && k < min_renders)
        return "--renders needs at least " + std::to_string(min_renders) + " renders, got " + std::to_string(k) +
               " (two buffers need variance channels: use --buffers or two half buffers)";
    if (buffers && k < 2) return "--buffers needs at least 2 files, got " + std::to_string(k);
    if (k > max_buffers) return flag + " takes at most " + std::to_string(max_buffers) + " files, got " + std::to_string(k);
    return {};
}

// Two halves, PFM or OpenEXR each: a PFM half takes its variance from its --variance-a/-b
// file, an OpenEXR half from its own channels (a variance file beside it would be ignored).
inline std::string check_half_variances(const options& c) {
    for (int i = 0; i < 2; ++i) {
        const std::string flag = i ? "--variance-b" : "--variance-a";
        const std::string& half = c.inputs[static_cast<std::size_t>(i)];
        const bool pfm = ends_with_ci(half, ".pfm"), given = !(i ? c.var_b : c.var_a).empty();
        if (pfm && !given)
            return "PFM inputs hold colour only: give " + flag + " (the variance PFM of " + half + ")";
        if (!pfm && given)
            return flag + " goes with a PFM half only: " + half + " is OpenEXR and holds its own variance channels";
    }
    return {};
}

// Options that belong to one mode only.
inline std::string check_mode_options(const options& c) {
    const bool halves = c.mode == input_mode::halves, renders = c.mode == input_mode::renders;
    const bool pfm_variance = !c.var_a.empty() || !c.var_b.empty();
    bool pfm = false;
    for (const auto& p : c.inputs) pfm = pfm || ends_with_ci(p, ".pfm");
    if (pfm_variance && !(halves && pfm))
        return "--variance-a and --variance-b go with PFM half buffers (HALF_A HALF_B) only";
    if (halves && pfm)
        if (std::string e = check_half_variances(c); !e.empty()) return e;
    if (c.mode == input_mode::buffers && pfm)
        return "--buffers reads OpenEXR files with colour and variance channels (a PFM holds colour only: "
               "--renders takes colour-only files)";
    if (renders && c.variance.size() != 3)
        return "--renders writes one variance channel per colour channel: --variance wants three names";
    if (c.x.use_variance && !(c.mode == input_mode::buffers && c.buffers() >= 4))
        return "--use-variance needs --buffers with at least 4 files (renders carry no variance, 3 buffers "
               "always use it, 2 go to the two-half detector)";
    return {};
}

// A sequence reads and writes one set of files per frame: every input path needs '#'.
inline std::string check_sequence_paths(const options& c) {
    if (!c.sequence) return {};
    if (c.out.find('#') == std::string::npos) return "--frames needs '#' in the output name too, e.g. clean.####.exr";
    std::vector<std::string> paths = c.inputs;
    for (const auto* v : {&c.var_a, &c.var_b})
        if (!v->empty()) paths.push_back(*v);
    for (const auto& p : paths)
        if (p.find('#') == std::string::npos)
            return "--frames needs '#' in every input path: " + p + " has none (it would be read for every frame)";
    const std::pair<const char*, const std::string*> prefixes[] = {
        {"--halves", &c.halves}, {"--masks", &c.masks}, {"--preview", &c.preview}};
    for (const auto& [flag, prefix] : prefixes)
        if (!prefix->empty() && prefix->find('#') == std::string::npos)
            return std::string("--frames needs '#' in ") + flag + " too: " + *prefix +
                   " has none (every frame would overwrite the last)";
    return {};
}

// Checks across options, after parsing.
inline std::string check_parsed(options& c, const raw_args& r) {
    if (!r.channels.empty() && (c.colour = split(r.channels)).size() != 3) return "--channels wants three names, e.g. R,G,B";
    if (!r.variance.empty()) {
        c.variance = split(r.variance);
        if (c.variance.size() != 1 && c.variance.size() != 3) return "--variance wants one or three names";
    }
    if (std::string e = check_channel_names(c); !e.empty()) return e;
    if (std::string e = choose_inputs(c, r); !e.empty()) return e;
    if (c.out.empty()) return "no output: give -o FILE";
    if (!c.preview.empty() && !firefly_tools::have_png())
        return "--preview needs PNG support: rebuild with libpng-dev installed";
    if (const firefly::status st = firefly::check_options(c.o); !st.ok()) return std::string("bad option: ") + st.message();
    if (const firefly::status st = firefly::check_cross_buffer_options(c.x); !st.ok())
        return std::string("bad option: ") + st.message();
    if (std::string e = check_mode_options(c); !e.empty()) return e;
    return check_sequence_paths(c);
}

// An option given on the command line for the detector that will not run.
inline std::string check_option_groups(const CLI::App& app, const options& c) {
    const bool pair = c.buffers() == 2;
    const std::string unused = pair ? cross_group : pair_group;
    for (const CLI::Option* o : app.get_options())
        if (o->count() > 0 && o->get_group() == unused)
            return o->get_name() + " is an option of the " + (pair ? "K-buffer" : "two-half") + " detector, which " +
                   (pair ? "2 buffers do not use" : "--renders and --buffers with 3 or more files do not use");
    return {};
}

// An option given an empty value: refused, never taken for "not given" (--frames '' would
// run one frame, --report '' write no report).
inline std::string check_empty_values(const CLI::App& app) {
    for (const CLI::Option* o : app.get_options())
        for (const std::string& v : o->results()) {
            if (!v.empty()) continue;
            if (o->get_positional() && o->get_lnames().empty()) return "an input file name is empty";
            std::string wanted = o->get_type_name();  // FILE, NAMES, ...; FILE... for a list
            if (wanted.size() > 3 && wanted.compare(wanted.size() - 3, 3, "...") == 0)
                wanted.resize(wanted.size() - 3);
            return o->get_name() + " wants " + wanted + ", not an empty value";
        }
    return {};
}

// Parses the command line. Returns the complaint (one line) or empty; `done` is set when
// --help or --version was answered.
inline std::string parse(int argc, char** argv, options& c, bool& done) {
    CLI::App app(description, "firefly");
    app.footer(footer);
    app.option_defaults()->always_capture_default();
    app.get_formatter()->column_width(34);
    raw_args r;
    bool version = false;
    add_io_options(app, c, r);
    add_detector_options(app, c);
    add_cross_options(app, c);
    app.add_flag("--version", version, "print the version");
    try {
        app.parse(argc, argv);
    } catch (const CLI::CallForHelp&) {
        std::fputs(app.help().c_str(), stdout);
        done = true;
        return {};
    } catch (const CLI::ExtrasError& e) {
        return std::string("unknown option or extra argument: ") + e.what() + " (firefly --help lists them)";
    } catch (const CLI::ParseError& e) {
        return e.what();
    }
    if (std::string e = check_empty_values(app); !e.empty()) return e;
    if (version) {
        std::printf("firefly %d.%d.%d\n", FIREFLY_VERSION_MAJOR, FIREFLY_VERSION_MINOR, FIREFLY_VERSION_PATCH);
        done = true;
        return {};
    }
    if (!r.frames.empty())
        if (std::string e = parse_frames(r.frames, c); !e.empty()) return e;
    if (std::string e = check_parsed(c, r); !e.empty()) return e;
    return check_option_groups(app, c);
}

}  // namespace firefly_cli
