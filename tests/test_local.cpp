// The local, brightness-invariant firefly test (local_test.hpp): its false-alarm promise on
// frames without fireflies, recall on moderate fireflies, and the edges.
#include <firefly/local_test.hpp>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "catch.hpp"
#include "symmetry.hpp"

using namespace firefly;

namespace {

// The test's own generator (splitmix64 seeding, xoshiro256**, Box-Muller): the frames do not
// change when the simulator does.
struct test_rng {
    std::uint64_t s[4];
    explicit test_rng(std::uint64_t seed) {
        for (auto& v : s) {
            seed += 0x9E3779B97F4A7C15ull;
            std::uint64_t z = seed;
            z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
            z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
            v = z ^ (z >> 31);
        }
    }
    static std::uint64_t rotl(std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }
    std::uint64_t next() {
        const std::uint64_t r = rotl(s[1] * 5, 7) * 9, t = s[1] << 17;
        s[2] ^= s[0];
        s[3] ^= s[1];
        s[1] ^= s[2];
        s[0] ^= s[3];
        s[2] ^= t;
        s[3] = rotl(s[3], 45);
        return r;
    }
    double uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }
    double normal() {
        const double u = std::max(uniform(), 1e-300), v = uniform();
        return std::sqrt(-2.0 * std::log(u)) * std::cos(6.283185307179586 * v);
    }
};

// Gamma(k, 1) by Marsaglia and Tsang (k < 1 through the k + 1 boost).
double gamma_draw(test_rng& r, double k) {
    if (k < 1.0) {
        const double u = std::max(r.uniform(), 1e-300);
        return gamma_draw(r, k + 1.0) * std::pow(u, 1.0 / k);
    }
    const double d = k - 1.0 / 3.0, c = 1.0 / std::sqrt(9.0 * d);
    for (;;) {
        double x, v;
        do {
            x = r.normal();
            v = 1.0 + c * x;
        } while (v <= 0);
        v = v * v * v;
        const double u = r.uniform();
        if (u < 1.0 - 0.0331 * x * x * x * x) return d * v;
        if (std::log(std::max(u, 1e-300)) < 0.5 * x * x + d * (1.0 - v + std::log(v))) return d * v;
    }
}

// A frame of two half buffers (grey RGB, variance of the mean) whose samples are gamma(k)
// around a base that spans three decades left to right, with fine detail (6x lines, an 8x
// checker), highlights (25x, per-sample shape 0.16 in both halves), a black background with
// alpha outside a disk, and optionally fireflies: one sample that makes the half's pixel
// `multiplier` times its value, multiplier log-uniform in [ff_lo, ff_hi].
struct test_frame {
    int w = 0, h = 0;
    std::vector<float> color[2], variance[2], alpha;
    std::vector<std::uint8_t> firefly[2];
    std::vector<std::uint8_t> highlight;
    local_half<float> half(int i) const {
        local_half<float> v;
        v.color = *make_image_view(color[i].data(), w, h, 3);
        v.variance = *make_image_view(variance[i].data(), w, h, 3);
        v.alpha = *make_image_view(alpha.data(), w, h, 1);
        return v;
    }
};

struct frame_spec {
    int w = 64, h = 64, spp = 16;
    double shape = 1.0, base = 1.0;
    bool decades = true, detail = true, highlights = true, background = true;
    double ff_rate = 0.0, ff_lo = 2.0, ff_hi = 20.0;
    std::uint64_t seed = 1;
};

test_frame make_frame(const frame_spec& s) {
    test_frame f;
    f.w = s.w;
    f.h = s.h;
    const std::size_t n = static_cast<std::size_t>(s.w) * static_cast<std::size_t>(s.h);
    test_rng layout(s.seed * 7919u + 3u);
    std::vector<double> mu(n), shape(n, s.shape);
    f.highlight.assign(n, 0);
    f.alpha.assign(n, 1.0f);
    for (int y = 0; y < s.h; ++y)
        for (int x = 0; x < s.w; ++x) {
            const std::size_t i = static_cast<std::size_t>(y) * static_cast<std::size_t>(s.w) + static_cast<std::size_t>(x);
            double b = s.base * (s.decades ? 0.01 * std::pow(1000.0, static_cast<double>(x) / std::max(s.w - 1, 1)) : 1.0);
            if (s.detail && (x % 16 == 5 || y % 24 == 7)) b *= 6.0;
            if (s.detail && x >= s.w / 2 && x < s.w / 2 + 16 && y >= s.h / 4 && y < s.h / 4 + 16 && ((x + y) & 1)) b *= 8.0;
            mu[i] = b;
            if (s.background) {
                const double u = (x + 0.5 - 0.5 * s.w) / (0.46 * s.w), v = (y + 0.5 - 0.5 * s.h) / (0.46 * s.h);
                if (u * u + v * v >= 1.0) {
                    mu[i] = 0.0;
                    f.alpha[i] = 0.0f;
                }
            }
        }
    if (s.highlights)
        for (int k = 0; k < std::max(1, s.w * s.h / 2048); ++k) {
            const int cx = static_cast<int>(layout.uniform() * s.w), cy = static_cast<int>(layout.uniform() * s.h);
            for (int y = std::max(cy - 1, 0); y <= std::min(cy + 1, s.h - 1); ++y)
                for (int x = std::max(cx - 1, 0); x <= std::min(cx + 1, s.w - 1); ++x) {
                    const std::size_t i = static_cast<std::size_t>(y) * static_cast<std::size_t>(s.w) + static_cast<std::size_t>(x);
                    if (mu[i] > 0) {
                        if (!f.highlight[i]) mu[i] *= 25.0;
                        shape[i] = 0.16;
                        f.highlight[i] = 1;
                    }
                }
        }
    const double nspp = s.spp;
    for (int half = 0; half < 2; ++half) {
        test_rng r(s.seed * 0x9E3779B97F4A7C15ull + 101u + static_cast<std::uint64_t>(half));
        f.color[half].assign(n * 3, 0.0f);
        f.variance[half].assign(n * 3, 0.0f);
        f.firefly[half].assign(n, 0);
        for (std::size_t i = 0; i < n; ++i) {
            if (!(mu[i] > 0)) continue;
            const bool ff = s.ff_rate > 0 && r.uniform() < s.ff_rate;
            const double mult = std::exp(std::log(s.ff_lo) + r.uniform() * (std::log(s.ff_hi) - std::log(s.ff_lo)));
            double sum = 0, sum2 = 0;
            for (int j = 0; j < s.spp; ++j) {
                double v = mu[i] / shape[i] * gamma_draw(r, shape[i]);
                if (ff && j == 0) v = mu[i] * ((mult - 1.0) * nspp + 1.0);
                sum += v;
                sum2 += v * v;
            }
            const double mean = sum / nspp;
            const double var_mean = std::max(sum2 - sum * mean, 0.0) / (nspp - 1) / nspp;
            for (int c = 0; c < 3; ++c) {
                f.color[half][i * 3 + static_cast<std::size_t>(c)] = static_cast<float>(mean);
                f.variance[half][i * 3 + static_cast<std::size_t>(c)] = static_cast<float>(var_mean);
            }
            f.firefly[half][i] = ff ? 1 : 0;
        }
    }
    return f;
}

