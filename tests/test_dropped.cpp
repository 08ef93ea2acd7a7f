// Dropped pixels (dropped.hpp): a buffer black where the others show it cannot be by chance.
#include <firefly/firefly.hpp>
#include <firefly/sim/scene.hpp>
#include <firefly/sim/scenes.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <initializer_list>
#include <vector>

#include "catch.hpp"
#include "frame_views.hpp"
#include "symmetry.hpp"

using namespace firefly;
using firefly_test::frame_views;

namespace {

// log P(Binomial(n, j/k) >= a), summed term by term in long double.
double direct_log_tail(int n, int a, int k, int j = 1) {
    long double sum = 0, p = static_cast<long double>(j) / k;
    for (int t = a; t <= n; ++t) {
        long double c = 1;
        for (int i = 0; i < t; ++i) c = c * (n - i) / (i + 1);
        sum += c * std::pow(p, t) * std::pow(1 - p, n - t);
    }
    return static_cast<double>(std::log(sum));
}

struct lcg {
    std::uint32_t s;
    explicit lcg(std::uint32_t seed) : s(seed * 2654435761u + 12345u) {}
    double next() {
        s = s * 1664525u + 1013904223u;
        return (s >> 8) / 16777216.0;
    }
};

std::size_t pixel(int x, int y, int w) { return static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x); }

// A w x h lone map: each pixel a lone black with probability `rate`, of a buffer drawn
// uniformly from k (the null: exchangeable buffers).
std::vector<std::uint8_t> null_lone_map(int w, int h, int k, double rate, std::uint32_t seed) {
    lcg r(seed);
    std::vector<std::uint8_t> lone(static_cast<std::size_t>(w) * static_cast<std::size_t>(h), 0);
    for (auto& l : lone)
        if (r.next() < rate) l = static_cast<std::uint8_t>(1 + static_cast<int>(r.next() * k) % k);
    return lone;
}

// A w x h map of black-buffer masks under the null: each pixel partly black with probability
// `rate`, its black buffers a uniform subset of 1 to `most` of the k (exchangeable buffers).
std::vector<std::uint64_t> null_black_map(int w, int h, int k, int most, double rate, std::uint32_t seed) {
    lcg r(seed);
    std::vector<std::uint64_t> black(static_cast<std::size_t>(w) * static_cast<std::size_t>(h), 0);
    for (auto& m : black) {
        if (!(r.next() < rate)) continue;
        const int j = 1 + static_cast<int>(r.next() * most) % most;
        while (detail::blacks_in(m) < j) m |= std::uint64_t{1} << (static_cast<int>(r.next() * k) % k);
    }
    return black;
}

// find_dropped on a mask map: the found (pixel, buffer) pairs as a map of masks.
std::vector<std::uint64_t> found_masks(const std::vector<std::uint64_t>& black, int w, int h, int k, std::size_t* tested = nullptr) {
    dropped_scratch s;
    std::vector<dropped_pixel> found;
    const std::size_t t = find_dropped_masks(w, h, k, 0.05, [&](int x, int y) { return black[pixel(x, y, w)]; }, s, executor{}, found);
    if (tested) *tested = t;
    std::vector<std::uint64_t> m(black.size(), 0);
    for (const dropped_pixel& d : found) m[d.pixel] |= std::uint64_t{1} << d.buffer;
    return m;
}


// relMSE of the halves' mean against the expected image, over the square [x0, x0 + s)^2 (or the
// whole frame when s is 0).
double relmse(const sim::frame& f, int x0, int y0, int s) {
    double sum = 0;
    std::size_t n = 0;
    for (int y = 0; y < f.height; ++y)
        for (int x = 0; x < f.width; ++x) {
            if (s > 0 && (x < x0 || x >= x0 + s || y < y0 || y >= y0 + s)) continue;
            for (int c = 0; c < 3; ++c) {
                const std::size_t i = pixel(x, y, f.width) * 3 + static_cast<std::size_t>(c);
                const double ref = f.expected[i], v = 0.5 * (f.color[0][i] + f.color[1][i]);
                sum += (v - ref) * (v - ref) / (ref * ref + 0.01);
                ++n;
            }
        }
    return sum / static_cast<double>(n);
}

