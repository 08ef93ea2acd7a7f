// The peers the accuracy tables measure firefly against (bench/peers.hpp) hold to their
// published rules: BCD's spike removal (SpikeRemovalFilter) and G-MoN's two variants.
#include <cmath>
#include <cstddef>
#include <random>
#include <vector>

#include "../bench/peers.hpp"
#include "catch.hpp"

namespace {
using firefly_peers::view;

struct rgb_image {
    int w, h;
    std::vector<float> px;
    rgb_image(int width, int height, float v) : w(width), h(height), px(static_cast<std::size_t>(width) * height * 3, v) {}
    view colour() { return *firefly::make_image_view(px.data(), w, h, 3); }
    float& at(int x, int y, int c) { return px[(static_cast<std::size_t>(y) * w + x) * 3 + c]; }
};

void set_rgb(rgb_image& im, int x, int y, float v) {
    for (int c = 0; c < 3; ++c) im.at(x, y, c) = v;
}

// One pixel's value in each of the K buffers, the same in every channel but where `c0` sets
// channel 0 apart.
std::vector<std::vector<float>> pixel_buffers(const std::vector<float>& v, const std::vector<float>& c0 = {}) {
    std::vector<std::vector<float>> b;
    for (std::size_t j = 0; j < v.size(); ++j) b.push_back({c0.empty() ? v[j] : c0[j], v[j], v[j]});
    return b;
}

firefly_peers::buffer_list list_of(const std::vector<std::vector<float>>& b) {
    firefly_peers::buffer_list l;
    for (const auto& x : b) l.push_back(x.data());
    return l;
}
}  // namespace

TEST_CASE("bcd_spikes: a spike at a corner or an edge is removed; its window holds 9 pixels", "[peers]") {
    // A 4-pixel corner window (the window cut short) can never pass k = 2: one value among n
    // lies at most sqrt(n - 1) population deviations from their mean. BCD moves the window inward.
    rgb_image im(8, 8, 1.0f);
    const int spikes[][2] = {{0, 0}, {7, 0}, {0, 7}, {7, 7}, {4, 0}};
    for (const auto& s : spikes) set_rgb(im, s[0], s[1], 50.0f);
    rgb_image var(8, 8, 0.0f);
    firefly_peers::bcd_spikes(im.colour(), var.colour());
    for (int y = 0; y < 8; ++y)
        for (int x = 0; x < 8; ++x) {
            INFO("pixel " << x << ", " << y);
            CHECK(im.at(x, y, 0) == 1.0f);  // every spike replaced by its window's medoid, nothing else moved
        }
}

TEST_CASE("bcd_spikes: on Gaussian noise it flags BCD's share (sample sd, n - 1)", "[peers]") {
    // |x - mean| > 2 sd in any of three channels: 5.9% of interior pixels with the sample
    // standard deviation, 9.7% with the population one. A flagged pixel is never its window's
    // L1 medoid here, so the changed share is the flagged share.
    const int w = 128, h = 128;
    rgb_image im(w, h, 0.0f);
    std::mt19937 rng(1);
    std::normal_distribution<float> noise(10.0f, 1.0f);
    for (float& v : im.px) v = noise(rng);
    const rgb_image before = im;
    rgb_image var(w, h, 0.0f);
    firefly_peers::bcd_spikes(im.colour(), var.colour());
    int changed = 0;
    for (int y = 1; y < h - 1; ++y)
        for (int x = 1; x < w - 1; ++x) {
            const std::size_t i = (static_cast<std::size_t>(y) * w + x) * 3;
            changed += im.px[i] != before.px[i] || im.px[i + 1] != before.px[i + 1] || im.px[i + 2] != before.px[i + 2];
        }
    const double share = static_cast<double>(changed) / ((w - 2) * (h - 2));
    INFO("interior share changed: " << share);
    CHECK(share > 0.050);
    CHECK(share < 0.068);
}

TEST_CASE("agmon, gmon: G-MoN's adaptive and binary variants on hand-computed means", "[peers]") {
    // Five buffers, one mean each (M = K = 5). Sorted {1, 2, 4, 5, 20}: sum 32, Gini
    // sum (2i - 6) x_i / (5 * 32) = (-4 - 4 + 0 + 10 + 80) / 160 = 0.5125; c = floor(0.5125 * 5 / 2) = 1:
    // adaptive (2 + 4 + 5) / 3; binary, G >= 0.25: the median, 4.
    auto b = pixel_buffers({20, 1, 5, 2, 4});
    float out[3];
    firefly_peers::agmon(list_of(b), 1, 5, out);
    CHECK(out[0] == Approx(11.0 / 3.0));
    CHECK(out[2] == Approx(11.0 / 3.0));
    firefly_peers::gmon(list_of(b), 1, 5, 0.25, out);
    CHECK(out[0] == Approx(4.0));
    // {2, 2, 2, 2, 3}: Gini 4 / 55 = 0.073, c = 0: the mean, 2.2 (binary: the mean too)
    b = pixel_buffers({2, 3, 2, 2, 2});
    firefly_peers::agmon(list_of(b), 1, 5, out);
    CHECK(out[1] == Approx(2.2));
    // One Gini for the pixel, averaged over the channels: channel 0 {1, 2, 4, 5, 20} beside two
    // flat channels gives G = 0.5125 / 3 = 0.171, c = floor(0.427) = 0: channel 0 keeps its
    // mean, 6.4, where on its own it would be trimmed.
    b = pixel_buffers({1, 1, 1, 1, 1}, {20, 1, 5, 2, 4});
    firefly_peers::agmon(list_of(b), 1, 5, out);
    CHECK(out[0] == Approx(6.4));
    CHECK(out[1] == Approx(1.0));
    // M = 2 groups of 2 buffers: c = floor(G) = 0, the mean of the two means whatever G
    b = pixel_buffers({0, 0, 0, 100});
    firefly_peers::agmon(list_of(b), 1, 2, out);
    CHECK(out[0] == Approx(25.0));
}

TEST_CASE("agmon: equal means, whose Gini rounds below 0, are averaged whole", "[peers]") {
    // Eight equal means of 2.1467233 give a Gini of -2.6e-17 (the sum of (2i - 9) x rounds below
    // 0), and floor(G M / 2) was -1: the trimmed mean read the value before the array (a heap
    // overflow; 2e47 on the Cycles seed renders, a different value each run).
    std::vector<float> v(8, 2.14672327f);
    std::vector<float> scratch = v;
    REQUIRE(firefly_peers::gini(scratch.data(), 8) <= 0.0);
    const auto b = pixel_buffers(v);
    float out[3] = {};
    firefly_peers::agmon(list_of(b), 1, 8, out);
    for (float o : out) CHECK(o == Approx(2.14672327f));
    // and directly: a Gini below 0, NaN or above 1 trims nothing, or at most all but one
    v.assign({1, 2, 3, 4, 100});
    CHECK(firefly_peers::gini_trimmed_mean(v.data(), 5, -1e-17) == Approx(22.0));
    v.assign({1, 2, 3, 4, 100});
    CHECK(firefly_peers::gini_trimmed_mean(v.data(), 5, std::nan("")) == Approx(22.0));
    v.assign({1, 2, 3, 4, 100});
    CHECK(firefly_peers::gini_trimmed_mean(v.data(), 5, 7.0) == Approx(3.0));
}
