// Speed of firefly, always next to the reference it is judged against: copy_inputs, the
// time to copy both half buffers of the frame (RGB float colour + RGB float variance per
// half). Quote ratios from one run: the machines are shared and noisy.
#include <benchmark/benchmark.h>

#include <firefly/firefly.hpp>
#include <firefly/sim/scene.hpp>

#include <cstring>
#include <map>
#include <random>
#include <vector>

using namespace firefly;

namespace {

// One simulated frame per size: sparse-ish production mix at ~0.5% firefly pixels per half.
const sim::frame& frame_of(int w, int h) {
    static std::map<std::pair<int, int>, sim::frame> cache;
    auto it = cache.find({w, h});
    if (it == cache.end()) {
        sim::scene s = sim::named_scene("highlights", w, h, 42);
        it = cache.emplace(std::make_pair(w, h), sim::simulate(s)).first;
    }
    return it->second;
}

struct working_copy {
    std::vector<float> col[2], var[2];
    half_buffer<float> half[2];
    explicit working_copy(const sim::frame& f) {
        for (int i = 0; i < 2; ++i) {
            col[i] = f.color[i];
            var[i] = f.variance[i];
            half[i].color = *make_image_view(col[i].data(), f.width, f.height, 3);
            half[i].variance = *make_image_view(var[i].data(), f.width, f.height, 3);
        }
    }
    void restore(const sim::frame& f) {
        for (int i = 0; i < 2; ++i) {
            std::memcpy(col[i].data(), f.color[i].data(), f.color[i].size() * 4);
            std::memcpy(var[i].data(), f.variance[i].data(), f.variance[i].size() * 4);
        }
    }
};

void copy_inputs(benchmark::State& st) {
    const int w = static_cast<int>(st.range(0)), h = static_cast<int>(st.range(1));
    const sim::frame& f = frame_of(w, h);
    working_copy c(f);
    for (auto _ : st) {
        c.restore(f);
        benchmark::DoNotOptimize(c.col[0].data());
        benchmark::ClobberMemory();
    }
    st.SetBytesProcessed(static_cast<std::int64_t>(st.iterations()) * static_cast<std::int64_t>(f.pixels()) * 4 * 12);
}
BENCHMARK(copy_inputs)->Args({256, 256})->Args({2048, 1080})->Args({4096, 2160})->Unit(benchmark::kMillisecond)
    ->Name("copy_inputs")->ArgNames({"w", "h"});

// Detection only (stddev, bound, ESD on both halves, the half-buffer checks); the inputs are
// not modified. warm: the lambda cache is kept; cold: emptied before every frame.
void detect(benchmark::State& st, bool warm) {
    const int w = static_cast<int>(st.range(0)), h = static_cast<int>(st.range(1));
    const sim::frame& f = frame_of(w, h);
    working_copy c(f);
    detector_options o;
    o.reconstruct = false;
    detector d(o, executor::threads(static_cast<unsigned>(st.range(2))));
    frame_report r = d.process(c.half[0], c.half[1]);
    for (auto _ : st) {
        if (!warm) d.lambdas().clear();
        r = d.process(c.half[0], c.half[1]);
        benchmark::DoNotOptimize(r);
    }
    st.counters["outliers"] = static_cast<double>(r.half[0].outliers + r.half[1].outliers);
    st.counters["lambdas_per_frame"] = static_cast<double>(r.lambdas_computed);
}
BENCHMARK_CAPTURE(detect, warm, true)
    ->Args({256, 256, 1})->Args({2048, 1080, 1})->Args({2048, 1080, 2})
    ->ArgNames({"w", "h", "threads"})->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(detect, cold, false)
    ->Args({256, 256, 1})->Args({2048, 1080, 1})
    ->ArgNames({"w", "h", "threads"})->Unit(benchmark::kMillisecond)->UseRealTime();

// The whole pipeline, cleaning both halves in place (inputs restored outside the timing).
void pipeline(benchmark::State& st) {
    const int w = static_cast<int>(st.range(0)), h = static_cast<int>(st.range(1));
    const unsigned threads = static_cast<unsigned>(st.range(2));
    const sim::frame& f = frame_of(w, h);
    working_copy c(f);
    detector d(detector_options{}, executor::threads(threads));
    frame_report r = d.process(c.half[0], c.half[1]);
    for (auto _ : st) {
        st.PauseTiming();
        c.restore(f);
        st.ResumeTiming();
        r = d.process(c.half[0], c.half[1]);
        benchmark::DoNotOptimize(r);
    }
    st.counters["fireflies"] = static_cast<double>(r.half[0].fireflies + r.half[1].fireflies);
    st.counters["phase2_iterations"] = std::max(r.half[0].phase2_iterations, r.half[1].phase2_iterations);
    st.counters["scratch_bytes_per_pixel_per_half"] =
        static_cast<double>(r.scratch_bytes) / (2.0 * static_cast<double>(f.pixels()));
}
BENCHMARK(pipeline)
    ->Args({256, 256, 1})
    ->Args({2048, 1080, 1})
    ->Args({2048, 1080, 2})
    ->Args({4096, 2160, 1})
    ->Args({4096, 2160, 2})
    ->ArgNames({"w", "h", "threads"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// What accuracy costs in time: one lambda per method, over k from 3 to 1e7 (alpha 0.05),
// with its largest relative error against the exact method as a counter.
void lambda(benchmark::State& st, lambda_method m) {
    std::vector<std::size_t> ks;
    for (double k = 3; k < 1e7; k *= 1.05) ks.push_back(static_cast<std::size_t>(k));
    double worst = 0;
    for (std::size_t k : ks) {
        const double e = esd_lambda(k, 0.05, false, lambda_method::exact);
        worst = std::max(worst, std::fabs(esd_lambda(k, 0.05, false, m) - e) / e);
    }
    std::size_t i = 0;
    for (auto _ : st) {
        benchmark::DoNotOptimize(esd_lambda(ks[i], 0.05, false, m));
        if (++i == ks.size()) i = 0;
    }
    st.counters["max_rel_error"] = worst;
}
BENCHMARK_CAPTURE(lambda, exact, lambda_method::exact);
BENCHMARK_CAPTURE(lambda, hill, lambda_method::hill);
BENCHMARK_CAPTURE(lambda, normal, lambda_method::normal);

// The top-m selection of the generalized ESD: a heap over all values (the generic API)
// against the detector's way, only the values above the modified Z-score cutoff.
std::vector<float> esd_values(std::size_t n) {
    std::mt19937 g(7);
    std::gamma_distribution<float> d(4.0f, 0.01f);
    std::vector<float> v(n);
    for (auto& x : v) x = d(g);
    for (std::size_t i = 0; i < n; i += 211) v[i] *= 500.0f;  // ~0.5% outliers
    return v;
}
void esd_heap(benchmark::State& st) {
    const auto v = esd_values(static_cast<std::size_t>(st.range(0)));
    lambda_cache cache;
    std::vector<double> scratch;
    esd_options o;
    std::size_t m = 0;
    for (auto _ : st) {
        const bound_result b = modified_zscore_bound_if(
            v.size(), [&](std::size_t i) { return static_cast<double>(v[i]); }, [](std::size_t) { return true; },
            3.5, scratch);
        o.max_outliers = m = b.count;
        benchmark::DoNotOptimize(generalized_esd(v.data(), v.size(), o, cache));
    }
    st.counters["m"] = static_cast<double>(m);
}
void esd_threshold(benchmark::State& st) {
    const auto v = esd_values(static_cast<std::size_t>(st.range(0)));
    lambda_cache cache;
    std::vector<double> scratch;
    esd_options o;
    for (auto _ : st) {
        const bound_result b = modified_zscore_bound_if(
            v.size(), [&](std::size_t i) { return static_cast<double>(v[i]); }, [](std::size_t) { return true; },
            3.5, scratch);
        std::vector<std::uint32_t> idx;
        for (std::size_t i = 0; i < v.size(); ++i)
            if (b.above(v[i])) idx.push_back(static_cast<std::uint32_t>(i));
        std::sort(idx.begin(), idx.end(), [&](std::uint32_t a, std::uint32_t c) { return v[a] > v[c] || (v[a] == v[c] && a < c); });
        std::vector<double> removed(idx.size());
        for (std::size_t j = 0; j < idx.size(); ++j) removed[j] = v[idx[j]];
        const summary rest = summary_of(v.size(), [&](std::size_t i) { return static_cast<double>(v[i]); },
                                        [&](std::size_t i) { return !b.above(v[i]); });
        esd_result r;
        o.max_outliers = idx.size();
        detail::esd_from_removals(removed.data(), idx.size(), rest, v.size(), o, cache, r);
        benchmark::DoNotOptimize(r);
    }
}
BENCHMARK(esd_heap)->Arg(1 << 20)->Unit(benchmark::kMillisecond);
BENCHMARK(esd_threshold)->Arg(1 << 20)->Unit(benchmark::kMillisecond);

}  // namespace
