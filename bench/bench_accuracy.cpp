// Accuracy against time: every method and configuration on every named simulated scene
// (2048x1080 by default; FIREFLY_ACCURACY_SIZE=WxH to change), and on the real renders in
// ../shared/data when present (cycles-caustics, cycles-interior: half buffers with variance;
// cycles-caustics-seeds: 8 renders with different seeds, split 4 + 4 into two halves whose
// variance is the renders' spread, and used whole by the K-buffer estimators). Each
// benchmark's time is one frame; its counters are described in docs/accuracy.md and
// computed in count_metrics below. Run with --benchmark_format=json and turn the output into
// tables and a Pareto plot with bench/accuracy_report.py. FIREFLY_ACCURACY_RENDERS adds renders
// of one's own (see extra_render_dirs).
//
// FIREFLY_ACCURACY_IMAGES=DIR writes, per scene, every downstream method's combined output
// and the reference (DIR/<scene>/<method>.pfm) for bench/downstream.py, NL-means after each
// prefilter. Simulated scenes are cropped around the centre to FIREFLY_ACCURACY_CROP (default
// 320x180), and the K-buffer variants (name@kK) are not written: NL-means is slow.
#include <benchmark/benchmark.h>

#include <firefly/firefly.hpp>
#include <firefly/sim/metrics.hpp>
#include <firefly/sim/scene.hpp>

#include <sys/stat.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "../bench/peers.hpp"
#include "image_io.hpp"
#include "pfm.hpp"

using namespace firefly;