local_test_result run(const test_frame& f, const local_test_options& o = {}) {
    local_test_scratch scratch;
    local_test_result res;
    const status st = local_test(f.half(0), f.half(1), o, scratch, res);
    REQUIRE(st.ok());
    return res;
}

// Smallest x with P(Poisson(mu) >= x) <= p: the most flags a promise of mean mu allows at
// significance p. A Poisson bound is conservative for the binomial with the same mean.
std::size_t poisson_upper(double mu, double p) {
    double term = std::exp(-mu), cdf = term;
    std::size_t x = 0;
    while (1.0 - cdf > p && x < 100000) {
        ++x;
        term *= mu / static_cast<double>(x);
        cdf += term;
    }
    return x + 1;
}

}  // namespace

TEST_CASE("local test: false alarms on frames without fireflies keep the promise", "[local][calibration]") {
    // Per-sample gamma noise of shape 1 to 16, 4 to 1024 samples per half, three decades,
    // fine detail, highlights, black background and alpha. Frame sizes keep the sample count
    // per configuration similar; several seeds each. The promise is checked over all frames
    // and per sample count (Bonferroni over the groups), at two levels q.
    const double shapes[] = {1.0, 4.0, 16.0};
    struct cfg {
        int spp, size, seeds;
    };
    const cfg cfgs[] = {{4, 160, 3}, {16, 128, 2}, {64, 96, 2}, {256, 64, 1}, {1024, 40, 1}};
    constexpr int groups = 5;
    const double qs[] = {1e-3, 1e-4};
    std::size_t flagged[2][groups + 1] = {}, tested[groups + 1] = {};
    std::ostringstream by_spp;  // where the flags are, for a failure's message
    std::uint64_t seed = 1;
    for (const double k : shapes)
        for (int g = 0; g < groups; ++g)
            for (int s = 0; s < cfgs[g].seeds; ++s) {
                frame_spec spec;
                spec.w = spec.h = cfgs[g].size;
                spec.spp = cfgs[g].spp;
                spec.shape = k;
                spec.seed = seed++;
                const test_frame f = make_frame(spec);
                by_spp << "k " << k << " spp " << spec.spp << ":";
                for (int j = 0; j < 2; ++j) {
                    local_test_options o;
                    o.false_alarm = qs[j];
                    const local_test_result r = run(f, o);
                    std::size_t n = 0, on_highlights = 0;
                    for (const auto& fl : r.half) {
                        n += fl.index.size();
                        for (const std::uint32_t i : fl.index) on_highlights += f.highlight[i];
                    }
                    flagged[j][g] += n;
                    flagged[j][groups] += n;
                    if (j == 0) {
                        tested[g] += 2 * r.tested;
                        tested[groups] += 2 * r.tested;
                    }
                    by_spp << " " << n << " (" << on_highlights << " on highlights)" << (j == 0 ? " /" : " of ")
                           << (j == 0 ? "" : std::to_string(2 * r.tested) + "\n");
                }
            }
    INFO(by_spp.str());
    for (int j = 0; j < 2; ++j)
        for (int g = 0; g <= groups; ++g) {
            const double mu = qs[j] * static_cast<double>(tested[g]);
            const std::size_t allowed = poisson_upper(mu, g == groups ? 1e-3 : 1e-3 / groups);
            INFO("q " << qs[j] << ", " << (g == groups ? std::string("all") : "spp " + std::to_string(cfgs[g].spp))
                      << ": " << flagged[j][g] << " flagged of " << tested[g] << " pixel-halves (promise " << mu
                      << ", allowed " << allowed << ")");
            CHECK(flagged[j][g] < allowed);
        }
}

