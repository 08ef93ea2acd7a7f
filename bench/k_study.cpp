// firefly_k_study: how the K-buffer result grows with K at a fixed total sample count, and
// what each K costs a renderer in memory (issue 18, item 4; the tables are docs/k_study.md).
//
//   firefly_k_study OUT.md [--size WxH] [--seeds N] [--totals T1,T2,...]
//
// sim::simulate_buffers splits a scene's 2 x spp samples per pixel over the K buffers (the
// first 2 spp mod K buffers get one more), so spp = total / 2 keeps the total the same at
// every K and only the way it is split changes. Each frame is cleaned by the mean of the K
// buffers, median of means (M = K; M = 4 too where K >= 8), G-MoN (M = K) at each threshold of
// {0.1, 0.25, 0.4} (bench/peers.hpp, the estimators bench_accuracy.cpp runs), and
// firefly::cross_buffer_detector at its default options: K = 2 hands the pair to
// firefly::detector (variance required), K = 3 needs the variances, K >= 4 gets colour only,
// because its default (use_variance = false) judges from the spread of the buffers and a
// renderer need not keep variance for it (the memory section checks that the output is the
// same with them). relMSE is sim::relmse against the expected radiance, as in the accuracy
// bench. The Markdown goes to stdout and to OUT.md.
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

struct frame_result {
    double mean = 0, mon_k = 0, mon_4 = NAN;
    std::array<double, 3> gmon{}, gmon_changed{}, gmon_hl{};
    double ff = 0, ff_changed = 0, ff_hl = 0, ff_ms = 0;
    double ff_majority = 0;  // the part of ff from pixels with fireflies in more than K / 2 buffers
    bool ff_ok = true;
};

