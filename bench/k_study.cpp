// firefly_k_study: how the K-buffer result grows with K at a fixed total sample count, and
// what each K costs a renderer in memory (the tables are docs/k_study.md).
//
//   firefly_k_study OUT.md [--size WxH] [--seeds N] [--totals T1,T2,...]
//
// sim::simulate_buffers splits a scene's 2 x spp samples per pixel over the K buffers (the
// first 2 spp mod K buffers get one more), so spp = total / 2 keeps the total the same at
// every K and only the way it is split changes. Each frame is cleaned by the mean of the K
// buffers, median of means (M = K; M = 4 too where K >= 8), G-MoN (M = K) at each threshold of
// {0.1, 0.25, 0.4} (bench/peers.hpp, the estimators bench_accuracy.cpp runs), and
// firefly::cross_buffer_detector twice: at its default options (the energy return of
// energy.hpp on) and with return_energy = false (and pair.return_energy = false: K = 2 hands
// the pair to firefly::detector, variance required, whose own return it is). K = 3 needs the
// variances, K >= 4 gets colour only,
// because its default (use_variance = false) judges from the spread of the buffers and a
// renderer need not keep variance for it (the memory section checks that the output is the
// same with them). relMSE is sim::relmse against the expected radiance, as in the accuracy
// bench; "highlights not lowered" counts highlight pixels whose mean colour did not go down,
// as bench_accuracy.cpp's highlight_not_lowered (the energy return changes pixels only by
// adding light). The Markdown goes to stdout and to OUT.md.
#include <firefly/firefly.hpp>
#include <firefly/sim/metrics.hpp>
#include <firefly/sim/scene.hpp>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <new>
#include <string>
#include <tuple>
#include <vector>

#include "peers.hpp"

// ---------------------------------------------------------------------------------------
// Heap accounting: the detector's own scratch is measured, not guessed. Every operator new
// records its size in a 16-byte header (malloc's alignment), so live and peak bytes are the
// bytes requested, the same unit as the formulas they are compared with.
namespace heap {
std::atomic<std::size_t> live{0}, peak{0};
constexpr std::size_t header = 16;

void* allocate(std::size_t n) noexcept {
    auto* p = static_cast<unsigned char*>(std::malloc(n + header));
    if (!p) return nullptr;
    std::memcpy(p, &n, sizeof n);
    const std::size_t now = live.fetch_add(n) + n;
    std::size_t seen = peak.load();
    while (now > seen && !peak.compare_exchange_weak(seen, now)) {}
    return p + header;
}
void release(void* q) noexcept {
    if (!q) return;
    auto* p = static_cast<unsigned char*>(q) - header;
    std::size_t n;
    std::memcpy(&n, p, sizeof n);
    live.fetch_sub(n);
    std::free(p);
}
void* allocate_or_throw(std::size_t n) {
    if (void* p = allocate(n)) return p;
    throw std::bad_alloc();
}
}  // namespace heap