TEST_CASE("local test: an understated variance breaks the promise (the check can fail)", "[local]") {
    // The same kind of frame, but the variance given is a quarter of the variance of the mean:
    // the statistic is then twice too large, and the share flagged far exceeds q.
    frame_spec spec;
    spec.w = spec.h = 96;
    spec.spp = 16;
    spec.shape = 4.0;
    const test_frame f = make_frame(spec);
    local_test_options o;
    o.false_alarm = 1e-4;
    const local_test_result honest = run(f, o);
    o.variance_scale = 0.25;
    const local_test_result under = run(f, o);
    const double mu = o.false_alarm * 2.0 * static_cast<double>(under.tested);
    const std::size_t n_honest = honest.half[0].index.size() + honest.half[1].index.size();
    const std::size_t n_under = under.half[0].index.size() + under.half[1].index.size();
    CHECK(n_honest < poisson_upper(mu, 1e-3));
    CHECK(n_under > 10 * poisson_upper(mu, 1e-3));
}

TEST_CASE("local test: recall on moderate fireflies in a dark noisy frame", "[local]") {
    frame_spec s;
    s.w = s.h = 128;
    s.spp = 64;
    s.shape = 4.0;
    s.base = 0.02;
    s.decades = false;
    s.highlights = false;
    s.ff_rate = 0.01;  // 2-20x the pixel
    const test_frame f = make_frame(s);
    const local_test_result r = run(f);
    std::size_t hits = 0, fireflies = 0, false_pos = 0;
    for (int h = 0; h < 2; ++h) {
        for (const std::uint32_t i : r.half[h].index) (f.firefly[h][i] ? hits : false_pos) += 1;
        for (const std::uint8_t v : f.firefly[h]) fireflies += v;
    }
    INFO(hits << " of " << fireflies << " fireflies, " << false_pos << " false positives");
    REQUIRE(fireflies > 200);
    CHECK(static_cast<double>(hits) >= 0.95 * static_cast<double>(fireflies));
    CHECK(false_pos <= 3);
    for (int h = 0; h < 2; ++h)
        for (const float sc : r.half[h].score) CHECK(sc > 1.0f);
}

TEST_CASE("local test: the spatial test reaches moderate fireflies the pair test cannot", "[local]") {
    // 8 samples of shape 1 per half: a pixel 4-8x its other half is ordinary for the pair
    // test (m ~ 8), but far above the level 16 neighbours agree on.
    frame_spec s;
    s.w = s.h = 96;
    s.spp = 8;
    s.shape = 1.0;
    s.decades = s.detail = s.highlights = s.background = false;
    s.ff_rate = 0.01;
    s.ff_lo = 4.0;
    s.ff_hi = 8.0;
    const test_frame f = make_frame(s);
    local_test_options o;
    std::size_t hits[2] = {0, 0}, false_pos[2] = {0, 0}, fireflies = 0;
    for (int spatial = 0; spatial < 2; ++spatial) {
        o.spatial = spatial != 0;
        const local_test_result r = run(f, o);
        for (int h = 0; h < 2; ++h)
            for (const std::uint32_t i : r.half[h].index) (f.firefly[h][i] ? hits : false_pos)[spatial] += 1;
        if (!o.spatial) CHECK(r.spatial == 0);
    }
    for (int h = 0; h < 2; ++h)
        for (const std::uint8_t v : f.firefly[h]) fireflies += v;
    INFO("pair only " << hits[0] << ", with spatial " << hits[1] << " of " << fireflies << "; false positives "
                      << false_pos[0] << ", " << false_pos[1]);
    REQUIRE(fireflies > 100);
    CHECK(static_cast<double>(hits[0]) < 0.5 * static_cast<double>(fireflies));
    CHECK(static_cast<double>(hits[1]) > 0.7 * static_cast<double>(fireflies));
    CHECK(false_pos[1] <= 3);
}

TEST_CASE("local test: F upper tail against the closed form at d1 = 2", "[local]") {
    // P(F(2, d2) > f) = (1 + 2 f / d2)^(-d2 / 2)
    for (const double d2 : {2.0, 7.5, 32.0, 300.0, 5000.0})
        for (const double f : {0.5, 1.0, 3.0, 10.0, 40.0}) {
            const double want = std::pow(1.0 + 2.0 * f / d2, -0.5 * d2);
            const double got = detail::f_upper_tail(f, 2.0, d2);
            INFO("d2 " << d2 << ", f " << f << ": " << got << " against " << want);
            CHECK(std::fabs(got - want) <= 1e-10 * want + 1e-300);
        }
}

TEST_CASE("local test: the F tail writes no global state (no data race across threads)", "[local]") {
    // glibc's lgamma stores the sign of Gamma in the global `signgam`; the local test's bands run
    // on the caller's threads, so that write was a race a ThreadSanitizer build reported.
#if defined(__GLIBC__) && defined(__USE_MISC)
    signgam = 12345;
    const double p = detail::f_log_upper_tail(3.0, 8.0, 40.0) + detail::f_upper_tail(3.0, 8.0, 40.0);
    CHECK(std::isfinite(p));
    CHECK(signgam == 12345);
    for (const double x : {1e-300, 0.5, 1.0, 2.5, 30.0, 1e10})
        CHECK(detail::log_gamma_positive(x) == std::lgamma(x));  // the same values
#else
    SUCCEED("no signgam outside glibc");
#endif
}