// The 24x20 tile at (60, 30) written black in the given buffers of b, which a default K-buffer
// detector then cleans in place; its masks into mk.
cross_buffer_report clean_with_black_tile(sim::buffers& b, std::initializer_list<int> black,
                                          std::vector<std::vector<std::uint8_t>>& mk, const cross_buffer_options& o = {}) {
    const int w = b.width, h = b.height, k = b.count();
    for (const int buf : black)
        for (int y = 30; y < 50; ++y)
            for (int x = 60; x < 84; ++x)
                for (int c = 0; c < 3; ++c) b.color[static_cast<std::size_t>(buf)][pixel(x, y, w) * 3 + static_cast<std::size_t>(c)] = 0.0f;
    std::vector<buffer_view<float>> views;
    mk.assign(static_cast<std::size_t>(k), std::vector<std::uint8_t>(b.pixels(), 0));
    std::vector<image_view<std::uint8_t>> masks;
    for (int i = 0; i < k; ++i) {
        views.push_back({*make_image_view(b.color[static_cast<std::size_t>(i)].data(), w, h, 3), {}});
        masks.push_back(*make_image_view(mk[static_cast<std::size_t>(i)].data(), w, h, 1));
    }
    cross_buffer_detector d(o);
    return d.process(views, masks);
}

}  // namespace

TEST_CASE("binomial tail table: exact values, 1e-70 tails", "[dropped]") {
    for (int k : {2, 3, 4, 8, 64}) {
        detail::binomial_tail_table t;
        t.build(k, 224);
        CHECK(t.log_tail(0, 0) == 0.0);
        for (int n : {1, 2, 7, 40, 224})
            for (int a : {0, 1, n / 3, n / 2, n}) {
                if (a > n) continue;
                const double want = direct_log_tail(n, a, k);
                CHECK(t.log_tail(n, a) == Approx(want).epsilon(1e-12).margin(1e-13));
                CHECK(t.log_tail(n, a) <= 0.0);
            }
        CHECK(t.log_tail(224, 224) == Approx(-224 * std::log(static_cast<double>(k))).epsilon(1e-13));
    }
}

TEST_CASE("binomial upper tail at any p: exact values, 1e-100 tails", "[dropped]") {
    std::vector<double> lf(225, 0.0);
    for (int i = 1; i <= 224; ++i) lf[static_cast<std::size_t>(i)] = lf[static_cast<std::size_t>(i - 1)] + std::log(static_cast<double>(i));
    for (const int k : {3, 8, 64})
        for (const int j : {1, 2, k - 1})
            for (const int n : {1, 7, 40, 224})
                for (const int c : {1, n / 2, n - 1, n}) {
                    if (c < 1 || !(c >= n * j / static_cast<double>(k) + 1.0)) continue;
                    const double p = static_cast<double>(j) / k, want = direct_log_tail(n, c, k, j);
                    INFO("k " << k << " j " << j << " n " << n << " c " << c);
                    CHECK(detail::log_binomial_upper_tail(n, c, p, lf) == Approx(want).epsilon(1e-12).margin(1e-13));
                }
    CHECK(detail::log_binomial_upper_tail(224, 224, 0.125, lf) == Approx(224 * std::log(0.125)).epsilon(1e-13));
    CHECK(detail::log_binomial_upper_tail(10, 11, 0.5, lf) == -HUGE_VAL);
}

// K >= 3: a tile black in the same two renders (every pixel of it has two black buffers, none
// a lone black) is found in both, and one black in a third render that overlaps it too.
TEST_CASE("find_dropped: a block black in two or three buffers at once", "[dropped]") {
    const int w = 96, h = 64;
    for (int k : {3, 4, 8, 16}) {
        std::vector<std::uint64_t> black = null_black_map(w, h, k, std::min(k - 1, 2), 0.2, 5u);
        for (int y = 20; y < 36; ++y)
            for (int x = 30; x < 46; ++x) black[pixel(x, y, w)] = (std::uint64_t{1} << 1) | (std::uint64_t{1} << (k - 1));
        if (k >= 8)  // buffer 2 too, over a block that overlaps the first one's right half
            for (int y = 24; y < 40; ++y)
                for (int x = 38; x < 54; ++x) black[pixel(x, y, w)] |= std::uint64_t{1} << 2;
        std::size_t tested = 0;
        const std::vector<std::uint64_t> m = found_masks(black, w, h, k, &tested);
        std::size_t pairs = 0;
        for (const std::uint64_t b : black) pairs += static_cast<std::size_t>(detail::blacks_in(b));
        CHECK(tested == pairs);
        std::size_t in = 0, wanted = 0, far = 0, inner_missed = 0;
        for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x) {
                const bool first = x >= 30 && x < 46 && y >= 20 && y < 36;
                const bool second = k >= 8 && x >= 38 && x < 54 && y >= 24 && y < 40;
                const std::uint64_t want = (first ? (std::uint64_t{1} << 1) | (std::uint64_t{1} << (k - 1)) : 0) |
                                           (second ? std::uint64_t{1} << 2 : 0);
                const bool reach = x >= 30 - 7 && x < 54 + 7 && y >= 20 - 7 && y < 40 + 7;
                // two pixels in from a block's edges: every pixel found (at a corner, a quarter
                // window of it among the background's chance blacks can miss)
                const bool inner1 = x >= 32 && x < 44 && y >= 22 && y < 34, inner2 = k >= 8 && x >= 40 && x < 52 && y >= 26 && y < 38;
                const bool inner = (first || second) && (inner1 || !first) && (inner2 || !second);
                wanted += static_cast<std::size_t>(detail::blacks_in(want));
                in += static_cast<std::size_t>(detail::blacks_in(m[pixel(x, y, w)] & want));
                inner_missed += inner && (m[pixel(x, y, w)] & want) != want;
                far += !reach && m[pixel(x, y, w)] != 0;
                far += (m[pixel(x, y, w)] & ~black[pixel(x, y, w)]) != 0;  // only black buffers are found
            }
        INFO("K = " << k << ": " << in << " of " << wanted << " found");
        CHECK(inner_missed == 0);
        CHECK(in >= wanted * 97 / 100);
        CHECK(far == 0);
    }
}

