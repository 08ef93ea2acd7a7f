#include <firefly/firefly.hpp>
#include <firefly/sim/metrics.hpp>
#include <firefly/sim/scene.hpp>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "../examples/pfm.hpp"
#include "catch.hpp"

using namespace firefly;

namespace {
sim::accuracy run_default(const sim::frame& original, frame_report* rep = nullptr,
                          const detector_options& o = {}) {
    std::vector<float> col[2] = {original.color[0], original.color[1]};
    std::vector<float> var[2] = {original.variance[0], original.variance[1]};
    half_buffer<float> h[2];
    for (int i = 0; i < 2; ++i) {
        h[i].color = *make_image_view(col[i].data(), original.width, original.height, 3);
        h[i].variance = *make_image_view(var[i].data(), original.width, original.height, 3);
        if (!original.alpha.empty())
            h[i].alpha = *make_image_view(original.alpha.data(), original.width, original.height, 1);
    }
    detector d(o);
    const frame_report r = d.process(h[0], h[1]);
    if (rep) *rep = r;
    const std::vector<float>* cleaned[2] = {&col[0], &col[1]};
    return sim::evaluate(original, cleaned);
}
}  // namespace

TEST_CASE("the simulator is deterministic for a seed and differs across seeds", "[sim]") {
    const sim::scene s = sim::named_scene("production", 96, 64, 3);
    const sim::frame a = sim::simulate(s), b = sim::simulate(s);
    CHECK(a.color[0] == b.color[0]);
    CHECK(a.variance[1] == b.variance[1]);
    sim::scene s2 = s;
    s2.seed = 4;
    CHECK(sim::simulate(s2).color[0] != a.color[0]);
}

TEST_CASE("only the effects a scene lists are simulated", "[sim]") {
    sim::scene s = sim::named_scene("flat", 128, 96, 1);
    sim::frame f = sim::simulate(s);
    std::size_t ff = 0, hl = 0, zero = 0;
    for (std::size_t i = 0; i < f.pixels(); ++i) {
        ff += f.firefly_energy[0][i] > 0 || f.firefly_energy[1][i] > 0;
        hl += f.highlight[i];
        zero += f.color[0][i * 3] == 0.0f;
    }
    CHECK(ff == 0);
    CHECK(hl == 0);
    CHECK(zero == 0);
    CHECK(f.alpha.empty());
    s.effects = sim::fireflies;
    f = sim::simulate(s);
    ff = 0;
    for (std::size_t i = 0; i < f.pixels(); ++i) ff += f.firefly_energy[0][i] > 0;
    // ~0.5% of pixels per half by default
    CHECK(ff > f.pixels() / 400);
    CHECK(ff < f.pixels() / 100);
    s.firefly_probability = 1e-3;  // per sample: 1 - (1 - 1e-3)^64 = 6.2% of pixels per half
    f = sim::simulate(s);
    ff = 0;
    for (std::size_t i = 0; i < f.pixels(); ++i) ff += f.firefly_energy[0][i] > 0;
    CHECK(static_cast<double>(ff) / static_cast<double>(f.pixels()) == Approx(0.062).epsilon(0.1));
    s.firefly_probability = 0;
    s.effects = sim::black_background | sim::alpha_coverage;
    f = sim::simulate(s);
    CHECK(!f.alpha.empty());
    CHECK(f.color[0][0] == 0.0f);  // corner is background
    CHECK(f.alpha[0] == 0.0f);
    const std::size_t mid = static_cast<std::size_t>(48 * 128 + 64);
    CHECK(f.alpha[mid] == 1.0f);
}

TEST_CASE("simulated pixel statistics match a renderer's", "[sim]") {
    // Over a flat scene, (A - B)^2 averages var(A) + var(B): the variance is of the mean.
    sim::scene s = sim::named_scene("flat", 200, 200, 9);
    const sim::frame f = sim::simulate(s);
    double d2 = 0, v = 0, mean = 0;
    for (std::size_t i = 0; i < f.pixels() * 3; ++i) {
        const double d = f.color[0][i] - f.color[1][i];
        d2 += d * d;
        v += f.variance[0][i] + f.variance[1][i];
        mean += f.color[0][i];
    }
    CHECK(d2 / v == Approx(1.0).epsilon(0.05));
    CHECK(mean / static_cast<double>(f.pixels() * 3) == Approx(s.base * (1 + 0.85 + 0.7) / 3).epsilon(0.01));
}