namespace {

// One benchmark scene: the two halves every half-buffer method cleans, the K buffers the
// K-buffer estimators read (the halves themselves when the scene has no more), the
// reference, and the simulator's ground truth when there is one.
struct scene_data {
    std::string name;
    int w = 0, h = 0;
    sim::frame f;                             // halves, alpha, reference (f.expected); for a
                                              // simulated scene also the ground truth
    std::vector<std::vector<float>> buffers;  // K x RGB; empty: the halves
    std::vector<float> input;                 // (A + B) / 2 as given
    const sim::frame* truth = nullptr;        // &f when simulated
    std::size_t pixels() const { return static_cast<std::size_t>(w) * static_cast<std::size_t>(h); }
    const std::vector<float>& reference() const { return f.expected; }
    firefly_peers::buffer_list buffer_list() const {
        firefly_peers::buffer_list b;
        if (buffers.empty())
            for (const auto& c : f.color) b.push_back(c.data());
        for (const auto& c : buffers) b.push_back(c.data());
        return b;
    }
};

using halves_fn = std::function<bool(half_buffer<float>&, half_buffer<float>&)>;  // false: error
using buffers_fn = std::function<void(const firefly_peers::buffer_list&, int w, int h, float*)>;

// A method on the two halves is made afresh for each benchmark (a detector keeps frame-sized
// work buffers: hundreds of them kept alive would hold gigabytes at 2K).
using halves_factory = std::function<halves_fn()>;

struct config {
    std::string name;
    halves_factory halves;  // a method on the two halves, or ...
    buffers_fn buffers;  // ... an estimator over the K buffers
    bool downstream = false;  // write its output for the NL-means column
};

halves_factory firefly_with(detector_options o) {
    return [o] {
        auto d = std::make_shared<detector>(o);
        return halves_fn([d](half_buffer<float>& a, half_buffer<float>& b) { return d->process(a, b).error.ok(); });
    };
}

// A peer cleans each half on its own, after the shared non-finite repair.
halves_factory peer(std::function<void(const image_view<float>&, const image_view<float>&)> f) {
    return [f] {
        return halves_fn([f](half_buffer<float>& a, half_buffer<float>& b) {
            firefly_peers::repair_nonfinite(a.color, a.variance, b.color, b.variance);
            f(a.color, a.variance);
            f(b.color, b.variance);
            return true;
        });
    };
}

void add_firefly_configs(std::vector<config>& c) {
    detector_options def;
    c.push_back({"firefly", firefly_with(def), {}, true});
    auto with = [&](const char* name, auto edit, bool downstream = false) {
        detector_options o = def;
        edit(o);
        c.push_back({name, firefly_with(o), {}, downstream});
    };
    with("firefly_paper", [](detector_options& o) {  // the paper as written
        o.highlight.rule = highlight_rule::same_pixel;
        o.highlight.min_excess_z = 0;
        o.rebuild = rebuild_source::spatial;
        o.local_test = false;
        o.return_energy = false;
    }, true);
    with("firefly_spatial_rebuild", [](detector_options& o) { o.rebuild = rebuild_source::spatial; }, true);
    with("firefly_no_blend", [](detector_options& o) { o.blend_spatial = false; });
    with("firefly_no_local_test", [](detector_options& o) { o.local_test = false; }, true);
    with("firefly_no_energy", [](detector_options& o) { o.return_energy = false; }, true);
    with("firefly_fine_energy", [](detector_options& o) { o.energy_coarse_sigma = 0; }, true);  // one scale
    with("firefly_no_density", [](detector_options& o) { o.energy_density_evidence = 0; }, true);  // density.hpp
    with("firefly_alpha0.01", [](detector_options& o) { o.alpha = 0.01; });
    with("firefly_alpha0.2", [](detector_options& o) { o.alpha = 0.2; });
    with("firefly_bound3.0", [](detector_options& o) { o.bound_threshold = 3.0; });
    with("firefly_bound5.0", [](detector_options& o) { o.bound_threshold = 5.0; });
    with("firefly_same_pixel", [](detector_options& o) { o.highlight.rule = highlight_rule::same_pixel; });
    with("firefly_agree4", [](detector_options& o) { o.highlight.rule = highlight_rule::agree; });
    with("firefly_confident_agree", [](detector_options& o) { o.highlight.rule = highlight_rule::confident_and_agree; });
    with("firefly_no_excess_check", [](detector_options& o) { o.highlight.min_excess_z = 0; });
    with("firefly_no_cluster_rule", [](detector_options& o) { o.highlight.cluster_relative_error = 0; });
    with("firefly_kernel3", [](detector_options& o) { o.reconstruction.kernel_width = 3; });
    with("firefly_kernel7", [](detector_options& o) { o.reconstruction.kernel_width = 7; o.reconstruction.sigma = 1.5; });
    with("firefly_phase1_only", [](detector_options& o) { o.reconstruction.max_iterations = 0; });
    with("firefly_tol1e-2", [](detector_options& o) { o.reconstruction.tolerance = 1e-2; });
    with("firefly_hill_lambdas", [](detector_options& o) { o.lambdas = lambda_method::hill; });
    with("firefly_normal_lambdas", [](detector_options& o) { o.lambdas = lambda_method::normal; });
}

void add_peer_configs(std::vector<config>& c) {
    c.push_back({"input", [] { return halves_fn([](half_buffer<float>&, half_buffer<float>&) { return true; }); },
                 {}, true});
    c.push_back({"median3x3", peer(&firefly_peers::median3x3), {}, true});
    c.push_back({"cycles_prefilter", peer(&firefly_peers::cycles_prefilter), {}, true});
    c.push_back({"bcd_spikes", peer([](const image_view<float>& col, const image_view<float>& var) {
                     firefly_peers::bcd_spikes(col, var);
                 }), {}, true});
    c.push_back({"nrd_clamp", peer(&firefly_peers::nrd_clamp), {}, true});
    c.push_back({"clamp4", peer([](const image_view<float>& col, const image_view<float>& var) {
                     firefly_peers::fixed_clamp(col, var, 4.0f);
                 }), {}, true});
    c.push_back({"clamp16", peer([](const image_view<float>& col, const image_view<float>& var) {
                     firefly_peers::fixed_clamp(col, var, 16.0f);
                 }), {}, false});
}

// firefly's K-buffer detector (buffers.hpp) on copies of the K buffers (no variance: the
// spread of the buffers estimates the noise), then the mean of the cleaned ones.
buffers_fn firefly_buffers(cross_buffer_options o = {}) {
    return [o](const firefly_peers::buffer_list& b, int w, int h, float* out) {
        const std::size_t n = static_cast<std::size_t>(w) * h * 3;
        std::vector<std::vector<float>> copy(b.size());
        std::vector<buffer_view<float>> views;
        for (std::size_t i = 0; i < b.size(); ++i) {
            copy[i].assign(b[i], b[i] + n);
            views.push_back({*make_image_view(copy[i].data(), w, h, 3), {}});
        }
        cross_buffer_detector d(o);
        (void)d.process(views);
        for (std::size_t j = 0; j < n; ++j) {
            double sum = 0;
            for (const auto& c : copy) sum += c[j];
            out[j] = static_cast<float>(sum / static_cast<double>(copy.size()));
        }
    };
}

// The K-buffer estimators on K buffers (on the halves, K = 2, all reduce to the mean).
void add_buffer_configs(std::vector<config>& c, int k) {
    const std::string K = std::to_string(k);
    const bool ds = k > 2;  // at K = 2 their output is the input's: no NL-means column needed
    if (k >= 4) {  // no variance here
        c.push_back({"firefly_k" + K, {}, firefly_buffers(), ds});
        cross_buffer_options density;  // the return's finest scale, off by default here
        density.energy_density_evidence = 8;
        c.push_back({"firefly_k" + K + "_density", {}, firefly_buffers(density), false});
    }
    c.push_back({"mean_k" + K, {}, [](const firefly_peers::buffer_list& b, int w, int h, float* out) {
                     firefly_peers::mean_of_buffers(b, static_cast<std::size_t>(w) * h, out);
                 }, false});
    std::vector<int> groups = {k};
    if (k % 2 == 0 && k / 2 >= 3) groups.push_back(k / 2);
    for (int m : groups) {
        const std::string M = std::to_string(m);
        c.push_back({"mon_k" + K + "_m" + M, {}, [m](const firefly_peers::buffer_list& b, int w, int h, float* out) {
                         firefly_peers::median_of_means(b, static_cast<std::size_t>(w) * h, m, out);
                     }, ds});
        // G-MoN: the binary variant (mean or median of means) at three thresholds, and the
        // paper's adaptive one (a Gini-trimmed mean of the means; no threshold)
        c.push_back({"agmon_k" + K + "_m" + M, {}, [m](const firefly_peers::buffer_list& b, int w, int h, float* out) {
                         firefly_peers::agmon(b, static_cast<std::size_t>(w) * h, m, out);
                     }, ds});
        for (double t : {0.1, 0.25, 0.4}) {
            if (m == 2 && t != 0.25) continue;  // two means: every threshold gives the mean
            char name[64];
            std::snprintf(name, sizeof name, "gmon_k%d_m%d_t%.2f", k, m, t);
            c.push_back({name, {}, [m, t](const firefly_peers::buffer_list& b, int w, int h, float* out) {
                             firefly_peers::gmon(b, static_cast<std::size_t>(w) * h, m, t, out);
                         }, ds && t == 0.25});
        }
    }
}

// On K-buffer scenes (K > 2) only firefly at defaults and as the paper wrote it: the
// configurations are compared on the half-buffer scenes.
std::vector<config> configs(int k) {
    std::vector<config> c;
    add_firefly_configs(c);
    if (k > 2) c.resize(2);
    add_peer_configs(c);
    add_buffer_configs(c, k);
    return c;
}

// ---------------------------------------------------------------------------------------
// Counters.

using sim::pixel_error;  // the relMSE term summed over the channels; non-finite: infinite

// A pixel is changed when a channel moved by more than float round-off (the K-buffer mean
// sums in another order than (A + B) / 2); NaN against NaN is unchanged.
bool pixel_changed(const float* out, const float* in) {
    for (int c = 0; c < 3; ++c) {
        if (out[c] == in[c] || (std::isnan(out[c]) && std::isnan(in[c]))) continue;
        if (!(std::fabs(out[c] - in[c]) <= 1e-6f * std::fabs(in[c]))) return true;
    }
    return false;
}

// Dark: reference brightness below the median of the lit pixels; bright: at or above their
// 95th percentile. Lit: reference brightness > 0.
void brightness_cuts(const std::vector<float>& ref, double& dark, double& bright) {
    std::vector<float> lit;
    for (std::size_t i = 0; i + 2 < ref.size(); i += 3) {
        const float l = (ref[i] + ref[i + 1] + ref[i + 2]) / 3.0f;
        if (l > 0) lit.push_back(l);
    }
    dark = bright = 0;
    if (lit.empty()) return;
    std::sort(lit.begin(), lit.end());
    dark = lit[lit.size() / 2];
    bright = lit[std::min(lit.size() - 1, lit.size() * 95 / 100)];
}

// relMSE, changed, made worse and energy of a combined output against the reference.
void count_lowered(benchmark::State& st, const scene_data& s, const std::vector<float>& out);

void count_metrics(benchmark::State& st, const scene_data& s, const std::vector<float>& out) {
    const std::size_t np = s.pixels();
    double dark_cut, bright_cut;
    brightness_cuts(s.reference(), dark_cut, bright_cut);
    std::size_t changed = 0, worse = 0;
    double sum_out[3] = {0, 0, 0}, sum_ref[3] = {0, 0, 0};  // all, dark, bright
    for (std::size_t p = 0; p < np; ++p) {
        const float* o = &out[p * 3];
        const float* in = &s.input[p * 3];
        const float* r = &s.reference()[p * 3];
        if (pixel_changed(o, in)) {
            ++changed;
            worse += pixel_error(o, r) > pixel_error(in, r);
        }
        const double lo = (static_cast<double>(o[0]) + o[1] + o[2]) / 3.0, lr = (static_cast<double>(r[0]) + r[1] + r[2]) / 3.0;
        if (!std::isfinite(lo)) continue;
        const bool region[3] = {true, lr > 0 && lr < dark_cut, lr >= bright_cut && lr > 0};
        for (int k = 0; k < 3; ++k)
            if (region[k]) {
                sum_out[k] += lo;
                sum_ref[k] += lr;
            }
    }
    st.counters["relmse"] = sim::relmse(out.data(), s.reference().data(), np);
    st.counters["changed"] = static_cast<double>(changed) / static_cast<double>(np);
    st.counters["worse"] = static_cast<double>(worse) / static_cast<double>(np);
    st.counters["worse_of_changed"] = changed ? static_cast<double>(worse) / static_cast<double>(changed) : 0.0;
    const char* names[3] = {"energy", "energy_dark", "energy_bright"};
    for (int k = 0; k < 3; ++k) st.counters[names[k]] = sum_ref[k] > 0 ? sum_out[k] / sum_ref[k] : 1.0;
    count_lowered(st, s, out);
}

// Highlight pixels whose output is not below the input less the fireflies' energy there (mean
// colour, beyond round-off): kept as highlights, nothing taken from them but fireflies. A
// method that only adds energy back (energy.hpp) changes pixels without lowering any;
// "highlight_kept" (unchanged) counts those as lost.
void count_lowered(benchmark::State& st, const scene_data& s, const std::vector<float>& out) {
    if (!s.truth || s.truth->highlight.size() != s.pixels()) return;
    std::size_t hl = 0, kept = 0;
    for (std::size_t p = 0; p < s.pixels(); ++p) {
        if (!s.truth->highlight[p]) continue;
        ++hl;
        const double o = (static_cast<double>(out[p * 3]) + out[p * 3 + 1] + out[p * 3 + 2]) / 3.0;
        const double in = (static_cast<double>(s.input[p * 3]) + s.input[p * 3 + 1] + s.input[p * 3 + 2]) / 3.0;
        const double fireflies = 0.5 * (static_cast<double>(s.truth->firefly(0, p)) + s.truth->firefly(1, p));
        kept += !std::isfinite(in) || o >= in - fireflies - 1e-6 * std::fabs(in);
    }
    st.counters["highlight_not_lowered"] = hl ? static_cast<double>(kept) / static_cast<double>(hl) : 1.0;
}

// Recall, false positives, highlights kept, from the simulator's ground truth.
void count_truth(benchmark::State& st, const scene_data& s, const std::vector<float>* halves[2]) {
    if (!s.truth) return;
    const sim::accuracy a = sim::evaluate(*s.truth, halves);
    st.counters["recall"] = a.recall;
    st.counters["precision"] = a.precision;
    st.counters["false_positive"] = a.false_positive;
    st.counters["highlight_kept"] = a.highlight_kept;
}

// ---------------------------------------------------------------------------------------
// Images for the downstream column.

std::string image_dir() {
    const char* d = std::getenv("FIREFLY_ACCURACY_IMAGES");
    return d && *d ? std::string(d) : std::string();
}

// The centre crop written for a scene: whole real renders, simulated scenes cropped.
void crop_rect(const scene_data& s, int& x0, int& y0, int& cw, int& ch) {
    cw = s.w;
    ch = s.h;
    if (s.truth) {
        int mw = 320, mh = 180;
        if (const char* c = std::getenv("FIREFLY_ACCURACY_CROP")) std::sscanf(c, "%dx%d", &mw, &mh);
        cw = std::min(cw, mw);
        ch = std::min(ch, mh);
    }
    x0 = (s.w - cw) / 2;
    y0 = (s.h - ch) / 2;
}

void write_image(const scene_data& s, const std::string& method, const std::vector<float>& rgb) {
    const std::string dir = image_dir();
    if (dir.empty() || s.name.find("@k") != std::string::npos) return;  // NL-means costs: not on @k
    ::mkdir(dir.c_str(), 0755);
    ::mkdir((dir + "/" + s.name).c_str(), 0755);
    int x0, y0, cw, ch;
    crop_rect(s, x0, y0, cw, ch);
    firefly_tools::pfm_image img;
    img.width = cw;
    img.height = ch;
    img.channels = 3;
    img.pixels.resize(static_cast<std::size_t>(cw) * ch * 3);
    for (int y = 0; y < ch; ++y)
        std::memcpy(&img.pixels[static_cast<std::size_t>(y) * cw * 3],
                    &rgb[(static_cast<std::size_t>(y0 + y) * s.w + x0) * 3], static_cast<std::size_t>(cw) * 3 * sizeof(float));
    const std::string err = firefly_tools::write_pfm(dir + "/" + s.name + "/" + method + ".pfm", img);
    if (!err.empty()) std::fprintf(stderr, "note: %s\n", err.c_str());
}

// ---------------------------------------------------------------------------------------
// Running one method on one scene.

struct work {
    std::vector<float> col[2], var[2];
    half_buffer<float> half[2];
    void load(const scene_data& s) {
        for (int i = 0; i < 2; ++i) {
            col[i] = s.f.color[i];
            var[i] = s.f.variance[i];
            half[i].color = *make_image_view(col[i].data(), s.w, s.h, 3);
            half[i].variance = *make_image_view(var[i].data(), s.w, s.h, 3);
            if (!s.f.alpha.empty()) half[i].alpha = *make_image_view(s.f.alpha.data(), s.w, s.h, 1);
        }
    }
};

// The combined image of a half-buffer method, and for the "input" row the input after the
// shared repair (what the denoiser alone is given: NL-means cannot take NaN).
std::vector<float> combine(const std::vector<float>& a, const std::vector<float>& b) {
    std::vector<float> out(a.size());
    for (std::size_t i = 0; i < a.size(); ++i) out[i] = 0.5f * (a[i] + b[i]);
    return out;
}

// warm_up (a scene's first method): one untimed frame first, by another instance of the
// method, so that the timed one does not also pay the process's first touch of the scene's
// data and of fresh heap pages (measured: 50-70 ms of a 1024x540 frame, which the method
// that happened to run first was charged).
void run_halves(benchmark::State& st, const scene_data* s, const config& cfg, bool warm_up) {
    work wk;
    bool ok = true;
    if (warm_up) {
        wk.load(*s);
        (void)cfg.halves()(wk.half[0], wk.half[1]);
    }
    const halves_fn run = cfg.halves();  // the first iteration is the cold frame
    for (auto _ : st) {
        st.PauseTiming();
        wk.load(*s);
        st.ResumeTiming();
        ok = run(wk.half[0], wk.half[1]);
    }
    const std::vector<float> out = combine(wk.col[0], wk.col[1]);
    count_metrics(st, *s, out);
    st.counters["error"] = ok ? 0 : 1;  // the library said the frame was not cleaned
    const std::vector<float>* halves[2] = {&wk.col[0], &wk.col[1]};
    count_truth(st, *s, halves);
    if (!cfg.downstream) return;
    if (cfg.name != "input") return write_image(*s, cfg.name, out);
    wk.load(*s);
    firefly_peers::repair_nonfinite(wk.half[0].color, wk.half[0].variance, wk.half[1].color, wk.half[1].variance);
    write_image(*s, cfg.name, combine(wk.col[0], wk.col[1]));
}

void run_buffers(benchmark::State& st, const scene_data* s, const config& cfg) {
    const firefly_peers::buffer_list bl = s->buffer_list();
    std::vector<float> out(s->pixels() * 3);
    for (auto _ : st) cfg.buffers(bl, s->w, s->h, out.data());
    count_metrics(st, *s, out);
    // Halves for the ground-truth counters: a pixel the estimator left at the input's value
    // is unchanged in both halves; any other takes the output in both.
    std::vector<float> h[2] = {s->f.color[0], s->f.color[1]};
    for (std::size_t p = 0; p < s->pixels(); ++p)
        if (pixel_changed(&out[p * 3], &s->input[p * 3]))
            for (int i = 0; i < 2; ++i) std::copy_n(&out[p * 3], 3, &h[i][p * 3]);
    const std::vector<float>* halves[2] = {&h[0], &h[1]};
    count_truth(st, *s, halves);
    if (cfg.downstream) write_image(*s, cfg.name, out);
}

void register_scene(const scene_data* s, int iterations) {
    const int k = s->buffers.empty() ? 2 : static_cast<int>(s->buffers.size());
    bool first = true;
    for (const config& c : configs(k)) {
        const std::string name = "accuracy/" + s->name + "/" + c.name;
        auto* b = c.halves ? benchmark::RegisterBenchmark(name.c_str(), run_halves, s, c, std::exchange(first, false))
                           : benchmark::RegisterBenchmark(name.c_str(), run_buffers, s, c);
        b->Unit(benchmark::kMillisecond)->Iterations(iterations);
    }
    write_image(*s, "reference", s->reference());
}

// ---------------------------------------------------------------------------------------
// Scenes.

void finish(scene_data& s) {
    s.w = s.f.width;
    s.h = s.f.height;
    s.input = combine(s.f.color[0], s.f.color[1]);
}

void add_simulated(std::map<std::string, scene_data>& all, int w, int h) {
    std::vector<std::string> names = sim::scene_names();
    names.push_back("highlights@16spp");  // hard: few samples make real highlights noisy
    names.push_back("production@16spp");
    for (const std::string& name : names) {
        const std::size_t at = name.find('@');
        sim::scene sc = sim::named_scene(name.substr(0, at), w, h, 1);
        if (at != std::string::npos) sc.spp = std::atoi(name.c_str() + at + 1);
        scene_data& s = all[name];
        s.name = name;
        s.f = sim::simulate(sc);
        s.truth = &s.f;
        finish(s);
    }
}

// Half h of a simulated K-buffer frame: the mean of its K/2 buffers (the simulator splits the
// samples evenly) and the variance of that mean; its ground truth likewise.
void buffer_half(const sim::buffers& b, int h, sim::frame& f) {
    const int per = b.count() / 2;
    const std::size_t n = b.pixels();
    f.color[h].assign(n * 3, 0.0f);
    f.variance[h].assign(n * 3, 0.0f);
    if (!b.firefly_energy.empty() && !b.firefly_energy[0].empty()) f.firefly_energy[h].assign(n, 0.0f);
    if (!b.nonfinite.empty() && !b.nonfinite[0].empty()) f.nonfinite[h].assign(n, 0);
    for (int k = h * per; k < (h + 1) * per; ++k) {
        for (std::size_t i = 0; i < n * 3; ++i) {
            f.color[h][i] += b.color[k][i] / per;
            f.variance[h][i] += b.variance[k][i] / (static_cast<float>(per) * per);
        }
        for (std::size_t i = 0; i < n && !f.firefly_energy[h].empty(); ++i) f.firefly_energy[h][i] += b.firefly(k, i) / per;
        for (std::size_t i = 0; i < n && !f.nonfinite[h].empty(); ++i) f.nonfinite[h][i] |= b.bad(k, i) ? 1 : 0;
    }
}

// Simulated scenes with K buffers (name@kK): the K-buffer estimators read the K buffers, the
// half-buffer methods their two halves (K/2 buffers each), the same samples. At most
// 1024x540: K full frames per scene cost memory, and the comparison does not need more.
void add_buffer_scenes(std::map<std::string, scene_data>& all, int w, int h) {
    w = std::min(w, 1024);
    h = std::min(h, 540);
    for (const char* base : {"sparse_fireflies", "highlights", "production", "caustics", "interior", "null_k4_spp64"})
        for (int k : {4, 8}) {
            const std::string name = std::string(base) + "@k" + std::to_string(k);
            sim::buffers b = sim::simulate_buffers(sim::named_scene(base, w, h, 1), k);
            scene_data& s = all[name];
            s.name = name;
            sim::frame& f = s.f;
            f.width = b.width;
            f.height = b.height;
            f.effects = b.effects;
            buffer_half(b, 0, f);
            buffer_half(b, 1, f);
            f.alpha = std::move(b.alpha);
            f.expected = std::move(b.expected);
            f.firefly_expected = std::move(b.firefly_expected);
            f.highlight = std::move(b.highlight);
            f.touched = std::move(b.touched);
            s.buffers = std::move(b.color);
            s.truth = &s.f;
            finish(s);
        }
}

std::string shared_dir(const char* scene) { return std::string(FIREFLY_SHARED_DATA) + "/" + scene + "/"; }

// A real render with half buffers and variance (PFM copies of the EXR files) in dir, named
// scene in the tables.
bool load_halves_render(scene_data& s, const std::string& scene, const std::string& dir) {
    firefly_tools::pfm_image img[5];
    const char* files[5] = {"a_color", "a_variance", "b_color", "b_variance", "reference"};
    for (int i = 0; i < 5; ++i) {
        const std::string err = firefly_tools::read_pfm(dir + files[i] + ".pfm", img[i]);
        if (!err.empty() || img[i].channels != 3 || img[i].width != img[0].width || img[i].height != img[0].height) {
            std::fprintf(stderr, "note: %s: %s; its rows are skipped\n", scene.c_str(), err.empty() ? "bad size" : err.c_str());
            return false;
        }
    }
    s.name = scene;
    s.f.width = img[0].width;
    s.f.height = img[0].height;
    s.f.color[0] = std::move(img[0].pixels);
    s.f.variance[0] = std::move(img[1].pixels);
    s.f.color[1] = std::move(img[2].pixels);
    s.f.variance[1] = std::move(img[3].pixels);
    s.f.expected = std::move(img[4].pixels);
    finish(s);
    return true;
}

// Half h of K seed renders: the mean of its K/2 renders, and the variance of that mean from
// their spread (sample variance / (K/2)).
void seed_half(scene_data& s, int h) {
    const std::size_t n = static_cast<std::size_t>(s.f.width) * s.f.height * 3;
    const int per = static_cast<int>(s.buffers.size()) / 2;
    s.f.color[h].assign(n, 0.0f);
    s.f.variance[h].assign(n, 0.0f);
    for (std::size_t i = 0; i < n; ++i) {
        double sum = 0, sum2 = 0;
        for (int j = h * per; j < (h + 1) * per; ++j) sum += s.buffers[j][i];
        const double m = sum / per;
        for (int j = h * per; j < (h + 1) * per; ++j) sum2 += (s.buffers[j][i] - m) * (s.buffers[j][i] - m);
        s.f.color[h][i] = static_cast<float>(m);
        s.f.variance[h][i] = static_cast<float>(sum2 / (per - 1) / per);
    }
}

bool file_exists(const std::string& path) {
    struct stat st;
    return ::stat(path.c_str(), &st) == 0;
}

// K renders with different seeds, dir/render_0.exr ... (R, G, B; K even, >= 4: every one
// present is read), named scene: K buffers, and split K/2 + K/2 into two halves whose variance
// is the renders' spread.
bool load_seed_renders(scene_data& s, const std::string& scene, const std::string& dir, const std::string& reference) {
    firefly_tools::pfm_image ref;
    std::string err = firefly_tools::read_pfm(reference, ref);
    for (int k = 0; err.empty(); ++k) {
        const std::string path = dir + "render_" + std::to_string(k) + ".exr";
        if (!file_exists(path)) break;
        firefly_tools::image img;
        err = firefly_tools::read_exr(path, {"R", "G", "B"}, img);
        if (err.empty() && (img.width != ref.width || img.height != ref.height)) err = "render size differs from the reference";
        if (err.empty()) s.buffers.push_back(std::move(img.pixels));
    }
    if (err.empty() && s.buffers.empty()) err = dir + "render_0.exr: not found";
    if (err.empty() && (s.buffers.size() < 4 || s.buffers.size() % 2)) err = "needs an even number of renders, at least 4";
    if (!err.empty()) {
        std::fprintf(stderr, "note: %s: %s; its rows are skipped\n", scene.c_str(), err.c_str());
        return false;
    }
    s.name = scene;
    s.f.width = ref.width;
    s.f.height = ref.height;
    s.f.expected = std::move(ref.pixels);
    seed_half(s, 0);
    seed_half(s, 1);
    finish(s);
    return true;
}

// FIREFLY_ACCURACY_RENDERS=DIR[:DIR...]: more renders, a user's own, in the same tables. A folder
// laid out as ../shared/data's half-buffer ones (a_color.pfm, a_variance.pfm, b_color.pfm,
// b_variance.pfm, reference.pfm) is a scene named by the folder; render_0.exr ... beside the
// reference (seed renders, bench/renders/halves.py --renders) one named folder-seeds.
std::vector<std::string> extra_render_dirs() {
    std::vector<std::string> dirs;
    const char* env = std::getenv("FIREFLY_ACCURACY_RENDERS");
    for (std::string rest = env ? env : ""; !rest.empty();) {
        const std::size_t at = rest.find(':');
        std::string dir = rest.substr(0, at);
        while (dir.size() > 1 && dir.back() == '/') dir.pop_back();
        if (!dir.empty()) dirs.push_back(dir);
        rest = at == std::string::npos ? "" : rest.substr(at + 1);
    }
    return dirs;
}

std::string folder_name(const std::string& dir) {
    const std::size_t at = dir.find_last_of('/');
    return at == std::string::npos ? dir : dir.substr(at + 1);
}

int register_all() {
    int w = 2048, h = 1080;
    if (const char* s = std::getenv("FIREFLY_ACCURACY_SIZE")) std::sscanf(s, "%dx%d", &w, &h);
    benchmark::AddCustomContext("simulated_frame", std::to_string(w) + "x" + std::to_string(h));
    static std::map<std::string, scene_data> scenes;
    add_simulated(scenes, w, h);
    add_buffer_scenes(scenes, w, h);
    for (auto& [name, s] : scenes) register_scene(&s, 2);
    static std::vector<std::unique_ptr<scene_data>> real;  // registered by address
    std::string names;  // the renders' scene names, for the report (what is not simulated)
    auto add = [&](auto&& load) {  // load(scene_data&) -> whether it loaded
        auto s = std::make_unique<scene_data>();
        if (!load(*s)) return;
        register_scene(s.get(), 3);
        names += (names.empty() ? "" : ",") + s->name;
        real.push_back(std::move(s));
    };
    for (const char* scene : {"cycles-caustics", "cycles-interior"})
        add([&](scene_data& s) { return load_halves_render(s, scene, shared_dir(scene)); });
    add([&](scene_data& s) {
        return load_seed_renders(s, "cycles-caustics-seeds", shared_dir("cycles-caustics-seeds"),
                                 shared_dir("cycles-caustics") + "reference.pfm");
    });
    for (const std::string& dir : extra_render_dirs()) {
        const std::string name = folder_name(dir), d = dir + "/";
        if (file_exists(d + "a_color.pfm")) add([&](scene_data& s) { return load_halves_render(s, name, d); });
        if (file_exists(d + "render_0.exr"))
            add([&](scene_data& s) { return load_seed_renders(s, name + "-seeds", d, d + "reference.pfm"); });
    }
    benchmark::AddCustomContext("renders", names);
    return 0;
}
const int registered = register_all();

}  // namespace