TEST_CASE("find_dropped: a block of one buffer's lone blacks, nothing else", "[dropped]") {
    const int w = 96, h = 64;
    for (int k : {2, 4}) {
        std::vector<std::uint8_t> lone = null_lone_map(w, h, k, 0.2, 3u);
        for (int y = 20; y < 36; ++y)
            for (int x = 40; x < 56; ++x) lone[pixel(x, y, w)] = 2;  // buffer 1 dropped
        dropped_scratch s;
        std::vector<dropped_pixel> found;
        const std::size_t tested = find_dropped(lone.data(), w, h, k, 0.05, s, executor{}, found);
        CHECK(tested == static_cast<std::size_t>(std::count_if(lone.begin(), lone.end(), [](std::uint8_t l) { return l != 0; })));
        // Found: the block, and lone blacks of buffer 1 whose window reaches into it (their
        // windows hold mostly the block's); nothing farther, nothing of another buffer.
        std::size_t in = 0, near = 0, far = 0;
        for (const dropped_pixel& d : found) {
            const int x = static_cast<int>(d.pixel % w), y = static_cast<int>(d.pixel / w);
            const bool inside = x >= 40 && x < 56 && y >= 20 && y < 36;
            const bool reach = x >= 40 - 7 && x < 56 + 7 && y >= 20 - 7 && y < 36 + 7;
            in += inside && d.buffer == 1;
            near += !inside && reach && d.buffer == 1;
            far += !reach || d.buffer != 1;
        }
        CHECK(in == 16u * 16u);
        CHECK(far == 0);
        CHECK(near < 16u * 16u / 2);
    }
}

TEST_CASE("find_dropped keeps its promise on exchangeable buffers", "[dropped][calibration]") {
    // 400 frames without a dropped region, lone blacks at 2% and 30% of the pixels: at most
    // alpha of them with any pixel found (expected <= 20 of 400; 3 binomial sds above: 33).
    for (int k : {2, 4})
        for (double rate : {0.02, 0.3}) {
            int frames_with_any = 0;
            dropped_scratch s;
            std::vector<dropped_pixel> found;
            for (std::uint32_t seed = 0; seed < 400; ++seed) {
                const std::vector<std::uint8_t> lone = null_lone_map(48, 48, k, rate, 1000u + seed);
                (void)find_dropped(lone.data(), 48, 48, k, 0.05, s, executor{}, found);
                frames_with_any += !found.empty();
            }
            INFO("k " << k << " rate " << rate);
            CHECK(frames_with_any <= 33);
        }
    // several buffers black at a pixel (K >= 3): 1 to 2 or 1 to K - 1 of them, exchangeable
    for (int k : {3, 4, 8})
        for (int most : {2, k - 1})
            for (double rate : {0.02, 0.3}) {
                int frames_with_any = 0;
                for (std::uint32_t seed = 0; seed < 400; ++seed) {
                    const std::vector<std::uint64_t> m = found_masks(null_black_map(48, 48, k, most, rate, 7000u + seed), 48, 48, k);
                    frames_with_any += std::any_of(m.begin(), m.end(), [](std::uint64_t v) { return v != 0; });
                }
                INFO("k " << k << " most " << most << " rate " << rate);
                CHECK(frames_with_any <= 33);
            }
}