TEST_CASE("local test: a bright noisy region without fireflies is left alone", "[local]") {
    frame_spec s;
    s.w = s.h = 128;
    s.spp = 16;
    s.shape = 1.0;  // every pixel noisy
    s.decades = false;
    s.highlights = false;
    s.background = false;
    test_frame f = make_frame(s);
    // a bright square, 1000x, with the same relative noise
    for (int h = 0; h < 2; ++h)
        for (int y = 32; y < 96; ++y)
            for (int x = 32; x < 96; ++x)
                for (int c = 0; c < 3; ++c) {
                    const std::size_t j = (static_cast<std::size_t>(y) * 128u + static_cast<std::size_t>(x)) * 3u + static_cast<std::size_t>(c);
                    f.color[h][j] *= 1000.0f;
                    f.variance[h][j] *= 1e6f;
                }
    local_test_options o;
    o.false_alarm = 1e-5;
    const local_test_result r = run(f, o);
    CHECK(r.tested == 128u * 128u);
    CHECK(r.half[0].index.size() + r.half[1].index.size() <= poisson_upper(2.0 * 128 * 128 * 1e-5, 1e-3));
}

TEST_CASE("local test: double colour with float variance gives the float frame's flags", "[local]") {
    frame_spec s;
    s.w = 40;
    s.h = 32;
    s.spp = 16;
    s.ff_rate = 0.03;
    const test_frame f = make_frame(s);
    const local_test_result ref = run(f);
    REQUIRE(ref.half[0].index.size() + ref.half[1].index.size() > 5);
    std::vector<double> colour[2];
    local_half<double, float, float> h[2];
    for (int i = 0; i < 2; ++i) {
        colour[i].assign(f.color[i].begin(), f.color[i].end());
        h[i].color = *make_image_view(colour[i].data(), f.w, f.h, 3);
        h[i].variance = *make_image_view(f.variance[i].data(), f.w, f.h, 3);
        h[i].alpha = *make_image_view(f.alpha.data(), f.w, f.h, 1);
    }
    local_test_scratch scratch;
    local_test_result r;
    REQUIRE(local_test(h[0], h[1], local_test_options{}, scratch, r).ok());
    for (int i = 0; i < 2; ++i) {
        CHECK(r.half[i].index == ref.half[i].index);
        CHECK(r.half[i].score == ref.half[i].score);
    }
}

namespace {

// The frame seen through symmetry t; source_index[i]: the source pixel of pixel i.
test_frame apply(const test_frame& f, const firefly_test::symmetry& t, std::vector<std::uint32_t>& source_index) {
    test_frame g;
    g.w = t.width();
    g.h = t.height();
    source_index.assign(static_cast<std::size_t>(f.w) * static_cast<std::size_t>(f.h), 0);
    for (int y = 0; y < g.h; ++y)
        for (int x = 0; x < g.w; ++x)
            source_index[static_cast<std::size_t>(y) * static_cast<std::size_t>(g.w) + static_cast<std::size_t>(x)] =
                static_cast<std::uint32_t>(t.source(x, y));
    for (int h = 0; h < 2; ++h) {
        g.color[h] = t.apply(f.color[h], 3);
        g.variance[h] = t.apply(f.variance[h], 3);
    }
    g.alpha = t.apply(f.alpha, 1);
    return g;
}

}  // namespace

TEST_CASE("local test: the same flags under the 8 flips and transposes", "[local]") {
    frame_spec s;
    s.w = 48;
    s.h = 40;
    s.spp = 16;
    s.ff_rate = 0.03;
    const test_frame f = make_frame(s);
    const local_test_result ref = run(f);
    REQUIRE(ref.half[0].index.size() + ref.half[1].index.size() > 10);
    for (int m = 1; m < 8; ++m) {
        const firefly_test::symmetry t{m, f.w, f.h};
        std::vector<std::uint32_t> src;
        const test_frame g = apply(f, t, src);
        const local_test_result r = run(g);
        for (int h = 0; h < 2; ++h) {
            std::vector<std::pair<std::uint32_t, float>> got;
            for (std::size_t j = 0; j < r.half[h].index.size(); ++j)
                got.emplace_back(src[r.half[h].index[j]], r.half[h].score[j]);
            std::sort(got.begin(), got.end());
            REQUIRE(got.size() == ref.half[h].index.size());
            for (std::size_t j = 0; j < got.size(); ++j) {
                CHECK(got[j].first == ref.half[h].index[j]);
                CHECK(got[j].second == ref.half[h].score[j]);
            }
            CHECK(std::is_sorted(r.half[h].index.begin(), r.half[h].index.end()));
        }
    }
}

namespace {

// A w x h frame, both halves `value` with relative variance `rel_var`, no alpha.
struct flat_frame {
    int w, h;
    std::vector<float> color[2], variance[2];
    flat_frame(int w_, int h_, float value, float rel_var) : w(w_), h(h_) {
        for (int i = 0; i < 2; ++i) {
            color[i].assign(static_cast<std::size_t>(w * h * 3), value);
            variance[i].assign(static_cast<std::size_t>(w * h * 3), value * value * rel_var);
        }
    }
    void set(int half, int x, int y, float c, float v) {
        for (std::size_t k = 0; k < 3; ++k) {
            color[half][static_cast<std::size_t>(y * w + x) * 3 + k] = c;
            variance[half][static_cast<std::size_t>(y * w + x) * 3 + k] = v;
        }
    }
    local_half<float> half(int i) const {
        local_half<float> v;
        v.color = *make_image_view(color[i].data(), w, h, 3);
        v.variance = *make_image_view(variance[i].data(), w, h, 3);
        return v;
    }
    local_test_result run(const local_test_options& o = {}) const {
        local_test_scratch scratch;
        local_test_result res;
        const status st = local_test(half(0), half(1), o, scratch, res);
        REQUIRE(st.ok());
        for (const auto& f : res.half)
            for (const float sc : f.score) REQUIRE(std::isfinite(sc));
        return res;
    }
};

// Deterministic noise: every pixel of both halves scaled by 1 +- a few percent.
void jitter(flat_frame& f, float amount) {
    std::uint32_t s = 12345u;
    for (int h = 0; h < 2; ++h)
        for (std::size_t i = 0; i < f.color[h].size(); i += 3) {
            s = s * 1664525u + 1013904223u;
            const float m = 1.0f + amount * (static_cast<float>((s >> 8) & 0xffff) / 32768.0f - 1.0f);
            for (std::size_t k = 0; k < 3; ++k) f.color[h][i + k] *= m;
        }
}

}  // namespace