firefly_peers::buffer_list buffer_list(const sim::buffers& b) {
    firefly_peers::buffer_list l;
    for (const auto& c : b.color) l.push_back(c.data());
    return l;
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

// Share of pixels changed from `in`, and share of highlight pixels left as they were
// (NaN when the scene has none).
void change_counts(const std::vector<float>& out, const std::vector<float>& in,
                   const std::vector<std::uint8_t>& highlight, double& changed, double& kept) {
    std::size_t n = 0, hl = 0, hl_kept = 0;
    for (std::size_t p = 0; p < highlight.size(); ++p) {
        const bool c = pixel_changed(&out[p * 3], &in[p * 3]);
        n += c;
        hl += highlight[p];
        hl_kept += highlight[p] && !c;
    }
    changed = static_cast<double>(n) / static_cast<double>(highlight.size());
    kept = hl ? static_cast<double>(hl_kept) / static_cast<double>(hl) : NAN;
}

// The mean, median of means and G-MoN; `mean` is also the input the others are compared to.
void run_estimators(const sim::buffers& b, int k, frame_result& r) {
    const firefly_peers::buffer_list bl = buffer_list(b);
    const std::size_t np = b.pixels();
    std::vector<float> mean(np * 3), out(np * 3);
    firefly_peers::mean_of_buffers(bl, np, mean.data());
    r.mean = sim::relmse(mean.data(), b.expected.data(), np);
    firefly_peers::median_of_means(bl, np, k, out.data());
    r.mon_k = sim::relmse(out.data(), b.expected.data(), np);
    if (k >= 8) {
        firefly_peers::median_of_means(bl, np, 4, out.data());
        r.mon_4 = sim::relmse(out.data(), b.expected.data(), np);
    }
    for (std::size_t t = 0; t < gmon_thresholds.size(); ++t) {
        firefly_peers::gmon(bl, np, k, gmon_thresholds[t], out.data());
        r.gmon[t] = sim::relmse(out.data(), b.expected.data(), np);
        change_counts(out, mean, b.highlight, r.gmon_changed[t], r.gmon_hl[t]);
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

void run_firefly(cross_buffer_detector& det, const sim::buffers& b, int k, frame_result& r) {
    buffer_copy work(b, default_variance(k));
    const auto t0 = std::chrono::steady_clock::now();
    const cross_buffer_report rep = det.process(work.views);
    const auto t1 = std::chrono::steady_clock::now();
    r.ff_ms = std::chrono::duration<double, std::milli>(t1 - t0).count();
    r.ff_ok = rep.ok();
    const sim::accuracy a = sim::evaluate_buffers(b, work.color);  // relMSE of the spp-weighted mean
    r.ff = a.relmse;
    r.ff_hl = a.highlight_kept;
    r.ff_changed = buffers_changed(b, work.color);
    r.ff_majority = majority_hit_error(b, sim::combine(b, work.color));
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

// The fastest seed's time: the machine may be shared, and other work only ever adds time.
double fastest(const cell& c) {
    double t = INFINITY;
    for (const frame_result& r : c.seeds) t = std::min(t, r.ff_ms);
    return t;
}

double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    const std::size_t n = v.size();
    return n == 0 ? NAN : n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// G-MoN's threshold with the lowest relMSE averaged over the seeds (chosen after the fact:
// the most favourable choice for G-MoN).
std::size_t best_gmon(const cell& c) {
    std::size_t best = 0;
    for (std::size_t t = 1; t < gmon_thresholds.size(); ++t)
        if (mean_over(c, [&](const frame_result& r) { return r.gmon[t]; }) <
            mean_over(c, [&](const frame_result& r) { return r.gmon[best]; }))
            best = t;
    return best;
}

using key = std::tuple<int, std::string, int>;  // total, scene, K
using results = std::map<key, cell>;

// One detector per K, kept over every frame as a renderer keeps it (its caches warm up).
void run_all(const study& s, results& res) {
    std::map<int, cross_buffer_detector> detectors;
    for (int total : s.totals)
        for (const std::string& name : s.scenes)
            for (int k : s.ks)
                for (int seed = 1; seed <= s.seeds; ++seed) {
                    const sim::buffers b = sim::simulate_buffers(make_scene(name, s, total, seed), k);
                    cell& c = res[{total, name, k}];
                    c.spp_min = *std::min_element(b.spp.begin(), b.spp.end());
                    c.spp_max = *std::max_element(b.spp.begin(), b.spp.end());
                    frame_result r;
                    run_estimators(b, k, r);
                    run_firefly(detectors[k], b, k, r);
                    c.seeds.push_back(r);
                    std::fprintf(stderr, "total %d %s K=%d seed %d: firefly %.4g (%.1f ms)\n", total, name.c_str(),
                                 k, seed, r.ff, r.ff_ms);
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
    double peak = 0, kept = 0;   // per pixel, the largest over the scenes
    double pair_scratch = 0;     // K = 2: firefly::detector::scratch_bytes(), largest over the scenes
    bool variance_neutral = true;  // K >= 4: the output is bit-identical with the variances given
};

// Heap of a fresh detector's first frame (its largest: later frames of the size reuse it).
heap_use detector_heap(const sim::buffers& b, int k) {
    buffer_copy work(b, default_variance(k));
    cross_buffer_detector det;
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
    return without.color == with.color;
}

std::vector<memory_row> measure_memory(const study& s) {
    std::vector<memory_row> rows;
    const double np = static_cast<double>(s.pixels());
    for (int k : s.ks) {
        memory_row m;
        m.k = k;
        m.accumulator_formula = accumulator_formula(k, 3);
        m.accumulator_bytes = accumulator_measured(k, 3);
        for (const std::string& name : s.scenes) {
            const sim::buffers b = sim::simulate_buffers(make_scene(name, s, s.totals.front(), 1), k);
            const heap_use u = detector_heap(b, k);
            m.peak = std::max(m.peak, static_cast<double>(u.peak) / np);
            m.kept = std::max(m.kept, static_cast<double>(u.kept) / np);
            if (k == 2) m.pair_scratch = std::max(m.pair_scratch, pair_scratch(b) / np);
            if (k >= 4) m.variance_neutral = m.variance_neutral && same_with_variance(b);
        }
        rows.push_back(m);
    }
    return rows;
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

// Per total: scenes down, K across; each cell firefly / G-MoN (best threshold) / mean.
std::string headline(const study& s, const results& res, int total) {
    std::string t = fmt("\n### relMSE at %d samples per pixel: firefly / G-MoN (best threshold) / mean\n\n| scene |", total);
    for (int k : s.ks) t += fmt(" K = %d |", k);
    t += "\n|---|";
    for (std::size_t i = 0; i < s.ks.size(); ++i) t += "---|";
    t += "\n";
    for (const std::string& name : s.scenes) {
        t += "| " + label(name) + " |";
        for (int k : s.ks) {
            const cell& c = res.at({total, name, k});
            const std::size_t g = best_gmon(c);
            t += " " + num(mean_over(c, [](const frame_result& r) { return r.ff; })) + " / " +
                 num(mean_over(c, [&](const frame_result& r) { return r.gmon[g]; })) + " / " +
                 num(mean_over(c, [](const frame_result& r) { return r.mean; })) + " |";
        }
        t += "\n";
    }
    return t;
}

std::string detail_row(int k, const cell& c) {
    const std::size_t g = best_gmon(c);
    auto m = [&](auto f) { return mean_over(c, f); };
    int errors = 0;
    for (const frame_result& r : c.seeds) errors += !r.ff_ok;
    std::string row = fmt("| %d | %s | ", k, spp_text(c).c_str());
    row += num(m([](const frame_result& r) { return r.mean; })) + " | " +
           num(m([](const frame_result& r) { return r.mon_k; })) + " | " +
           num(m([](const frame_result& r) { return r.mon_4; })) + " | " +
           num(m([&](const frame_result& r) { return r.gmon[g]; })) + fmt(" (%.2g) | ", gmon_thresholds[g]) +
           num(m([](const frame_result& r) { return r.ff; })) + (errors ? fmt(" (%d err)", errors) : "") + " | " +
           num(m([](const frame_result& r) { return r.ff_majority; })) + " | " +
           pct(m([](const frame_result& r) { return r.ff_changed; })) + " | " +
           pct(m([&](const frame_result& r) { return r.gmon_changed[g]; })) + " | " +
           pct(m([](const frame_result& r) { return r.ff_hl; })) + " | " +
           pct(m([&](const frame_result& r) { return r.gmon_hl[g]; })) + " | " + fmt("%.1f |\n", fastest(c));
    return row;
}

std::string details(const study& s, const results& res, int total) {
    std::string t;
    for (const std::string& name : s.scenes) {
        t += fmt("\n#### %s, %d samples per pixel\n\n", label(name).c_str(), total);
        t += "| K | spp per buffer | mean | MoN M = K | MoN M = 4 | G-MoN best (t) | firefly | firefly, of it from "
             "pixels hit in > K/2 buffers | firefly changed | "
             "G-MoN changed | firefly highlights kept | G-MoN highlights kept | firefly ms (fastest seed) |\n"
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
        for (int k : s.ks) t += detail_row(k, res.at({total, name, k}));
    }
    return t;
}

// Time per frame per K and total: the median over the scenes of each scene's fastest seed.
std::string timing(const study& s, const results& res) {
    std::string t = "\n### firefly time per frame (ms, process() only; median over the scenes of the fastest seed)\n\n| K |";
    for (int total : s.totals) t += fmt(" %d spp |", total);
    t += "\n|---|";
    for (std::size_t i = 0; i < s.totals.size(); ++i) t += "---|";
    t += "\n";
    for (int k : s.ks) {
        t += fmt("| %d |", k);
        for (int total : s.totals) {
            std::vector<double> ms;
            for (const std::string& name : s.scenes) ms.push_back(fastest(res.at({total, name, k})));
            t += fmt(" %.1f |", median(ms));
        }
        t += "\n";
    }
    return t;
}

std::string memory(const study& s, const std::vector<memory_row>& rows) {
    std::string t = fmt(
        "\n### Memory per pixel (bytes), RGB\n\n"
        "(a) the finished buffers handed to the detector; (b) sample_accumulator, whose float "
        "views are (a) with variance, so (b) includes (a); (c) the detector's heap: peak growth "
        "and bytes kept after the first frame of a fresh cross_buffer_detector, largest over the "
        "scenes at %dx%d, %d spp, seed 1.\n\n"
        "| K | (a) float colour | (a) + variance | (a) the detector needs at defaults | "
        "(b) accumulator, from its members | (b) accumulator bytes() | (c) detector peak | "
        "(c) detector kept | K = 2: detector::scratch_bytes() | accumulator + detector peak | "
        "same output with variance (K >= 4) |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
        s.w, s.h, s.totals.front());
    for (const memory_row& m : rows) {
        const double colour = m.k * 3.0 * sizeof(float);
        t += fmt("| %d | %.0f | %.0f | %.0f | %.0f | %.0f | %.1f | %.1f | %s | %.1f | %s |\n", m.k, colour, 2 * colour,
                 default_variance(m.k) ? 2 * colour : colour, m.accumulator_formula, m.accumulator_bytes, m.peak,
                 m.kept, m.k == 2 ? num(m.pair_scratch).c_str() : "-", m.accumulator_bytes + m.peak,
                 m.k < 4 ? "-" : m.variance_neutral ? "yes" : "NO");
    }
    return t;
}

std::string preamble(const study& s, double seconds) {
    std::string t = fmt(
        "## K-buffer study (bench/k_study.cpp)\n\n"
        "Simulated %dx%d, seeds 1-%d, totals", s.w, s.h, s.seeds);
    for (int total : s.totals) t += fmt(" %d", total);
    t += fmt(" samples per pixel split over K buffers; relMSE averaged over the seeds; firefly on one thread "
             "(serial executor), one detector per K kept over all frames; %s build; run took %.0f s.\n",
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
    const std::vector<memory_row> mem = measure_memory(s);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::string md = preamble(s, seconds);
    for (int total : s.totals) md += headline(s, res, total);
    md += timing(s, res);
    md += memory(s, mem);
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