// Every tested pair's p-value is the one of its window's counts, counted pixel by pixel here:
// the strip of rows slid down each band (dropped_band) and the column sums give the same
// integers as the window itself, at frame edges, band edges and frames narrower or shorter
// than the window, for lone blacks and several buffers black (K = 2 to 64, wide masks past 8).
TEST_CASE("find_dropped: each pair's p-value is its window's, counted directly", "[dropped]") {
    struct shape { int w, h, k, most; double rate; };
    for (const shape& f : {shape{70, 77, 2, 1, 0.3}, shape{5, 40, 2, 1, 0.9}, shape{33, 3, 3, 2, 0.5},
                           shape{1, 1, 2, 1, 1.0}, shape{64, 66, 8, 3, 0.25}, shape{40, 35, 9, 8, 0.4},
                           shape{31, 70, 64, 63, 0.6}, shape{50, 50, 4, 1, 1.0}}) {
        const std::vector<std::uint64_t> black = null_black_map(f.w, f.h, f.k, f.most, f.rate, 17u + static_cast<std::uint32_t>(f.k));
        dropped_scratch s;
        std::vector<dropped_pixel> found;
        const std::size_t tested = find_dropped_masks(f.w, f.h, f.k, 0.05, [&](int x, int y) { return black[pixel(x, y, f.w)]; },
                                                      s, executor::threads(2), found);
        std::vector<double> got(black.size() * static_cast<std::size_t>(f.k), 1.0);  // 1: no such pair (log p <= 0)
        for (const auto& row : s.rows)
            for (const dropped_pixel& d : row) got[d.pixel * static_cast<std::size_t>(f.k) + static_cast<std::size_t>(d.buffer)] = d.log_p;
        std::size_t pairs = 0, wrong = 0;
        const int r = detail::dropped_radius;
        for (int y = 0; y < f.h; ++y)
            for (int x = 0; x < f.w; ++x) {
                const std::uint64_t m = black[pixel(x, y, f.w)];
                if (m == 0) continue;
                int n = 0, blacks = -detail::blacks_in(m), a[64] = {};
                for (int j = std::max(0, y - r); j <= std::min(f.h - 1, y + r); ++j)
                    for (int i = std::max(0, x - r); i <= std::min(f.w - 1, x + r); ++i) {
                        const std::uint64_t q = black[pixel(i, j, f.w)];
                        n += q != 0;
                        blacks += detail::blacks_in(q);
                        for (int b = 0; b < f.k; ++b) a[b] += static_cast<int>((q >> b) & 1u);
                    }
                for (int b = 0; b < f.k; ++b) {
                    if (!((m >> b) & 1u)) continue;
                    const double want = detail::window_log_p(n - 1, a[b] - 1, blacks, f.k, s);
                    ++pairs;
                    wrong += !(got[pixel(x, y, f.w) * static_cast<std::size_t>(f.k) + static_cast<std::size_t>(b)] == want);
                }
            }
        INFO(f.w << "x" << f.h << " k " << f.k);
        CHECK(tested == pairs);
        CHECK(wrong == 0);
        CHECK(pairs > 0);
    }
}

// A mask bit past k names no buffer and a mask of every buffer is not partly black: both count
// as nothing (a bit past k was counted past the strip's per-buffer arrays: heap overflow).
TEST_CASE("find_dropped: mask bits past k and masks of every buffer count as nothing", "[dropped][errors]") {
    const int w = 40, h = 30;
    for (const int k : {2, 3, 9}) {
        const std::vector<std::uint64_t> clean = null_black_map(w, h, k, 1, 0.5, 5u);
        std::vector<std::uint64_t> stray = clean;
        const std::uint64_t all = (std::uint64_t{1} << k) - 1;
        for (std::size_t i = 0; i < stray.size(); ++i) {
            if (i % 3 == 0) stray[i] |= std::uint64_t{1} << (k + static_cast<int>(i % 5));  // past k (and past 8)
            if (i % 7 == 1 && clean[i] == 0) stray[i] = all;                                 // every buffer
        }
        std::size_t t_clean = 0, t_stray = 0;
        const std::vector<std::uint64_t> want = found_masks(clean, w, h, k, &t_clean);
        INFO("k " << k);
        CHECK(found_masks(stray, w, h, k, &t_stray) == want);
        CHECK(t_stray == t_clean);
    }
}