TEST_CASE("local test: edges", "[local]") {
    SECTION("constant image: everything tested, nothing flagged") {
        const flat_frame f(16, 16, 0.5f, 0.01f);
        const local_test_result r = f.run();
        CHECK(r.tested == 256);
        CHECK(r.half[0].index.empty());
        CHECK(r.half[1].index.empty());
        const flat_frame z(16, 16, 0.5f, 0.0f);  // zero variance everywhere
        CHECK(z.run().half[0].index.empty());
    }
    SECTION("1x1: nothing to pool, not flagged; 2x2: the corners are tested") {
        flat_frame one(1, 1, 0.5f, 0.01f);
        one.set(0, 0, 0, 500.0f, 1e4f);
        const local_test_result r1 = one.run();
        CHECK(r1.half[0].index.empty());
        CHECK(r1.half[1].index.empty());
        flat_frame two(2, 2, 0.5f, 0.01f);
        two.set(0, 1, 0, 500.0f, 1e4f);
        const local_test_result r2 = two.run();
        CHECK(r2.tested == 4);
        CHECK(r2.half[0].index == std::vector<std::uint32_t>{1u});
        CHECK(r2.half[1].index.empty());
        local_test_options o;
        o.min_neighbours = 7;  // a corner has 6
        CHECK(two.run(o).half[0].index.empty());
    }
    SECTION("a 1e30 firefly next to 1e-3 pixels") {
        flat_frame f(7, 7, 1e-3f, 0.01f);
        jitter(f, 0.05f);
        f.set(0, 3, 3, 1e30f, FLT_MAX);  // (1e30)^2 does not fit a float
        const local_test_result r = f.run();
        REQUIRE(r.half[0].index.size() == 1);
        CHECK(r.half[0].index[0] == 3u * 7u + 3u);
        CHECK(r.half[0].score[0] > 1.0f);
        CHECK(r.half[1].index.empty());
    }
    SECTION("FLT_MAX colour and variance") {
        flat_frame f(9, 9, 1.0f, 0.01f);
        jitter(f, 0.05f);
        f.set(1, 4, 4, FLT_MAX, FLT_MAX);
        f.set(0, 2, 2, FLT_MAX, 0.0f);
        const local_test_result r = f.run();
        CHECK(r.half[1].index == std::vector<std::uint32_t>{4u * 9u + 4u});
        CHECK(r.half[0].index == std::vector<std::uint32_t>{2u * 9u + 2u});
    }
    SECTION("denormals") {
        const float d = std::numeric_limits<float>::denorm_min();
        flat_frame f(9, 9, 1e4f * d, 0.0f);
        f.set(0, 4, 4, 3e5f * d, d);
        const local_test_result r = f.run();
        CHECK(r.tested == 81);
        CHECK(r.half[1].index.empty());
        flat_frame g(9, 9, 1e4f * d, 0.01f);  // variance underflows to 0 for most pixels
        jitter(g, 0.05f);
        (void)g.run();
    }
    SECTION("all black, and alpha 0 everywhere: nothing tested") {
        flat_frame f(8, 8, 0.0f, 0.0f);
        f.set(0, 4, 4, 5.0f, 1.0f);
        CHECK(f.run().tested == 0);
        flat_frame g(8, 8, 1.0f, 0.01f);
        g.set(0, 4, 4, 50.0f, 1.0f);
        std::vector<float> alpha(64, 0.0f);
        local_half<float> a = g.half(0), b = g.half(1);
        a.alpha = b.alpha = *make_image_view(alpha.data(), 8, 8, 1);
        local_test_scratch scratch;
        local_test_result res;
        REQUIRE(local_test(a, b, local_test_options{}, scratch, res).ok());
        CHECK(res.tested == 0);
        CHECK(res.half[0].index.empty());
    }
    SECTION("non-finite neighbours are left out, and never flagged") {
        flat_frame f(9, 9, 1.0f, 0.01f);
        jitter(f, 0.05f);
        f.set(0, 4, 4, 50.0f, 20.0f);
        f.set(0, 5, 4, std::numeric_limits<float>::quiet_NaN(), 0.01f);
        f.set(1, 3, 4, 1.0f, std::numeric_limits<float>::infinity());
        f.set(0, 4, 5, -std::numeric_limits<float>::infinity(), 0.01f);
        const local_test_result r = f.run();
        CHECK(r.half[0].index == std::vector<std::uint32_t>{4u * 9u + 4u});
        CHECK(r.half[1].index.empty());
        CHECK(r.tested == 81 - 3);
    }
    SECTION("labels from the stddev pass are honoured") {
        flat_frame f(9, 9, 1.0f, 0.01f);
        jitter(f, 0.05f);
        f.set(0, 4, 4, 50.0f, 20.0f);
        std::vector<std::uint8_t> la(81, 0), lb(81, 0);
        la[4 * 9 + 4] = static_cast<std::uint8_t>(pixel_class::ignored);
        local_half<float> a = f.half(0), b = f.half(1);
        a.label = la.data();
        b.label = lb.data();
        local_test_scratch scratch;
        local_test_result res;
        REQUIRE(local_test(a, b, local_test_options{}, scratch, res).ok());
        CHECK(res.half[0].index.empty());
        la[4 * 9 + 4] = 0;
        REQUIRE(local_test(a, b, local_test_options{}, scratch, res).ok());
        CHECK(res.half[0].index == std::vector<std::uint32_t>{4u * 9u + 4u});
    }
}