TEST_CASE("default detector on every named scene: ground-truth accuracy", "[sim][accuracy]") {
    for (const std::string& name : sim::scene_names()) {
        const sim::frame f = sim::simulate(sim::named_scene(name, 320, 240, 21));
        frame_report r;
        const sim::accuracy a = run_default(f, &r);
        const std::vector<float>* input[2] = {&f.color[0], &f.color[1]};
        const sim::accuracy none = sim::evaluate(f, input);
        std::printf("%-18s recall %.4f precision %.4f fp %.5f highlights %.4f relMSE %.5f (input %.4f)\n",
                    name.c_str(), a.recall, a.precision, a.false_positive, a.highlight_kept, a.relmse,
                    none.relmse);
        INFO(name);
        REQUIRE(r.error.ok());
        CHECK(a.recall >= 0.97);
        CHECK(a.false_positive <= 0.002);
        CHECK(a.highlight_kept >= 0.97);
        CHECK(a.relmse < none.relmse / 10);
    }
}

namespace {
// Cleans the real render in `dir` (a_color.pfm, a_variance.pfm, b_*, reference.pfm) and
// checks that the combined image moves closer to the reference. False when it is absent.
bool clean_real(const std::string& dir, const char* what) {
    using firefly_tools::pfm_image;
    pfm_image ac, av, bc, bv, ref;
    if (!firefly_tools::read_pfm(dir + "/a_color.pfm", ac).empty()) return false;
    REQUIRE(firefly_tools::read_pfm(dir + "/a_variance.pfm", av).empty());
    REQUIRE(firefly_tools::read_pfm(dir + "/b_color.pfm", bc).empty());
    REQUIRE(firefly_tools::read_pfm(dir + "/b_variance.pfm", bv).empty());
    REQUIRE(firefly_tools::read_pfm(dir + "/reference.pfm", ref).empty());
    const int w = ac.width, h = ac.height;
    const std::size_t np = static_cast<std::size_t>(w * h);
    std::vector<float> before(np * 3), after(np * 3);
    for (std::size_t i = 0; i < np * 3; ++i) before[i] = 0.5f * (ac.pixels[i] + bc.pixels[i]);
    half_buffer<float> a{*make_image_view(ac.pixels.data(), w, h, 3), *make_image_view(av.pixels.data(), w, h, 3), {}};
    half_buffer<float> b{*make_image_view(bc.pixels.data(), w, h, 3), *make_image_view(bv.pixels.data(), w, h, 3), {}};
    detector d;
    const frame_report r = d.process(a, b);
    REQUIRE(r.error.ok());
    for (std::size_t i = 0; i < np * 3; ++i) after[i] = 0.5f * (ac.pixels[i] + bc.pixels[i]);
    const double e0 = sim::relmse(before.data(), ref.pixels.data(), np);
    const double e1 = sim::relmse(after.data(), ref.pixels.data(), np);
    std::printf("%s %dx%d: fireflies %zu + %zu, highlights %zu, relMSE %.5f -> %.5f\n", what, w, h,
                r.half[0].fireflies, r.half[1].fireflies, r.half[0].highlights, e0, e1);
    CHECK(r.half[0].fireflies + r.half[1].fireflies > 0);
    CHECK(e1 < e0 / 5);
    return true;
}
}  // namespace

TEST_CASE("a real render: the Cycles caustics crop", "[real]") {
    REQUIRE(clean_real(FIREFLY_TEST_DATA, "real crop"));
}

TEST_CASE("the full real render in ../shared/data, when present", "[real]") {
    const std::string dir = std::string(FIREFLY_SHARED_DATA) + "/cycles-caustics";
    if (!clean_real(dir, "real"))
        WARN("skipped: " << dir << " is absent (it ships beside the repository, not in it)");
}