TEST_CASE("find_dropped: the 8 flips and transposes and executors give the same pixels", "[dropped]") {
    const int w = 70, h = 45;
    std::vector<std::uint8_t> lone = null_lone_map(w, h, 2, 0.3, 9u);
    for (int y = 5; y < 30; ++y)
        for (int x = 3; x < 20 + y / 2; ++x) lone[pixel(x, y, w)] = 1;
    auto found_set = [](const std::vector<std::uint8_t>& l, int ww, int hh, const executor& e) {
        dropped_scratch s;
        std::vector<dropped_pixel> f;
        (void)find_dropped(l.data(), ww, hh, 2, 0.05, s, e, f);
        std::vector<std::uint8_t> m(l.size(), 0);
        for (const dropped_pixel& d : f) m[d.pixel] = static_cast<std::uint8_t>(1 + d.buffer);
        return m;
    };
    const std::vector<std::uint8_t> base = found_set(lone, w, h, executor{});
    CHECK(std::count(base.begin(), base.end(), 1) > 300);
    CHECK(found_set(lone, w, h, executor::threads(2)) == base);
    for (int sym = 1; sym < 8; ++sym) {
        const firefly_test::symmetry t{sym, w, h};
        INFO("symmetry " << sym);
        CHECK(found_set(t.apply(lone, 1), t.width(), t.height(), executor{}) == t.apply(base, 1));
    }
}

// The same with several buffers black at a pixel (K = 8: masks of 1 to 3 buffers, a block
// black in two).
TEST_CASE("find_dropped, several buffers black: the 8 flips and transposes and executors give the same pairs", "[dropped]") {
    const int w = 64, h = 41, k = 8;
    std::vector<std::uint64_t> black = null_black_map(w, h, k, 3, 0.25, 11u);
    for (int y = 4; y < 30; ++y)
        for (int x = 6; x < 18 + y / 2; ++x) black[pixel(x, y, w)] = 0x24;  // buffers 2 and 5
    auto found = [&](const std::vector<std::uint64_t>& m, int ww, int hh, const executor& e) {
        dropped_scratch s;
        std::vector<dropped_pixel> f;
        (void)find_dropped_masks(ww, hh, k, 0.05, [&](int x, int y) { return m[pixel(x, y, ww)]; }, s, e, f);
        std::vector<std::uint64_t> out(m.size(), 0);
        for (const dropped_pixel& d : f) out[d.pixel] |= std::uint64_t{1} << d.buffer;
        return out;
    };
    const std::vector<std::uint64_t> base = found(black, w, h, executor{});
    CHECK(std::count(base.begin(), base.end(), std::uint64_t{0x24}) > 300);
    CHECK(found(black, w, h, executor::threads(2)) == base);
    for (int sym = 1; sym < 8; ++sym) {
        const firefly_test::symmetry t{sym, w, h};
        INFO("symmetry " << sym);
        CHECK(found(t.apply(black, 1), t.width(), t.height(), executor{}) == t.apply(base, 1));
    }
}

TEST_CASE("a bucket written black in half A is rebuilt from half B", "[dropped][pipeline]") {
    const sim::scene sc = sim::named_scene("dropped_bucket", 256, 192, 6);
    sim::scene intact_sc = sc;
    intact_sc.effects &= ~static_cast<std::uint32_t>(sim::dropped_bucket);
    frame_views v(sim::simulate(sc)), intact(sim::simulate(intact_sc));
    const int x0 = static_cast<int>(sc.bucket_x * 256), y0 = static_cast<int>(sc.bucket_y * 192), side = 32;
    std::size_t black = 0;
    for (int y = y0; y < y0 + side; ++y)
        for (int x = x0; x < x0 + side; ++x) black += v.col(0, x, y) == 0 && v.var(0, x, y) == 0 && v.col(1, x, y) > 0;
    REQUIRE(black == 32u * 32u);
    const double before = relmse(v.f, x0, y0, side);
    detector d;
    const frame_report r = v.process(d);
    REQUIRE(r.ok());
    CHECK(r.half[0].dropped == 32u * 32u);
    CHECK(r.half[1].dropped == 0);
    CHECK(r.half[0].ignored == 0);
    CHECK(r.half[0].nonfinite == 0);
    std::size_t marked = 0, other = 0;
    for (int y = 0; y < v.f.height; ++y)
        for (int x = 0; x < v.f.width; ++x) {
            const bool in = x >= x0 && x < x0 + side && y >= y0 && y < y0 + side;
            const std::uint8_t m = v.mask[0][v.at(x, y)];
            marked += in && (m & mask_bits::dropped) && !(m & mask_bits::nonfinite);
            other += !in && (m & mask_bits::dropped);
            other += (v.mask[1][v.at(x, y)] & mask_bits::dropped) != 0;
        }
    CHECK(marked == 32u * 32u);
    CHECK(other == 0);
    detector di;
    (void)intact.process(di);
    const double after = relmse(v.f, x0, y0, side), intact_err = relmse(intact.f, x0, y0, side);
    INFO("bucket relMSE before " << before << " after " << after << " intact frame, cleaned " << intact_err);
    CHECK(before > 0.15);                 // half the light is missing there
    CHECK(after < 2.0 * intact_err);      // about what the intact frame gives there
    CHECK(relmse(v.f, 0, 0, 0) < 1.2 * relmse(intact.f, 0, 0, 0));
    // Rebuilt as a non-finite pixel would be: from the other half, variance with it.
    for (int y = y0; y < y0 + side; ++y)
        for (int x = x0; x < x0 + side; ++x) REQUIRE(v.var(0, x, y) > 0);
}

