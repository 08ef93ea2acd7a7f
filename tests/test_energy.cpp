// The energy return (energy.hpp): a uniform field of removed energy comes back whole, a lone
// firefly's not at all; in the two-half detector (return_energy, off by default) it only ever
// adds light, never to the black background, and lowers the error on simulated caustics and
// dense fireflies.
#include <firefly/energy.hpp>
#include <firefly/firefly.hpp>
#include <firefly/sim/metrics.hpp>
#include <firefly/sim/scene.hpp>
#include <firefly/sim/scenes.hpp>

#include <cmath>
#include <vector>

#include "catch.hpp"
#include "frame_views.hpp"

using namespace firefly;

TEST_CASE("energy return: a uniform removed field comes back whole, a lone one not at all", "[energy]") {
    const int w = 80, h = 80;
    const std::size_t n = static_cast<std::size_t>(w * h) * 3;
    std::vector<double> shape(n, 0.5), excess(n, 0.1), returned;
    energy_scratch s;
    energy_return(excess, shape, w, h, 4.0, returned, s, executor{});
    for (int y = 20; y < 60; ++y)  // away from the borders (the Gaussian reaches 12 px)
        for (int x = 20; x < 60; ++x)
            CHECK(returned[static_cast<std::size_t>(y * w + x) * 3] == Approx(0.1).epsilon(0.01));
    std::vector<double> lone(n, 0.0);
    for (int c = 0; c < 3; ++c) lone[static_cast<std::size_t>(40 * w + 40) * 3 + static_cast<std::size_t>(c)] = 1e3;
    energy_return(lone, shape, w, h, 4.0, returned, s, executor{});
    for (const double v : returned) CHECK(v == 0.0);
}

TEST_CASE("energy return: extreme and denormal excess stays finite and non-negative", "[energy]") {
    const int w = 24, h = 20;
    const std::size_t n = static_cast<std::size_t>(w * h) * 3;
    std::vector<double> shape(n, 1e-3), excess(n, 0.0), returned;
    for (int i = 0; i < 40; ++i) excess[static_cast<std::size_t>(i * 7) % n] = i % 2 ? 1e30 : 4.9e-324;
    energy_scratch s;
    energy_return(excess, shape, w, h, 8.0, returned, s, executor{});
    for (const double v : returned) {
        CHECK(std::isfinite(v));
        CHECK(v >= 0.0);
    }
}

namespace {
// The two halves of a simulated scene cleaned with or without the energy return.
frame_report clean(firefly_test::frame_views& v, bool energy) {
    detector_options o;
    o.return_energy = energy;
    detector d(o);
    return d.process(v.h[0], v.h[1]);
}
}  // namespace

TEST_CASE("two halves, return_energy: only adds, never to the background, lowers the caustic's error",
          "[energy][pipeline]") {
    for (const char* name : {"caustics", "black_alpha", "dense10"}) {
        INFO(name);
        const sim::frame f = sim::simulate(sim::named_scene(name, 160, 120, 3));
        firefly_test::frame_views off(f), on(f);
        const frame_report r_off = clean(off, false), r_on = clean(on, true);
        REQUIRE(r_off.ok());
        REQUIRE(r_on.ok());
        CHECK(r_on.half[0].fireflies == r_off.half[0].fireflies);  // detection is unchanged
        CHECK(r_off.half[0].energy_returned == 0.0);
        std::size_t lowered = 0, background = 0;
        for (int h = 0; h < 2; ++h)
            for (std::size_t i = 0; i < on.f.color[h].size(); ++i) {
                lowered += on.f.color[h][i] < off.f.color[h][i];
                const std::size_t p = i / 3;
                const bool black = f.color[h][p * 3] == 0 && f.color[h][p * 3 + 1] == 0 && f.color[h][p * 3 + 2] == 0;
                background += (black || (!f.alpha.empty() && !(f.alpha[p] > 0))) && on.f.color[h][i] != off.f.color[h][i];
            }
        CHECK(lowered == 0);
        CHECK(background == 0);
        if (std::string(name) != "black_alpha") {
            const std::vector<float>* a[2] = {&on.f.color[0], &on.f.color[1]};
            const std::vector<float>* b[2] = {&off.f.color[0], &off.f.color[1]};
            const double e_on = sim::evaluate(f, a).relmse, e_off = sim::evaluate(f, b).relmse;
            INFO("relMSE " << e_off << " -> " << e_on);
            CHECK(r_on.half[0].energy_returned > 0);
            CHECK(e_on < e_off);
        }
    }
    detector_options bad;
    bad.energy_sigma = 0.5;
    CHECK(check_options(bad).code() == errc::invalid_argument);
}