void* operator new(std::size_t n) { return heap::allocate_or_throw(n); }
void* operator new[](std::size_t n) { return heap::allocate_or_throw(n); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept { return heap::allocate(n); }
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept { return heap::allocate(n); }
void operator delete(void* p) noexcept { heap::release(p); }
void operator delete[](void* p) noexcept { heap::release(p); }
void operator delete(void* p, std::size_t) noexcept { heap::release(p); }
void operator delete[](void* p, std::size_t) noexcept { heap::release(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { heap::release(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { heap::release(p); }

using namespace firefly;

namespace {

// Peak heap growth while f runs, and what stays allocated after it.
struct heap_use {
    std::size_t peak = 0, kept = 0;
};
template <class F>
heap_use measure_heap(F&& f) {
    const std::size_t before = heap::live.load();
    heap::peak.store(before);
    f();
    return {heap::peak.load() - before, heap::live.load() - before};
}

// ---------------------------------------------------------------------------------------
// Setup.

struct study {
    int w = 512, h = 270, seeds = 3;
    std::vector<int> totals = {128, 32};
    std::vector<int> ks = {2, 3, 4, 8, 16};
    std::vector<std::string> scenes = {"caustics",   "interior",         "dense10",      "highlights",
                                       "production", "sparse_fireflies", "null_k4_spp64"};
    std::string out;
    std::size_t pixels() const { return static_cast<std::size_t>(w) * static_cast<std::size_t>(h); }
};

bool parse_args(int argc, char** argv, study& s) {
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        const bool has_value = i + 1 < argc;
        if (a == "--size" && has_value) {
            if (std::sscanf(argv[++i], "%dx%d", &s.w, &s.h) != 2 || s.w < 16 || s.h < 16) return false;
        } else if (a == "--seeds" && has_value) {
            s.seeds = std::atoi(argv[++i]);
            if (s.seeds < 1) return false;
        } else if (a == "--totals" && has_value) {
            s.totals.clear();
            for (const char* p = argv[++i]; *p; ++p) {
                s.totals.push_back(std::atoi(p));
                while (p[1] && *p != ',') ++p;
            }
        } else if (s.out.empty() && a[0] != '-') {
            s.out = a;
        } else {
            return false;
        }
    }
    // Every buffer gets at least 2 samples in the simulator: a total below 2 K would not be
    // the same total at every K.
    for (int t : s.totals)
        if (t < 2 * s.ks.back() || t % 2) return false;
    return !s.out.empty() && !s.totals.empty();
}

// The scene at `total` samples per pixel over all buffers. The null scene keeps its law
// (gamma, shape 4); only its sample count follows the total.
sim::scene make_scene(const std::string& name, const study& s, int total, int seed) {
    sim::scene sc = sim::named_scene(name, s.w, s.h, static_cast<std::uint64_t>(seed));
    sc.spp = total / 2;
    return sc;
}

std::string label(const std::string& name) {
    return name.rfind("null_k4", 0) == 0 ? "null (gamma shape 4, no fireflies)" : name;
}

// ---------------------------------------------------------------------------------------
// One frame.

constexpr std::array<double, 3> gmon_thresholds = {0.1, 0.25, 0.4};

// One cleaning method on one frame (NaN: not measured). Shares are of all pixels, or of the
// highlight pixels (NaN when the scene has none).
struct method_result {
    double relmse = NAN;
    double majority = NAN;        // the part of relmse from pixels with fireflies in more than K / 2 buffers
    double changed = NAN;         // share of pixels changed
    double hl_kept = NAN;         // share of highlight pixels unchanged
    double hl_not_lowered = NAN;  // share of highlight pixels whose mean colour did not go down
    double ms = NAN;              // process() wall clock
    bool ok = true;
};

enum method { m_firefly, m_plain, m_gmon, m_mean, method_count };
constexpr const char* method_names[method_count] = {"firefly", "firefly, no energy return", "G-MoN", "mean"};

struct frame_result {
    method_result ff, ff_plain, mean;  // firefly at its defaults, with return_energy = false
    std::array<method_result, 3> gmon{};
    double mon_k = 0, mon_4 = NAN;
    bool plain_same = false;  // ff_plain's buffers bit-identical to ff's
};

firefly_peers::buffer_list buffer_list(const sim::buffers& b) {
    firefly_peers::buffer_list l;
    for (const auto& c : b.color) l.push_back(c.data());
    return l;
}

bool has_highlights(const std::vector<std::uint8_t>& highlight) {
    return std::any_of(highlight.begin(), highlight.end(), [](std::uint8_t v) { return v != 0; });
}

// As bench_accuracy.cpp: changed when a channel moved by more than float round-off (the
// estimators sum in other orders); NaN against NaN is unchanged.
bool pixel_changed(const float* out, const float* in) {
    for (int c = 0; c < 3; ++c) {
        if (out[c] == in[c] || (std::isnan(out[c]) && std::isnan(in[c]))) continue;
        if (!(std::fabs(out[c] - in[c]) <= 1e-6f * std::fabs(in[c]))) return true;
    }
    return false;
}

double mean_colour(const float* p) { return (static_cast<double>(p[0]) + p[1] + p[2]) / 3.0; }

// As bench_accuracy.cpp's highlight_not_lowered: highlight pixels whose mean colour in `out`
// is not below `in`'s beyond 1e-6 relative (a non-finite input counts as not lowered). The
// energy return only adds light, so a highlight it touches is changed but not lowered.
double highlights_not_lowered(const std::vector<float>& out, const std::vector<float>& in,
                              const std::vector<std::uint8_t>& highlight) {
    std::size_t hl = 0, kept = 0;
    for (std::size_t p = 0; p < highlight.size(); ++p) {
        if (!highlight[p]) continue;
        ++hl;
        const double o = mean_colour(&out[p * 3]), i = mean_colour(&in[p * 3]);
        kept += !std::isfinite(i) || o >= i - 1e-6 * std::fabs(i);
    }
    return hl ? static_cast<double>(kept) / static_cast<double>(hl) : NAN;
}

// A one-image method against its input (the mean): pixels changed, highlights unchanged and
// not lowered.
void compare_to_input(const std::vector<float>& out, const std::vector<float>& in,
                      const std::vector<std::uint8_t>& highlight, method_result& m) {
    std::size_t n = 0, hl = 0, hl_kept = 0;
    for (std::size_t p = 0; p < highlight.size(); ++p) {
        const bool c = pixel_changed(&out[p * 3], &in[p * 3]);
        n += c;
        hl += highlight[p] != 0;
        hl_kept += highlight[p] && !c;
    }
    m.changed = static_cast<double>(n) / static_cast<double>(highlight.size());
    m.hl_kept = hl ? static_cast<double>(hl_kept) / static_cast<double>(hl) : NAN;
    m.hl_not_lowered = highlights_not_lowered(out, in, highlight);
}

// The mean, median of means and G-MoN; `mean` is also the input the others are compared to.
void run_estimators(const sim::buffers& b, int k, frame_result& r) {
    const firefly_peers::buffer_list bl = buffer_list(b);
    const std::size_t np = b.pixels();
    std::vector<float> mean(np * 3), out(np * 3);
    firefly_peers::mean_of_buffers(bl, np, mean.data());
    r.mean.relmse = sim::relmse(mean.data(), b.expected.data(), np);
    firefly_peers::median_of_means(bl, np, k, out.data());
    r.mon_k = sim::relmse(out.data(), b.expected.data(), np);
    if (k >= 8) {
        firefly_peers::median_of_means(bl, np, 4, out.data());
        r.mon_4 = sim::relmse(out.data(), b.expected.data(), np);
    }
    for (std::size_t t = 0; t < gmon_thresholds.size(); ++t) {
        firefly_peers::gmon(bl, np, k, gmon_thresholds[t], out.data());
        r.gmon[t].relmse = sim::relmse(out.data(), b.expected.data(), np);
        compare_to_input(out, mean, b.highlight, r.gmon[t]);
    }
}

// Copies of a frame's buffers and the views the detector cleans in place.
struct buffer_copy {
    std::vector<std::vector<float>> color, variance;
    std::vector<buffer_view<float>> views;
    buffer_copy(const sim::buffers& b, bool with_variance) : color(b.color) {
        if (with_variance) variance = b.variance;
        for (std::size_t i = 0; i < color.size(); ++i) {
            buffer_view<float> v{*make_image_view(color[i].data(), b.width, b.height, 3), {}};
            if (with_variance) v.variance = *make_image_view(variance[i].data(), b.width, b.height, 3);
            views.push_back(v);
        }
    }
};

// The detector's defaults: variance where it is required (K <= 3), none beyond.
bool default_variance(int k) { return k <= 3; }

cross_buffer_options without_return() {
    cross_buffer_options o;
    o.return_energy = false;
    o.pair.return_energy = false;  // K = 2: the half-buffer detector's own
    return o;
}

bool same_bits(const std::vector<std::vector<float>>& a, const std::vector<std::vector<float>>& b) {
    if (a.size() != b.size()) return false;
    for (std::size_t i = 0; i < a.size(); ++i)
        if (a[i].size() != b[i].size() || std::memcmp(a[i].data(), b[i].data(), a[i].size() * sizeof(float)) != 0)
            return false;
    return true;
}

// Share of pixels where any buffer changed.
double buffers_changed(const sim::buffers& b, const std::vector<std::vector<float>>& cleaned) {
    std::size_t n = 0;
    for (std::size_t p = 0; p < b.pixels(); ++p) {
        bool c = false;
        for (std::size_t i = 0; i < cleaned.size() && !c; ++i)
            c = std::memcmp(&b.color[i][p * 3], &cleaned[i][p * 3], 3 * sizeof(float)) != 0;
        n += c;
    }
    return static_cast<double>(n) / static_cast<double>(b.pixels());
}

// The part of a combined image's relMSE that comes from pixels where more than K / 2 buffers
// received a firefly: for K >= 3 the detector flags at most floor(K / 2) buffers of a pixel
// (the others must outvote them), so these are the ones it cannot clean by design.
double majority_hit_error(const sim::buffers& b, const std::vector<float>& combined) {
    const std::size_t np = b.pixels();
    std::vector<float> part(np * 3), ref(np * 3);
    for (std::size_t p = 0; p < np; ++p) {
        int hits = 0;
        for (int i = 0; i < b.count(); ++i) hits += b.firefly(i, p) > 0;
        const bool majority = hits > b.count() / 2;
        for (int c = 0; c < 3; ++c) {  // elsewhere output = reference: no error
            ref[p * 3 + c] = b.expected[p * 3 + c];
            part[p * 3 + c] = majority ? combined[p * 3 + c] : ref[p * 3 + c];
        }
    }
    return sim::relmse(part.data(), ref.data(), np);
}

// One detector's pass over a copy of the frame; `input` is the combined image of the
// uncleaned buffers, `cleaned` receives the cleaned colour.
method_result run_firefly(cross_buffer_detector& det, const sim::buffers& b, int k, const std::vector<float>& input,
                          std::vector<std::vector<float>>& cleaned) {
    buffer_copy work(b, default_variance(k));
    method_result m;
    const auto t0 = std::chrono::steady_clock::now();
    const cross_buffer_report rep = det.process(work.views);
    const auto t1 = std::chrono::steady_clock::now();
    m.ms = std::chrono::duration<double, std::milli>(t1 - t0).count();
    m.ok = rep.ok();
    const sim::accuracy a = sim::evaluate_buffers(b, work.color);  // relMSE of the spp-weighted mean
    const std::vector<float> combined = sim::combine(b, work.color);
    m.relmse = a.relmse;
    m.majority = majority_hit_error(b, combined);
    m.changed = buffers_changed(b, work.color);
    m.hl_kept = has_highlights(b.highlight) ? a.highlight_kept : NAN;
    m.hl_not_lowered = highlights_not_lowered(combined, input, b.highlight);
    cleaned = std::move(work.color);
    return m;
}

// One detector per K and option set, kept over every frame as a renderer keeps it.
struct detector_pair {
    cross_buffer_detector with_return, without{without_return()};
};

frame_result run_frame(detector_pair& d, const sim::buffers& b, int k) {
    frame_result r;
    run_estimators(b, k, r);
    const std::vector<float> input = sim::combine(b, b.color);
    std::vector<std::vector<float>> with, without;
    r.ff = run_firefly(d.with_return, b, k, input, with);
    r.ff_plain = run_firefly(d.without, b, k, input, without);
    r.plain_same = same_bits(with, without);
    return r;
}

// ---------------------------------------------------------------------------------------
// Results over seeds.

struct cell {
    std::vector<frame_result> seeds;
    int spp_min = 0, spp_max = 0;
};

template <class F>
double mean_over(const cell& c, F f) {
    double s = 0;
    for (const frame_result& r : c.seeds) s += f(r);
    return s / static_cast<double>(c.seeds.size());
}

// G-MoN's threshold with the lowest relMSE averaged over the seeds (chosen after the fact:
// the most favourable choice for G-MoN).
std::size_t best_gmon(const cell& c) {
    std::size_t best = 0;
    for (std::size_t t = 1; t < gmon_thresholds.size(); ++t)
        if (mean_over(c, [&](const frame_result& r) { return r.gmon[t].relmse; }) <
            mean_over(c, [&](const frame_result& r) { return r.gmon[best].relmse; }))
            best = t;
    return best;
}

const method_result& of(const frame_result& r, int m, std::size_t gmon_t) {
    switch (m) {
        case m_firefly: return r.ff;
        case m_plain: return r.ff_plain;
        case m_gmon: return r.gmon[gmon_t];
        default: return r.mean;
    }
}

// A method's field averaged over the seeds (G-MoN at its best threshold).
double avg(const cell& c, int m, double method_result::*field) {
    const std::size_t g = best_gmon(c);
    return mean_over(c, [&](const frame_result& r) { return of(r, m, g).*field; });
}

// The fastest seed's time: the machine may be shared, and other work only ever adds time.
double fastest(const cell& c, int m) {
    double t = INFINITY;
    for (const frame_result& r : c.seeds) t = std::min(t, of(r, m, 0).ms);
    return t;
}

int errors(const cell& c, int m) {
    int n = 0;
    for (const frame_result& r : c.seeds) n += !of(r, m, 0).ok;
    return n;
}

double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    const std::size_t n = v.size();
    return n == 0 ? NAN : n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

using key = std::tuple<int, std::string, int>;  // total, scene, K
using results = std::map<key, cell>;

// One detector pair per K, kept over every frame as a renderer keeps it (its caches warm up).
void run_all(const study& s, results& res) {
    std::map<int, detector_pair> detectors;
    for (int total : s.totals)
        for (const std::string& name : s.scenes)
            for (int k : s.ks)
                for (int seed = 1; seed <= s.seeds; ++seed) {
                    const sim::buffers b = sim::simulate_buffers(make_scene(name, s, total, seed), k);
                    cell& c = res[{total, name, k}];
                    c.spp_min = *std::min_element(b.spp.begin(), b.spp.end());
                    c.spp_max = *std::max_element(b.spp.begin(), b.spp.end());
                    c.seeds.push_back(run_frame(detectors[k], b, k));
                    const frame_result& r = c.seeds.back();
                    std::fprintf(stderr, "total %d %s K=%d seed %d: firefly %.4g (%.1f ms), no return %.4g (%.1f ms)\n",
                                 total, name.c_str(), k, seed, r.ff.relmse, r.ff.ms, r.ff_plain.relmse, r.ff_plain.ms);
                }
}

// ---------------------------------------------------------------------------------------
// Memory per K.

// sample_accumulator's state per pixel, from its members: per buffer a uint32 count, mean and
// M2 in double per channel, and the float colour and variance views finish() writes.
double accumulator_formula(int k, int channels) {
    return k * (sizeof(std::uint32_t) + 2.0 * channels * sizeof(double) + 2.0 * channels * sizeof(float));
}

double accumulator_measured(int k, int channels) {
    sample_accumulator acc;
    const int w = 64, h = 32;
    if (!acc.reset(w, h, k, channels).ok()) return NAN;
    return static_cast<double>(acc.bytes()) / (w * h);
}

struct memory_row {
    int k = 0;
    double accumulator_formula = 0, accumulator_bytes = 0;
    double peak = 0, kept = 0;              // per pixel, the largest over the scenes (default options)
    double plain_peak = 0, plain_kept = 0;  // the same with return_energy = false
    double pair_scratch = 0;      // K = 2: firefly::detector::scratch_bytes(), largest over the scenes
    bool variance_neutral = true;  // K >= 4: the output is bit-identical with the variances given
};

// Heap of a fresh detector's first frame (its largest: later frames of the size reuse it).
heap_use detector_heap(const sim::buffers& b, int k, const cross_buffer_options& o) {
    buffer_copy work(b, default_variance(k));
    cross_buffer_detector det(o);
    return measure_heap([&] { (void)det.process(work.views); });
}

// The half-buffer detector K = 2 delegates to, by its own account of its scratch.
double pair_scratch(const sim::buffers& b) {
    buffer_copy work(b, true);
    detector det;
    const half_buffer<float> a{work.views[0].color, work.views[0].variance, {}};
    const half_buffer<float> o{work.views[1].color, work.views[1].variance, {}};
    (void)det.process(a, o);
    return static_cast<double>(det.scratch_bytes());
}

bool same_with_variance(const sim::buffers& b) {
    buffer_copy without(b, false), with(b, true);
    cross_buffer_detector d1, d2;
    (void)d1.process(without.views);
    (void)d2.process(with.views);
    return same_bits(without.color, with.color);
}

void add_heap(double& peak, double& kept, const heap_use& u, double np) {
    peak = std::max(peak, static_cast<double>(u.peak) / np);
    kept = std::max(kept, static_cast<double>(u.kept) / np);
}

memory_row measure_memory(const study& s, int k) {
    const double np = static_cast<double>(s.pixels());
    memory_row m;
    m.k = k;
    m.accumulator_formula = accumulator_formula(k, 3);
    m.accumulator_bytes = accumulator_measured(k, 3);
    for (const std::string& name : s.scenes) {
        const sim::buffers b = sim::simulate_buffers(make_scene(name, s, s.totals.front(), 1), k);
        add_heap(m.peak, m.kept, detector_heap(b, k, {}), np);
        add_heap(m.plain_peak, m.plain_kept, detector_heap(b, k, without_return()), np);
        if (k == 2) m.pair_scratch = std::max(m.pair_scratch, pair_scratch(b) / np);
        if (k >= 4) m.variance_neutral = m.variance_neutral && same_with_variance(b);
    }
    return m;
}

// ---------------------------------------------------------------------------------------
// Markdown.

std::string fmt(const char* f, ...) {
    va_list ap, again;
    va_start(ap, f);
    va_copy(again, ap);
    std::string out(static_cast<std::size_t>(std::max(std::vsnprintf(nullptr, 0, f, ap), 0)), '\0');
    va_end(ap);
    std::vsnprintf(out.data(), out.size() + 1, f, again);
    va_end(again);
    return out;
}

std::string num(double v) { return std::isnan(v) ? "-" : fmt("%.4g", v); }
std::string pct(double v) { return std::isnan(v) ? "-" : fmt("%.3g%%", 100.0 * v); }

std::string spp_text(const cell& c) {
    return c.spp_min == c.spp_max ? std::to_string(c.spp_min) : fmt("%d-%d", c.spp_min, c.spp_max);
}

// A table head: the first columns, then one per K.
std::string k_head(const study& s, const std::string& first, int first_columns) {
    std::string t = "| " + first + " |";
    for (int k : s.ks) t += fmt(" K = %d |", k);
    t += "\n|";
    for (std::size_t i = 0; i < s.ks.size() + static_cast<std::size_t>(first_columns); ++i) t += "---|";
    return t + "\n";
}

std::string relmse_text(const cell& c, int m) {
    const int e = errors(c, m);
    return num(avg(c, m, &method_result::relmse)) + (e ? fmt(" (%d err)", e) : "");
}

// Per total: each scene's methods down, K across.
std::string headline(const study& s, const results& res, int total) {
    std::string t = fmt("\n### relMSE at %d samples per pixel\n\n", total) + k_head(s, "scene | method", 2);
    for (const std::string& name : s.scenes)
        for (int m = 0; m < method_count; ++m) {
            t += "| " + label(name) + " | " + method_names[m] + " |";
            for (int k : s.ks) t += " " + relmse_text(res.at({total, name, k}), m) + " |";
            t += "\n";
        }
    return t;
}

// Per total: median of means, M = K / M = 4 (K >= 8).
std::string mon_table(const study& s, const results& res, int total) {
    std::string t = fmt("\n### relMSE of median of means at %d samples per pixel: M = K / M = 4\n\n", total) +
                    k_head(s, "scene", 1);
    for (const std::string& name : s.scenes) {
        t += "| " + label(name) + " |";
        for (int k : s.ks) {
            const cell& c = res.at({total, name, k});
            t += " " + num(mean_over(c, [](const frame_result& r) { return r.mon_k; })) + " / " +
                 num(mean_over(c, [](const frame_result& r) { return r.mon_4; })) + " |";
        }
        t += "\n";
    }
    return t;
}

std::string detail_row(int k, const cell& c, int m) {
    std::string name = method_names[m];
    if (m == m_gmon) name += fmt(" (t = %.2g)", gmon_thresholds[best_gmon(c)]);
    const double ms = m == m_gmon ? NAN : fastest(c, m);
    return fmt("| %d | %s | %s | ", k, spp_text(c).c_str(), name.c_str()) + relmse_text(c, m) + " | " +
           num(avg(c, m, &method_result::majority)) + " | " + pct(avg(c, m, &method_result::changed)) + " | " +
           pct(avg(c, m, &method_result::hl_kept)) + " | " + pct(avg(c, m, &method_result::hl_not_lowered)) +
           " | " + (std::isnan(ms) ? std::string("-") : fmt("%.1f", ms)) + " |\n";
}

std::string details(const study& s, const results& res, int total) {
    std::string t;
    for (const std::string& name : s.scenes) {
        t += fmt("\n#### %s, %d samples per pixel\n\n", label(name).c_str(), total);
        t += "| K | spp per buffer | method | relMSE | of it from pixels hit in > K/2 buffers | pixels changed | "
             "highlights kept (unchanged) | highlights not lowered | ms (fastest seed) |\n"
             "|---|---|---|---|---|---|---|---|---|\n";
        for (int k : s.ks)
            for (int m : {m_firefly, m_plain, m_gmon}) t += detail_row(k, res.at({total, name, k}), m);
    }
    return t;
}

// Over the scenes: the median of each scene's fastest seed, with and without the return, and
// the median of the per-scene differences.
std::string timing_cells(const study& s, const results& res, int total, int k) {
    std::vector<double> with, without, cost;
    for (const std::string& name : s.scenes) {
        const cell& c = res.at({total, name, k});
        with.push_back(fastest(c, m_firefly));
        without.push_back(fastest(c, m_plain));
        cost.push_back(with.back() - without.back());
    }
    return fmt(" %.1f | %.1f | %+.1f (%+.0f%%) |", median(with), median(without), median(cost),
               100.0 * median(cost) / median(without));
}

std::string timing(const study& s, const results& res) {
    std::string t = "\n### firefly time per frame (ms, process() only; median over the scenes of the fastest seed)\n\n"
                    "The energy return's cost: the median over the scenes of (default - no return).\n\n| K |";
    for (int total : s.totals) t += fmt(" %d spp: default | no energy return | return's cost |", total);
    t += "\n|---|";
    for (std::size_t i = 0; i < 3 * s.totals.size(); ++i) t += "---|";
    t += "\n";
    for (int k : s.ks) {
        t += fmt("| %d |", k);
        for (int total : s.totals) t += timing_cells(s, res, total, k);
        t += "\n";
    }
    return t;
}

// Frames per K on which firefly with and without the energy return gave the same bits.
std::string identical(const study& s, const results& res) {
    std::string t = "\nFrames on which firefly with and without the energy return gave bit-identical buffers:";
    for (int k : s.ks) {
        int same = 0, n = 0;
        for (const auto& [where, c] : res) {
            if (std::get<2>(where) != k) continue;
            for (const frame_result& r : c.seeds) {
                same += r.plain_same;
                ++n;
            }
        }
        t += fmt("%s K = %d: %d of %d", k == s.ks.front() ? "" : ";", k, same, n);
    }
    return t + ".\n";
}

std::string memory(const study& s, const std::vector<memory_row>& rows) {
    std::string t = fmt(
        "\n### Memory per pixel (bytes), RGB\n\n"
        "(a) the finished buffers handed to the detector; (b) sample_accumulator, whose float "
        "views are (a) with variance, so (b) includes (a); (c) the detector's heap: peak growth "
        "and bytes kept after the first frame of a fresh cross_buffer_detector, largest over the "
        "scenes at %dx%d, %d spp, seed 1, at the defaults and with return_energy = false.\n\n"
        "| K | (a) float colour | (a) + variance | (a) the detector needs at defaults | "
        "(b) accumulator, from its members | (b) accumulator bytes() | (c) detector peak | "
        "(c) detector kept | (c) peak, no energy return | (c) kept, no energy return | "
        "K = 2: detector::scratch_bytes() | accumulator + detector peak | "
        "same output with variance (K >= 4) |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
        s.w, s.h, s.totals.front());
    for (const memory_row& m : rows) {
        const double colour = m.k * 3.0 * sizeof(float);
        t += fmt("| %d | %.0f | %.0f | %.0f | %.0f | %.0f | %.1f | %.1f | %.1f | %.1f | %s | %.1f | %s |\n", m.k, colour,
                 2 * colour, default_variance(m.k) ? 2 * colour : colour, m.accumulator_formula, m.accumulator_bytes,
                 m.peak, m.kept, m.plain_peak, m.plain_kept, m.k == 2 ? num(m.pair_scratch).c_str() : "-",
                 m.accumulator_bytes + m.peak, m.k < 4 ? "-" : m.variance_neutral ? "yes" : "NO");
    }
    return t;
}

std::string preamble(const study& s, double seconds) {
    std::string t = fmt(
        "## K-buffer study (bench/k_study.cpp)\n\n"
        "Simulated %dx%d, seeds 1-%d, totals", s.w, s.h, s.seeds);
    for (int total : s.totals) t += fmt(" %d", total);
    t += fmt(" samples per pixel split over K buffers; relMSE averaged over the seeds; firefly on one thread "
             "(serial executor), one detector per K and option set kept over all frames; \"firefly\" is "
             "cross_buffer_detector at its defaults (energy return on, sigma 8; at K = 2 the half-buffer "
             "detector's own), \"no energy return\" the same with return_energy = false (both); G-MoN at "
             "its best threshold of 0.1, 0.25, 0.4; %s build; run took %.0f s.\n",
#ifdef NDEBUG
             "NDEBUG",
#else
             "assert-enabled (not Release)",
#endif
             seconds);
    return t;
}

}  // namespace

int main(int argc, char** argv) {
    study s;
    if (!parse_args(argc, argv, s)) {
        std::fprintf(stderr, "usage: %s OUT.md [--size WxH] [--seeds N] [--totals T1,T2,...] "
                             "(even totals of at least %d)\n", argv[0], 2 * s.ks.back());
        return 2;
    }
    const auto t0 = std::chrono::steady_clock::now();
    results res;
    run_all(s, res);
    std::vector<memory_row> mem;
    for (int k : s.ks) mem.push_back(measure_memory(s, k));
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::string md = preamble(s, seconds);
    for (int total : s.totals) md += headline(s, res, total);
    md += timing(s, res) + identical(s, res) + memory(s, mem);
    for (int total : s.totals) md += mon_table(s, res, total);
    md += "\n### Per scene\n";
    for (int total : s.totals) md += details(s, res, total);
    std::fputs(md.c_str(), stdout);
    FILE* f = std::fopen(s.out.c_str(), "w");
    if (!f || std::fputs(md.c_str(), f) < 0 || std::fclose(f) != 0) {
        std::fprintf(stderr, "cannot write %s\n", s.out.c_str());
        return 1;
    }
    return 0;
}