TEST_CASE("find_dropped off, and detect(): the bucket is left as it is", "[dropped][pipeline]") {
    const sim::scene sc = sim::named_scene("dropped_bucket", 128, 96, 2);
    frame_views off(sim::simulate(sc)), det(sim::simulate(sc));
    const std::vector<float> input = off.f.color[0];
    detector_options o;
    o.find_dropped = false;
    detector d(o);
    const frame_report r = off.process(d);
    CHECK(r.half[0].dropped == 0);
    CHECK(r.half[0].ignored == 16u * 16u);
    const int x0 = static_cast<int>(sc.bucket_x * 128), y0 = static_cast<int>(sc.bucket_y * 96);
    CHECK(off.col(0, x0 + 3, y0 + 3) == 0.0f);
    detector dd;
    const frame_report rd = det.detect(dd);
    CHECK(rd.half[0].dropped == 16u * 16u);
    CHECK(det.f.color[0] == input);  // detect() writes nothing
    CHECK((det.mask[0][det.at(x0 + 3, y0 + 3)] & mask_bits::dropped) != 0);
}

TEST_CASE("lone blacks that both halves share alike are left alone", "[dropped][pipeline][calibration]") {
    // A dark frame at few samples: a third of its pixels black in either half, independently.
    // Twenty seeds: no pixel found dropped in more than alpha of them (expected <= 1).
    int frames_with_any = 0;
    for (std::uint64_t seed = 1; seed <= 20; ++seed) {
        sim::scene sc = sim::named_scene("sparse_fireflies", 96, 64, seed);
        frame_views v(sim::simulate(sc));
        lcg r(static_cast<std::uint32_t>(seed));
        for (int y = 0; y < 64; ++y)
            for (int x = 0; x < 96; ++x)
                for (int h = 0; h < 2; ++h)
                    if (r.next() < 0.33) v.set(h, x, y, 0.0f, 0.0f);
        detector d;
        const frame_report rep = v.detect(d);
        frames_with_any += rep.half[0].dropped + rep.half[1].dropped > 0;
    }
    CHECK(frames_with_any <= 3);
}

TEST_CASE("a whole half written black is rebuilt from the other", "[dropped][pipeline]") {
    frame_views v(sim::simulate(sim::named_scene("sparse_fireflies", 64, 48, 4)));
    for (int y = 0; y < 48; ++y)
        for (int x = 0; x < 64; ++x) v.set(1, x, y, 0.0f, 0.0f);
    detector d;
    const frame_report r = v.process(d);
    REQUIRE(r.ok());
    CHECK(r.half[1].dropped == 64u * 48u);
    for (int y = 0; y < 48; ++y)
        for (int x = 0; x < 64; ++x) REQUIRE(v.col(1, x, y) > 0);
}

TEST_CASE("K buffers: a render written black in one bucket is rebuilt from the others", "[dropped][buffers]") {
    for (int k : {3, 4, 8}) {
        sim::buffers b = sim::simulate_buffers(sim::named_scene("sparse_fireflies", 128, 96, 3), k);
        const int w = b.width, h = b.height;
        std::vector<std::vector<std::uint8_t>> mk;
        const cross_buffer_report r = clean_with_black_tile(b, {1}, mk);
        INFO("K = " << k);
        REQUIRE(r.ok());
        CHECK(r.dropped == 20u * 24u);
        CHECK(r.nonfinite == 0);
        std::size_t marked = 0;
        for (int y = 30; y < 50; ++y)
            for (int x = 60; x < 84; ++x) {
                marked += mk[1][pixel(x, y, w)] == mask_bits::dropped;
                // the mean of the others: never black again
                REQUIRE(b.color[1][pixel(x, y, w) * 3] > 0);
            }
        CHECK(marked == 20u * 24u);
        cross_buffer_options off;
        off.find_dropped = false;
        sim::buffers b2 = sim::simulate_buffers(sim::named_scene("sparse_fireflies", 128, 96, 3), k);
        for (int y = 30; y < 50; ++y)
            for (int x = 60; x < 84; ++x)
                for (int c = 0; c < 3; ++c) b2.color[1][pixel(x, y, w) * 3 + static_cast<std::size_t>(c)] = 0.0f;
        std::vector<buffer_view<float>> v2;
        for (int i = 0; i < k; ++i) v2.push_back({*make_image_view(b2.color[static_cast<std::size_t>(i)].data(), w, h, 3), {}});
        cross_buffer_detector d2(off);
        CHECK(d2.process(v2).dropped == 0);
        // left black (the energy return may add the others' returned light, no more)
        CHECK(b2.color[1][pixel(70, 40, w) * 3] < 0.25f * b2.color[0][pixel(70, 40, w) * 3]);
    }
}

