// Accuracy against time: every method and configuration on every named simulated scene
// (2048x1080 by default; FIREFLY_ACCURACY_SIZE=WxH to change), and on the real render in
// ../shared/data when present. Each benchmark's time is one frame (both halves); its
// counters are the ground-truth metrics of firefly/sim/metrics.hpp. Run with
// --benchmark_format=json and turn the output into a table and a Pareto plot with
// bench/accuracy_report.py.
#include <benchmark/benchmark.h>

#include <firefly/firefly.hpp>
#include <firefly/sim/metrics.hpp>
#include <firefly/sim/scene.hpp>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "../bench/peers.hpp"
#include "pfm.hpp"

using namespace firefly;

namespace {

using method = std::function<void(half_buffer<float>&, half_buffer<float>&)>;

struct config {
    std::string name;
    method run;
};

method firefly_with(detector_options o) {
    auto d = std::make_shared<detector>(o);
    return [d](half_buffer<float>& a, half_buffer<float>& b) { (void)d->process(a, b); };
}
method peer(void (*f)(const image_view<float>&, const image_view<float>&)) {
    return [f](half_buffer<float>& a, half_buffer<float>& b) {
        f(a.color, a.variance);
        f(b.color, b.variance);
    };
}

std::vector<config> configs() {
    std::vector<config> c;
    detector_options def;
    c.push_back({"firefly", firefly_with(def)});
    auto with = [&](const char* name, auto edit) {
        detector_options o = def;
        edit(o);
        c.push_back({name, firefly_with(o)});
    };
    with("firefly_paper", [](detector_options& o) {  // the paper as written
        o.highlight.rule = highlight_rule::same_pixel;
        o.highlight.min_excess_z = 0;
    });
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
    c.push_back({"median3x3", peer(&firefly_peers::median3x3)});
    c.push_back({"cycles_prefilter", peer(&firefly_peers::cycles_prefilter)});
    c.push_back({"bcd_spikes", peer([](const image_view<float>& col, const image_view<float>& var) {
                     firefly_peers::bcd_spikes(col, var);
                 })});
    c.push_back({"nrd_clamp", peer(&firefly_peers::nrd_clamp)});
    c.push_back({"clamp4", peer([](const image_view<float>& col, const image_view<float>& var) {
                     firefly_peers::fixed_clamp(col, var, 4.0f);
                 })});
    c.push_back({"clamp16", peer([](const image_view<float>& col, const image_view<float>& var) {
                     firefly_peers::fixed_clamp(col, var, 16.0f);
                 })});
    return c;
}

struct work {
    std::vector<float> col[2], var[2];
    std::vector<float> alpha;
    half_buffer<float> half[2];
    void load(const std::vector<float>* c, const std::vector<float>* v, const std::vector<float>& a, int w, int h) {
        alpha = a;
        for (int i = 0; i < 2; ++i) {
            col[i] = c[i];
            var[i] = v[i];
            half[i].color = *make_image_view(col[i].data(), w, h, 3);
            half[i].variance = *make_image_view(var[i].data(), w, h, 3);
            if (!alpha.empty()) half[i].alpha = *make_image_view(static_cast<const float*>(alpha.data()), w, h, 1);
        }
    }
};

void run_scene(benchmark::State& st, const sim::frame* f, config cfg) {
    work wk;
    for (auto _ : st) {
        st.PauseTiming();
        wk.load(f->color, f->variance, f->alpha, f->width, f->height);
        st.ResumeTiming();
        cfg.run(wk.half[0], wk.half[1]);
    }
    const std::vector<float>* cleaned[2] = {&wk.col[0], &wk.col[1]};
    const sim::accuracy a = sim::evaluate(*f, cleaned);
    st.counters["recall"] = a.recall;
    st.counters["precision"] = a.precision;
    st.counters["false_positive"] = a.false_positive;
    st.counters["highlight_kept"] = a.highlight_kept;
    st.counters["relmse"] = a.relmse;
}

struct real_frame {
    int w = 0, h = 0;
    std::vector<float> color[2], variance[2], reference;
};

void run_real(benchmark::State& st, const real_frame* f, config cfg) {
    work wk;
    for (auto _ : st) {
        st.PauseTiming();
        wk.load(f->color, f->variance, {}, f->w, f->h);
        st.ResumeTiming();
        cfg.run(wk.half[0], wk.half[1]);
    }
    std::vector<float> combined(f->reference.size());
    std::size_t changed = 0;
    for (std::size_t i = 0; i < combined.size(); ++i) {
        combined[i] = 0.5f * (wk.col[0][i] + wk.col[1][i]);
        changed += wk.col[0][i] != f->color[0][i] || wk.col[1][i] != f->color[1][i];
    }
    st.counters["relmse"] = sim::relmse(combined.data(), f->reference.data(), combined.size() / 3);
    st.counters["changed"] = static_cast<double>(changed) / static_cast<double>(combined.size());
}

int register_all() {
    int w = 2048, h = 1080;
    if (const char* s = std::getenv("FIREFLY_ACCURACY_SIZE")) std::sscanf(s, "%dx%d", &w, &h);
    static std::map<std::string, sim::frame> frames;
    std::vector<std::string> names = sim::scene_names();
    names.push_back("highlights@16spp");  // hard: few samples make real highlights noisy
    names.push_back("production@16spp");
    for (const std::string& name : names) {
        const std::size_t at = name.find('@');
        sim::scene sc = sim::named_scene(name.substr(0, at), w, h, 1);
        if (at != std::string::npos) sc.spp = std::atoi(name.c_str() + at + 1);
        frames[name] = sim::simulate(sc);
        for (const config& c : configs())
            benchmark::RegisterBenchmark(("accuracy/" + name + "/" + c.name).c_str(), run_scene, &frames[name], c)
                ->Unit(benchmark::kMillisecond)
                ->Iterations(2);
    }
    static real_frame real;
    const std::string dir = std::string(FIREFLY_SHARED_DATA) + "/cycles-caustics/";
    firefly_tools::pfm_image img[5];
    const char* files[5] = {"a_color", "a_variance", "b_color", "b_variance", "reference"};
    bool ok = true;
    for (int i = 0; i < 5 && ok; ++i) ok = firefly_tools::read_pfm(dir + files[i] + ".pfm", img[i]).empty();
    if (ok) {
        real.w = img[0].width;
        real.h = img[0].height;
        real.color[0] = img[0].pixels;
        real.variance[0] = img[1].pixels;
        real.color[1] = img[2].pixels;
        real.variance[1] = img[3].pixels;
        real.reference = img[4].pixels;
        for (const config& c : configs())
            benchmark::RegisterBenchmark(("accuracy/cycles-caustics/" + c.name).c_str(), run_real, &real, c)
                ->Unit(benchmark::kMillisecond)
                ->Iterations(3);
    } else {
        std::fprintf(stderr, "note: %s absent; the real-render rows are skipped\n", dir.c_str());
    }
    return 0;
}
const int registered = register_all();

}  // namespace