TEST_CASE("local test: options and views are checked", "[local]") {
    flat_frame f(8, 8, 1.0f, 0.01f);
    local_test_scratch scratch;
    local_test_result res;
    local_test_options o;
    o.false_alarm = 0.0;
    CHECK(local_test(f.half(0), f.half(1), o, scratch, res).code() == errc::invalid_argument);
    o = {};
    o.radius = 0;
    CHECK(check_local_test_options(o).code() == errc::invalid_argument);
    o = {};
    o.variance_scale = std::numeric_limits<double>::quiet_NaN();
    CHECK(check_local_test_options(o).code() == errc::invalid_argument);
    CHECK(check_local_test_options(local_test_options{}).ok());
    flat_frame g(8, 7, 1.0f, 0.01f);
    CHECK(local_test(f.half(0), g.half(1), local_test_options{}, scratch, res).code() == errc::size_mismatch);
}

// The neighbourhood's level that the one-half excess is judged at (pipeline.hpp, noise_floor):
// the median over the window of each neighbour's lower half, centre and unusable neighbours
// left out.
TEST_CASE("local test: the neighbourhood's lower level", "[local]") {
    const int w = 3, h = 3;
    const double nan = std::numeric_limits<double>::quiet_NaN();
    std::vector<double> level[2] = {std::vector<double>(9, 1.0), std::vector<double>(9, 1.0)};
    std::vector<float> pool;
    SECTION("a window's neighbours, the frame's edge and the centre left out") {
        int count[9] = {};
        for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x) detail::for_each_neighbour(w, h, x, y, 1, [&](std::size_t j) {
                    CHECK(j != static_cast<std::size_t>(y * w + x));
                    ++count[y * w + x];
                });
        CHECK(count[0] == 3);  // corner
        CHECK(count[1] == 5);  // edge
        CHECK(count[4] == 8);  // centre of the frame
    }
    SECTION("fireflies in one half of most neighbours do not lift it") {
        for (int j = 0; j < 9; ++j) level[j % 2][static_cast<std::size_t>(j)] = 1e30;  // one half of each
        level[0][4] = level[1][4] = 1e30;                                              // the centre itself
        CHECK(detail::neighbourhood_lower_level(level, w, h, 1, 1, 1, 1, pool) == 1.0);
    }
    SECTION("the median of the lower halves, 1e-3 next to 1e30 finite") {
        const double lower[9] = {1e-3, 2e-3, 3e-3, 4e-3, 0.0, 5e-3, 6e-3, 7e-3, 20e-3};
        for (std::size_t j = 0; j < 9; ++j) {
            level[0][j] = lower[j];
            level[1][j] = 1e30;
        }
        double mad = -1;
        const double got = detail::neighbourhood_lower_level(level, w, h, 1, 1, 1, 1, pool, &mad);
        CHECK(got == Approx(0.5 * (4e-3 + 5e-3)).epsilon(1e-6));  // 8 values: the two middle ones
        // and their MAD: |x - 4.5e-3| = 3.5, 2.5, 1.5, 0.5, 0.5, 1.5, 2.5, 15.5 (e-3), median 2e-3
        // (the mean absolute deviation would be 3.5e-3)
        CHECK(mad == Approx(2e-3).epsilon(1e-6));
    }
    SECTION("neighbours with an unusable half are left out; too few give NaN") {
        for (std::size_t j = 0; j < 9; ++j)
            if (j != 0 && j != 8) level[1][j] = nan;
        level[0][0] = 2.0;
        level[0][8] = 4.0;
        CHECK(detail::neighbourhood_lower_level(level, w, h, 1, 1, 1, 2, pool) == 1.0);  // min(2, 1), min(4, 1)
        CHECK(std::isnan(detail::neighbourhood_lower_level(level, w, h, 1, 1, 1, 3, pool)));
        CHECK(std::isnan(detail::neighbourhood_lower_level(level, 1, 1, 0, 0, 1, 1, pool)));  // 1x1: none
    }
}