// A tile that failed in the same two of K renders: every pixel of it has two black buffers and
// no lone black; both are found and rebuilt from the others (a lone-black test alone left the
// tile at (K - 2) / K of its light).
TEST_CASE("K buffers: a bucket written black in two renders at once is rebuilt from the others", "[dropped][buffers]") {
    for (int k : {4, 8}) {
        const sim::scene sc = sim::named_scene("sparse_fireflies", 128, 96, 3);
        sim::buffers b = sim::simulate_buffers(sc, k);
        const sim::buffers intact = b;
        const int w = b.width, h = b.height;
        std::vector<std::vector<std::uint8_t>> mk;
        const cross_buffer_report r = clean_with_black_tile(b, {1, k - 1}, mk);
        INFO("K = " << k);
        REQUIRE(r.ok());
        CHECK(r.dropped == 2u * 20u * 24u);
        CHECK(r.nonfinite == 0);
        std::size_t marked = 0, other = 0;
        double err = 0, err_black = 0, err_intact = 0;
        for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x) {
                const bool in = x >= 60 && x < 84 && y >= 30 && y < 50;
                for (int i = 0; i < k; ++i) {
                    const bool dropped = mk[static_cast<std::size_t>(i)][pixel(x, y, w)] == mask_bits::dropped;
                    const bool black_here = in && (i == 1 || i == k - 1);
                    marked += black_here && dropped;
                    other += !black_here && dropped;
                }
                if (!in) continue;
                // the mean over the buffers against the intact buffers' mean, first channel
                double mean = 0, ref = 0;
                for (int i = 0; i < k; ++i) {
                    mean += static_cast<double>(b.color[static_cast<std::size_t>(i)][pixel(x, y, w) * 3]) / k;
                    ref += static_cast<double>(intact.color[static_cast<std::size_t>(i)][pixel(x, y, w) * 3]) / k;
                }
                const double exp = intact.expected[pixel(x, y, w) * 3];
                err += (mean - exp) * (mean - exp) / (exp * exp + 0.01);
                err_black += (ref * (k - 2) / k - exp) * (ref * (k - 2) / k - exp) / (exp * exp + 0.01);
                err_intact += (ref - exp) * (ref - exp) / (exp * exp + 0.01);
            }
        CHECK(marked == 2u * 20u * 24u);
        CHECK(other == 0);
        INFO("relMSE in the tile: rebuilt " << err / 480 << ", left black " << err_black / 480 << ", intact "
                                            << err_intact / 480);
        // the mean of K - 2 buffers: K / (K - 2) times the intact mean's variance (at K = 4 the
        // two left cannot tell their own fireflies apart: 3.7 times the intact error there)
        if (k == 8) CHECK(err < 1.5 * k / (k - 2.0) * err_intact);
        CHECK(err < 0.25 * err_black);
        for (int y = 30; y < 50; ++y)
            for (int x = 60; x < 84; ++x) REQUIRE(b.color[1][pixel(x, y, w) * 3] > 0);
    }
}

// Black in more than half of the buffers (3 of 4, or 2 of 3): found, but the few left cannot
// be told from their own fireflies, so the tile is left as it is (no light given back either),
// says so (no_valid_pixels, report.left), and its masks say dropped | left on the black buffers.
TEST_CASE("K buffers: a bucket black in most renders is found and left, and says so", "[dropped][buffers]") {
    for (const int k : {3, 4}) {
        sim::buffers b = sim::simulate_buffers(sim::named_scene("sparse_fireflies", 128, 96, 3), k);
        const sim::buffers intact = b;
        const int w = b.width, good = k - 1;  // the buffer left
        std::vector<std::vector<std::uint8_t>> mk;
        const cross_buffer_report r = k == 3 ? clean_with_black_tile(b, {0, 1}, mk) : clean_with_black_tile(b, {0, 1, 2}, mk);
        INFO("K = " << k);
        CHECK(r.error.code() == errc::no_valid_pixels);
        CHECK(r.left == 20u * 24u);
        std::size_t marked = 0;
        for (int y = 30; y < 50; ++y)
            for (int x = 60; x < 84; ++x) {
                for (int i = 0; i < good; ++i)
                    marked += mk[static_cast<std::size_t>(i)][pixel(x, y, w)] == (mask_bits::dropped | mask_bits::left);
                REQUIRE(mk[static_cast<std::size_t>(good)][pixel(x, y, w)] == 0);
                for (std::size_t c = 0; c < 3; ++c) {  // left exactly as it was
                    REQUIRE(b.color[0][pixel(x, y, w) * 3 + c] == 0.0f);
                    REQUIRE(b.color[static_cast<std::size_t>(good)][pixel(x, y, w) * 3 + c] ==
                            intact.color[static_cast<std::size_t>(good)][pixel(x, y, w) * 3 + c]);
                }
            }
        CHECK(marked == static_cast<std::size_t>(good) * 20u * 24u);
    }
}

// Where fewer than 3 buffers are left (a tile black in two of four renders), their own
// fireflies cannot be told apart and stay: no light is given back there on top of them (it
// had been: the tile at 1.44x its expected light on the simulated caustics, 1.17x without).
TEST_CASE("K buffers: no light given back where too few buffers are left to test", "[dropped][buffers][energy]") {
    for (const char* name : {"caustics", "dense10"}) {
        INFO(name);
        const sim::buffers orig = sim::simulate_buffers(sim::named_scene(name, 160, 120, 5), 4);
        sim::buffers on = orig, off = orig;
        cross_buffer_options no_return;
        no_return.return_energy = false;
        std::vector<std::vector<std::uint8_t>> mk;
        const cross_buffer_report r_on = clean_with_black_tile(on, {1, 3}, mk);
        (void)clean_with_black_tile(off, {1, 3}, mk, no_return);
        REQUIRE(r_on.ok());
        CHECK(r_on.energy_returned > 0);
        const int w = orig.width;
        for (int y = 30; y < 50; ++y)
            for (int x = 60; x < 84; ++x)
                for (int i = 0; i < 4; ++i)
                    for (std::size_t c = 0; c < 3; ++c)
                        REQUIRE(on.color[static_cast<std::size_t>(i)][pixel(x, y, w) * 3 + c] ==
                                off.color[static_cast<std::size_t>(i)][pixel(x, y, w) * 3 + c]);
    }
}


// K = 2 hands the frame to the pair detector; its report must count what that found dropped
// as the K >= 3 path does (report.dropped, per_buffer), as its masks say. (It had counted
// fireflies and non-finite pixels only: the fuzz target's seed random_4 found the K >= 3 twin
// of this check failing in the harness, which did not count dropped pixels.)
TEST_CASE("K buffers: two buffers count the pixels the pair detector found dropped", "[dropped][buffers]") {
    sim::buffers b = sim::simulate_buffers(sim::named_scene("sparse_fireflies", 128, 96, 3), 2);
    const int w = b.width, h = b.height;
    for (int y = 30; y < 50; ++y)
        for (int x = 60; x < 84; ++x)
            for (int c = 0; c < 3; ++c) {
                b.color[1][pixel(x, y, w) * 3 + static_cast<std::size_t>(c)] = 0.0f;
                b.variance[1][pixel(x, y, w) * 3 + static_cast<std::size_t>(c)] = 0.0f;
            }
    std::vector<std::vector<std::uint8_t>> mk(2, std::vector<std::uint8_t>(b.pixels(), 0));
    std::vector<buffer_view<float>> views;
    std::vector<image_view<std::uint8_t>> masks;
    for (int i = 0; i < 2; ++i) {
        views.push_back({*make_image_view(b.color[static_cast<std::size_t>(i)].data(), w, h, 3),
                         *make_image_view(b.variance[static_cast<std::size_t>(i)].data(), w, h, 3)});
        masks.push_back(*make_image_view(mk[static_cast<std::size_t>(i)].data(), w, h, 1));
    }
    cross_buffer_detector d;
    const cross_buffer_report r = d.process(views, masks);
    REQUIRE(r.ok());
    CHECK(r.pair.half[1].dropped == 20u * 24u);
    CHECK(r.dropped == r.pair.half[0].dropped + r.pair.half[1].dropped);
    std::size_t marked = 0;
    for (int i = 0; i < 2; ++i) {
        std::size_t found = 0;
        for (const std::uint8_t m : mk[static_cast<std::size_t>(i)])
            found += (m & (mask_bits::firefly | mask_bits::nonfinite | mask_bits::dropped)) != 0;
        CHECK(r.per_buffer[static_cast<std::size_t>(i)] == found);
        marked += found;
    }
    CHECK(r.fireflies + r.nonfinite + r.dropped == marked);
}