TEST_CASE("local test: the level of a line through a pixel", "[local]") {
    const int w = 5, h = 5;
    const double nan = std::numeric_limits<double>::quiet_NaN();
    std::vector<double> level[2] = {std::vector<double>(25, 1.0), std::vector<double>(25, 1.0)};
    auto at = [&](int x, int y) { return static_cast<std::size_t>(y * w + x); };
    auto set = [&](int x, int y, double a, double b) { level[0][at(x, y)] = a, level[1][at(x, y)] = b; };
    SECTION("each direction: the second smallest lower half of the four pixels along it") {
        const int dirs[4][2] = {{1, 0}, {0, 1}, {1, 1}, {1, -1}};  // row, column, both diagonals
        for (const auto& d : dirs) {
            std::vector<double> keep[2] = {level[0], level[1]};
            set(2 + d[0], 2 + d[1], 6.0, 5.0);          // lower 5
            set(2 - d[0], 2 - d[1], 4.0, 7.0);          // lower 4
            set(2 + 2 * d[0], 2 + 2 * d[1], 9.0, 8.0);  // lower 8
            set(2 - 2 * d[0], 2 - 2 * d[1], 0.5, 9.0);  // one low draw: passed over
            set(2, 2, 1e30, 1e30);                      // the pixel itself plays no part
            INFO("direction " << d[0] << "," << d[1]);
            CHECK(detail::neighbourhood_line_level(level, w, h, 2, 2) == 4.0);  // of 0.5, 4, 5, 8
            level[0] = keep[0], level[1] = keep[1];
        }
    }
    SECTION("two bright pixels on a direction, or fireflies in one half, lift it not") {
        set(1, 2, 50.0, 50.0);  // both neighbours of the row, but not the row on
        set(3, 2, 50.0, 50.0);
        CHECK(detail::neighbourhood_line_level(level, w, h, 2, 2) == 1.0);
        for (const int y : {0, 1, 3, 4}) set(2, y, y % 2 ? 1e30 : 1.0, y % 2 ? 1.0 : 1e30);  // the column
        CHECK(detail::neighbourhood_line_level(level, w, h, 2, 2) == 1.0);
    }
    SECTION("1e-3 next to 1e30: exact, finite") {
        for (double& v : level[0]) v = 1e-3;
        for (double& v : level[1]) v = 1e-3;
        for (const int x : {0, 1, 3, 4}) set(x, 2, 1e30, 1e30);
        CHECK(detail::neighbourhood_line_level(level, w, h, 2, 2) == 1e30);
    }
    SECTION("the frame's edge and unusable pixels leave directions out; none gives NaN") {
        CHECK(detail::neighbourhood_line_level(level, w, h, 2, 0) == 1.0);         // the row only
        CHECK(std::isnan(detail::neighbourhood_line_level(level, w, h, 1, 1)));    // no room: none
        CHECK(std::isnan(detail::neighbourhood_line_level(level, 1, 1, 0, 0)));    // 1x1
        level[1][at(4, 0)] = nan;                                                   // the row's end
        CHECK(std::isnan(detail::neighbourhood_line_level(level, w, h, 2, 0)));
        for (const int y : {0, 1, 3, 4}) set(2, y, 3.0, 3.0);                       // the column
        level[1][at(2, 4)] = nan;
        CHECK(detail::neighbourhood_line_level(level, w, h, 2, 2) == 1.0);         // the column is out
    }
}

TEST_CASE("local test: the neighbourhood's lower halves' noise", "[local]") {
    const int w = 3, h = 3;
    local_test_scratch s;
    for (int half = 0; half < 2; ++half) {
        s.level[half].assign(9, 1.0);
        s.rel_var[half].assign(9, 0.25f);
    }
    std::vector<float> pool;
    std::size_t n = 0;
    SECTION("a firefly's half, with its level and its noise, is passed over") {
        for (std::size_t j = 0; j < 9; ++j) {  // one half of every neighbour carries a firefly
            const int hi = static_cast<int>(j % 2);
            s.level[hi][j] = 1e30;
            s.rel_var[hi][j] = 1.0f;
        }
        CHECK(detail::neighbourhood_lower_noise(s, w, h, 1, 1, 1, 1, pool, n) == 0.25);
        CHECK(n == 8);
    }
    SECTION("the median over the neighbours, the centre left out") {
        const float r[9] = {0.1f, 0.2f, 0.3f, 0.4f, 9.0f, 0.5f, 0.6f, 0.7f, 0.8f};
        for (std::size_t j = 0; j < 9; ++j) {
            s.rel_var[0][j] = r[j];
            s.level[1][j] = 2.0;  // half 0 is the lower one
        }
        CHECK(detail::neighbourhood_lower_noise(s, w, h, 1, 1, 1, 1, pool, n) == Approx(0.45).epsilon(1e-6));
        CHECK(n == 8);
    }
    SECTION("unusable neighbours are left out; too few give NaN") {
        for (std::size_t j = 1; j < 8; ++j) s.level[1][j] = std::numeric_limits<double>::quiet_NaN();
        CHECK(detail::neighbourhood_lower_noise(s, w, h, 1, 1, 1, 2, pool, n) == 0.25);  // pixels 0 and 8
        CHECK(n == 2);
        CHECK(std::isnan(detail::neighbourhood_lower_noise(s, w, h, 1, 1, 1, 3, pool, n)));
    }
}

TEST_CASE("local test: a pixel's level against its neighbourhood's", "[local]") {
    // F(4 m, 4 n m / pi): the pixel's mean over both halves (gamma 2 m) against a median of n
    for (const double m : {0.5, 4.0, 64.0})
        for (const double f : {1.5, 3.0, 30.0}) {
            const double d2 = 4.0 / 3.141592653589793 * 8.0 * m;
            INFO("m " << m << ", f " << f);
            CHECK(detail::pixel_level_log_p(f, m, 8) == Approx(std::log(detail::f_upper_tail(f, 4.0 * m, d2))));
            // monotone: brighter, or less noise, is less likely
            CHECK(detail::pixel_level_log_p(f * 1.1, m, 8) < detail::pixel_level_log_p(f, m, 8));
            CHECK(detail::pixel_level_log_p(f, m * 1.1, 8) < detail::pixel_level_log_p(f, m, 8));
        }
    // against an independent evaluation (mpmath, 30 digits): far in the tail too, where the
    // p-value is below the smallest double
    CHECK(detail::pixel_level_log_p(30.0, 4.0, 8) == Approx(-38.6436926).epsilon(1e-8));
    CHECK(detail::pixel_level_log_p(3.0, 64.0, 8) == Approx(-65.8213951).epsilon(1e-8));
    CHECK(detail::pixel_level_log_p(1e30, 4.0, 8) == Approx(-1374.389).epsilon(1e-5));
    CHECK(detail::pixel_level_log_p(1e80, 4.0, 8) == Approx(-3719.783).epsilon(1e-5));
    // above m = 1e4, Paulson's normal point (lgamma would cancel): still monotone, <= 0
    CHECK(detail::pixel_level_log_p(1.0 + 1e-7, 1e14, 8) <= 0.0);
    CHECK(detail::pixel_level_log_p(1.5, 2e4, 8) < detail::pixel_level_log_p(1.4, 2e4, 8));
    CHECK(detail::pixel_level_log_p(1.0, 4.0, 8) == 0.0);  // not above the neighbourhood
    CHECK(detail::pixel_level_log_p(0.2, 4.0, 8) == 0.0);
    CHECK(detail::pixel_level_log_p(3.0, 0.0, 8) == 0.0);  // no noise model: nothing said
    CHECK(detail::pixel_level_log_p(3.0, 4.0, 0) == 0.0);
    // 1e30 times the neighbourhood at a million samples' noise: a finite log
    const double tiny = detail::pixel_level_log_p(1e30, 1e6, 8);
    CHECK(std::isfinite(tiny));
    CHECK(tiny < -1e4);
}

TEST_CASE("local test: levels and relative variances match local_pixel bit for bit", "[local]") {
    // Every special value local_pixel sorts out (NaN, Inf, -0, negative and zero variance,
    // black, negative colour), in pairs of neighbours and at odd widths, for 3 and 1 variance
    // channels: the row pass (two pixels at a time where it can) gives local_pixel's bits.
    const float specials[] = {0.0f, -0.0f, 1.0f, -1.0f, 0.5f, 3e38f, 1e-40f, -2.5f,
                              std::numeric_limits<float>::infinity(), std::numeric_limits<float>::quiet_NaN()};
    test_rng rng(99);
    for (const int w : {1, 2, 7, 16}) {
        for (const int vch : {3, 1}) {
            const int h = 9;
            std::vector<float> col(static_cast<std::size_t>(w) * h * 3), var(static_cast<std::size_t>(w) * h * vch);
            auto pick = [&]() {
                const std::uint64_t r = rng.next();
                return r % 3 == 0 ? specials[(r >> 8) % 10] : static_cast<float>((r >> 11) % 1000) / 100.0f;
            };
            for (float& v : col) v = pick();
            for (float& v : var) v = pick();
            local_half<float> half{*make_image_view(static_cast<const float*>(col.data()), w, h, 3),
                                   *make_image_view(static_cast<const float*>(var.data()), w, h, vch)};
            std::vector<double> level;
            std::vector<float> rel_var;
            detail::local_levels(half, 2.0, level, rel_var);
            for (std::size_t i = 0; i < level.size(); ++i) {
                double l = 0;
                float r = std::numeric_limits<float>::quiet_NaN();
                const bool counts = detail::local_pixel(&col[i * 3], 1, &var[i * vch], 1, 3, vch == 1, 2.0, l, r);
                if (!counts) {
                    CHECK(std::isnan(level[i]));
                    CHECK(std::isnan(rel_var[i]));
                    continue;
                }
                CHECK(std::memcmp(&l, &level[i], sizeof l) == 0);
                if (std::isnan(r))
                    CHECK(std::isnan(rel_var[i]));
                else
                    CHECK(std::memcmp(&r, &rel_var[i], sizeof r) == 0);
            }
        }
    }
}

// The spatial test's screen (Paulson's z at m = 1 / r_other) rules a pixel out only where it
// bounds the exact test. Where the other half is very noisy (r_other >= 4.5) its z has a
// ceiling below z_q: before, a firefly of 1e7 over neighbours at 1 went unflagged where the
// exact test gives p = 2e-7 (flagged from 1e4 to 3e5, then not from 1e6 to 1e9).
TEST_CASE("local test: a very noisy other half does not hide a bright firefly from the spatial test", "[local]") {
    for (const double f : {1e6, 1e7, 1e8, 1e9}) {
        const int w = 5, h = 5;
        std::vector<float> c[2], v[2];
        for (int k = 0; k < 2; ++k) {
            c[k].assign(static_cast<std::size_t>(w * h * 3), 1.0f);
            v[k].assign(c[k].size(), 0.01f);
        }
        for (std::size_t ch = 0; ch < 3; ++ch) {
            c[0][12 * 3 + ch] = static_cast<float>(f);
            v[0][12 * 3 + ch] = static_cast<float>(f * f * 0.01);
            v[1][12 * 3 + ch] = 20.0f;  // the other half: level 1, relative variance 20
        }
        local_half<float> a, b;
        a.color = *make_image_view(c[0].data(), w, h, 3);
        a.variance = *make_image_view(v[0].data(), w, h, 3);
        b.color = *make_image_view(c[1].data(), w, h, 3);
        b.variance = *make_image_view(v[1].data(), w, h, 3);
        local_test_scratch s;
        local_test_result r;
        REQUIRE(local_test(a, b, local_test_options{}, s, r).ok());
        INFO("firefly " << f);
        CHECK(std::find(r.half[0].index.begin(), r.half[0].index.end(), 12u) != r.half[0].index.end());
    }
}
