#include <firefly/reconstruct.hpp>
#include <firefly/stddev.hpp>

#include <cfloat>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <vector>

#include "catch.hpp"
#include "symmetry.hpp"

using namespace firefly;

namespace {
struct img {
    int w, h, c;
    std::vector<float> px;
    img(int w_, int h_, int c_) : w(w_), h(h_), c(c_), px(static_cast<std::size_t>(w_ * h_ * c_)) {}
    float& at(int x, int y, int ch) { return px[static_cast<std::size_t>((y * w + x) * c + ch)]; }
    image_view<float> view() { return *make_image_view(px.data(), w, h, c); }
};

// Deterministic pseudo-random fill.
void fill(img& im, unsigned seed) {
    std::uint32_t s = seed * 2654435761u + 1;
    for (auto& v : im.px) {
        s = s * 1664525u + 1013904223u;
        v = static_cast<float>((s >> 8) & 0xffff) / 65536.0f + 0.1f;
    }
}
}  // namespace

TEST_CASE("the paper's 2 2 x x 8 8 row has no directional bias", "[reconstruct]") {
    img im(6, 1, 1);
    const float row[6] = {2, 2, 1000, 1000, 8, 8};
    for (int x = 0; x < 6; ++x) im.at(x, 0, 0) = row[x];
    std::vector<std::uint8_t> mask = {0, 0, 1, 1, 0, 0};
    reconstruct_scratch s;
    const reconstruct_report r = reconstruct(im.view(), image_view<float>(), mask.data(), {}, s);
    REQUIRE(r.error.ok());
    CHECK(r.pixels == 2);
    // symmetric: the two x's mirror each other around 5
    CHECK(im.at(2, 0, 0) + im.at(3, 0, 0) == Approx(10.0f));
    CHECK(im.at(2, 0, 0) > 2.0f);
    CHECK(im.at(3, 0, 0) < 8.0f);
    CHECK(im.at(2, 0, 0) < im.at(3, 0, 0));
    // untouched pixels are bit-identical
    CHECK(im.at(0, 0, 0) == 2.0f);
    CHECK(im.at(5, 0, 0) == 8.0f);
}

TEST_CASE("flips and transposes give bit-identical results", "[reconstruct][invariant]") {
    const int w = 17;
    img base(w, w, 3);
    fill(base, 3);
    std::vector<std::uint8_t> mask(static_cast<std::size_t>(w * w), 0);
    // a cluster wider than the kernel, an isolated pixel, a border pixel, a corner pixel
    for (int y = 4; y < 12; ++y)
        for (int x = 3; x < 10; ++x) mask[static_cast<std::size_t>(y * w + x)] = 1;
    mask[static_cast<std::size_t>(2 * w + 14)] = 1;
    mask[static_cast<std::size_t>(0 * w + 7)] = 1;
    mask[static_cast<std::size_t>(16 * w + 16)] = 1;
    for (std::size_t i = 0; i < mask.size(); ++i)
        if (mask[i]) base.px[i * 3] = 1e6f;  // the firefly values must not matter
    reconstruct_options o;
    o.max_iterations = 50;
    o.tolerance = 0;  // run every iteration: a long chain of arithmetic to keep symmetric
    img ref = base;
    reconstruct_scratch s;
    const reconstruct_report r0 = reconstruct(ref.view(), image_view<float>(), mask.data(), o, s);
    CHECK(r0.phase1_rounds >= 2);
    for (int k = 1; k < 8; ++k) {
        const firefly_test::symmetry sym{k, w, w};
        img t(w, w, 3);
        t.px = sym.apply(base.px, 3);
        const std::vector<std::uint8_t> tm = sym.apply(mask, 1);
        const reconstruct_report r = reconstruct(t.view(), image_view<float>(), tm.data(), o, s);
        CHECK(r.phase1_rounds == r0.phase1_rounds);
        CHECK(r.phase2_iterations == r0.phase2_iterations);
        INFO("symmetry " << k);
        CHECK(t.px == sym.apply(ref.px, 3));
    }
}

TEST_CASE("clusters wider than the kernel stay within their neighbours' range", "[reconstruct]") {
    const int w = 40, h = 30;
    img col(w, h, 3), var(w, h, 3);
    fill(col, 9);
    fill(var, 10);
    std::vector<std::uint8_t> mask(static_cast<std::size_t>(w * h), 0);
    // a wide "highlight" disk whose every pixel is marked, radius 9 (kernel radius 2)
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            if ((x - 20) * (x - 20) + (y - 15) * (y - 15) <= 81) {
                mask[static_cast<std::size_t>(y * w + x)] = 1;
                for (int c = 0; c < 3; ++c) {
                    col.at(x, y, c) = std::numeric_limits<float>::quiet_NaN();
                    var.at(x, y, c) = 1e30f;
                }
            }
    float lo[3] = {1e30f, 1e30f, 1e30f}, hi[3] = {0, 0, 0};
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            if (!mask[static_cast<std::size_t>(y * w + x)])
                for (int c = 0; c < 3; ++c) {
                    lo[c] = std::min(lo[c], col.at(x, y, c));
                    hi[c] = std::max(hi[c], col.at(x, y, c));
                }
    reconstruct_scratch s;
    const reconstruct_report r = reconstruct(col.view(), var.view(), mask.data(), {}, s);
    REQUIRE(r.error.ok());
    CHECK(r.phase1_rounds >= 4);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            for (int c = 0; c < 3; ++c) {
                CHECK(std::isfinite(col.at(x, y, c)));
                CHECK(col.at(x, y, c) >= lo[c]);
                CHECK(col.at(x, y, c) <= hi[c]);
                CHECK(var.at(x, y, c) < 2.0f);  // variance rebuilt from neighbours too
            }
}

TEST_CASE("borders, corners, 1x1 and nothing to read from", "[reconstruct]") {
    reconstruct_scratch s;
    img one(1, 1, 3);
    one.at(0, 0, 0) = std::numeric_limits<float>::infinity();
    one.at(0, 0, 1) = 5.0f;
    std::uint8_t m1 = 1;
    reconstruct_report r = reconstruct(one.view(), image_view<float>(), &m1, {}, s);
    CHECK(r.error.code() == errc::no_valid_pixels);
    CHECK(r.unreachable == 1);
    CHECK(std::isinf(one.at(0, 0, 0)));  // left as it was: the status says why
    CHECK(one.at(0, 0, 1) == 5.0f);

    img all(4, 4, 1);
    fill(all, 2);
    all.at(1, 1, 0) = std::numeric_limits<float>::quiet_NaN();
    std::vector<std::uint8_t> every(16, 1);
    r = reconstruct(all.view(), image_view<float>(), every.data(), {}, s);
    CHECK(r.error.code() == errc::no_valid_pixels);
    CHECK(r.unreachable == 16);
    CHECK(std::isnan(all.at(1, 1, 0)));
    img before(4, 4, 1);
    fill(before, 2);
    CHECK(all.at(0, 0, 0) == before.at(0, 0, 0));

    img corner(5, 5, 1);
    for (auto& v : corner.px) v = 3.0f;
    corner.at(0, 0, 0) = 1e20f;
    corner.at(4, 4, 0) = 1e20f;
    std::vector<std::uint8_t> cm(25, 0);
    cm[0] = cm[24] = 1;
    r = reconstruct(corner.view(), image_view<float>(), cm.data(), {}, s);
    CHECK(r.error.ok());
    CHECK(corner.at(0, 0, 0) == 3.0f);
    CHECK(corner.at(4, 4, 0) == 3.0f);

    img none(3, 3, 1);
    std::vector<std::uint8_t> nm(9, 0);
    r = reconstruct(none.view(), image_view<float>(), nm.data(), {}, s);
    CHECK(r.pixels == 0);
}

TEST_CASE("unmarked pixels are never changed, bit for bit", "[reconstruct]") {
    img col(32, 20, 4), var(32, 20, 1);
    fill(col, 4);
    fill(var, 5);
    col.at(3, 3, 1) = -0.0f;
    const img col0 = col, var0 = var;
    std::vector<std::uint8_t> mask(32 * 20, 0);
    for (std::size_t i = 7; i < mask.size(); i += 37) mask[i] = 1;
    reconstruct_scratch s;
    (void)reconstruct(col.view(), var.view(), mask.data(), {}, s);
    for (std::size_t i = 0; i < mask.size(); ++i) {
        if (mask[i]) continue;
        for (int c = 0; c < 4; ++c)
            CHECK(std::memcmp(&col.px[i * 4 + static_cast<std::size_t>(c)], &col0.px[i * 4 + static_cast<std::size_t>(c)], 4) == 0);
        CHECK(std::memcmp(&var.px[i], &var0.px[i], 4) == 0);
    }
}

TEST_CASE("sources near DBL_MAX of either sign give a finite mean, never inf - inf", "[reconstruct]") {
    // A double frame (the fuzz target's reproducer rebuild_sum_overflows_near_dbl_max): the
    // plain weighted sums overflow to +inf and -inf and their sum is NaN.
    const int w = 5, h = 3;
    std::vector<double> px(static_cast<std::size_t>(w * h));
    for (int i = 0; i < w * h; ++i) px[static_cast<std::size_t>(i)] = (i % 3 == 0) ? -DBL_MAX : DBL_MAX;
    std::vector<std::uint8_t> mask(px.size(), 0);
    mask[7] = 1;  // the centre (2, 1)
    reconstruct_scratch s;
    const reconstruct_report r = reconstruct(*make_image_view(px.data(), w, h, 1), image_view<double>(), mask.data(), {}, s);
    REQUIRE(r.error.ok());
    CHECK(std::isfinite(px[7]));
    for (double& v : px) v = DBL_MAX;  // all at the top: the mean is DBL_MAX itself, not inf
    (void)reconstruct(*make_image_view(px.data(), w, h, 1), image_view<double>(), mask.data(), {}, s);
    CHECK(px[7] == Approx(DBL_MAX));
    CHECK(std::isfinite(px[7]));
}

TEST_CASE("options are checked", "[reconstruct]") {
    reconstruct_options o;
    o.kernel_width = 4;
    CHECK(check_reconstruct_options(o).code() == errc::invalid_argument);
    o.kernel_width = 7;
    o.sigma = 0;
    CHECK(!check_reconstruct_options(o).ok());
    o.sigma = 0.0999;  // every weight would underflow (at 0.02 the rebuild found no source)
    CHECK(!check_reconstruct_options(o).ok());
    o.sigma = 1.5;
    CHECK(check_reconstruct_options(o).ok());
    img im(3, 3, 1);
    std::vector<std::uint8_t> m(9, 1);
    reconstruct_scratch s;
    o.kernel_width = 2;
    CHECK(reconstruct(im.view(), image_view<float>(), m.data(), o, s).error.code() == errc::invalid_argument);
}

TEST_CASE("standard deviation: reductions, black, alpha, negative, non-finite", "[stddev]") {
    const int w = 6, h = 1;
    std::vector<float> col = {1, 1, 1, 0, 0, 0, 1, 2, 3, 1, 1, 1, 1, 1, 1, 1, 1, 1};
    std::vector<float> var = {4, 4, 4, 1, 1, 1, 1, 4, 16, -1, 4, 4, 1, 1, std::numeric_limits<float>::quiet_NaN(), 9, 9, 9};
    std::vector<float> alpha = {1, 1, 1, 1, 1, 0};
    auto c = *make_image_view(static_cast<const float*>(col.data()), w, h, 3);
    auto v = *make_image_view(static_cast<const float*>(var.data()), w, h, 3);
    auto a = *make_image_view(static_cast<const float*>(alpha.data()), w, h, 1);
    std::vector<float> sd(6);
    std::vector<std::uint8_t> lab(6);
    stddev_counts n = compute_stddev(c, v, a, variance_reduction::mean, sd.data(), lab.data());
    CHECK(sd[0] == 2.0f);
    CHECK(lab[1] == static_cast<std::uint8_t>(pixel_class::ignored));  // black
    CHECK(sd[2] == Approx(std::sqrt(7.0)));
    CHECK(sd[3] == Approx(std::sqrt(8.0 / 3.0)));  // -1 counts as 0
    CHECK(lab[4] == static_cast<std::uint8_t>(pixel_class::nonfinite));
    CHECK(std::isnan(sd[4]));
    CHECK(lab[5] == static_cast<std::uint8_t>(pixel_class::ignored));  // alpha 0
    CHECK(n.valid == 3);
    CHECK(n.ignored == 2);
    CHECK(n.nonfinite == 1);
    CHECK(n.negative_variance == 1);
    (void)compute_stddev(c, v, a, variance_reduction::max, sd.data(), lab.data());
    CHECK(sd[2] == 4.0f);
    (void)compute_stddev(c, v, a, variance_reduction::luminance, sd.data(), lab.data());
    CHECK(sd[2] == Approx(std::sqrt(0.2126 + 0.7152 * 4 + 0.0722 * 16)));
    CHECK(!check_half_views(c, *v.subview(0, 0, 5, 1), a).ok());
    CHECK(check_half_views(c, *v.channel_range(0, 2), a).code() == errc::channel_mismatch);
}

TEST_CASE("standard deviation: every layout gives the same bits", "[stddev][invariant]") {
    // Packed RGB (SIMD path), RGBA (4-channel path), planar (strided path), with and without
    // alpha, on values that exercise every class: NaN, Inf, black, negative, FLT_MAX, denormal.
    const int w = 37, h = 11;  // not a multiple of 4: SIMD tails too
    const std::size_t n = static_cast<std::size_t>(w * h);
    std::vector<float> rgb(n * 3), var(n * 3), alpha(n);
    std::uint32_t s = 12345;
    auto rnd = [&] {
        s = s * 1664525u + 1013904223u;
        return static_cast<float>(s >> 8) / 16777216.0f;
    };
    for (std::size_t i = 0; i < n; ++i) {
        for (int c = 0; c < 3; ++c) {
            rgb[i * 3 + c] = rnd();
            var[i * 3 + c] = rnd() * rnd();
        }
        alpha[i] = rnd() < 0.2f ? 0.0f : rnd();
        switch (i % 23) {
            case 1: rgb[i * 3 + 1] = std::numeric_limits<float>::quiet_NaN(); break;
            case 2: var[i * 3 + 2] = std::numeric_limits<float>::infinity(); break;
            case 3: rgb[i * 3] = rgb[i * 3 + 1] = rgb[i * 3 + 2] = 0.0f; break;
            case 4: var[i * 3 + 1] = -1e-7f; break;
            case 5: var[i * 3] = var[i * 3 + 1] = var[i * 3 + 2] = FLT_MAX; break;
            case 6: var[i * 3] = 1e-45f; break;
            case 7: rgb[i * 3] = -0.0f; rgb[i * 3 + 1] = 0.0f; rgb[i * 3 + 2] = -0.0f; break;
            case 8: alpha[i] = std::numeric_limits<float>::quiet_NaN(); break;
            case 9: var[i * 3 + 1] = -0.0f; break;
            default: break;
        }
    }
    std::vector<float> rgba(n * 4), vara(n * 4), planar_c(n * 3), planar_v(n * 3);
    for (std::size_t i = 0; i < n; ++i)
        for (int c = 0; c < 3; ++c) {
            rgba[i * 4 + c] = rgb[i * 3 + c];
            vara[i * 4 + c] = var[i * 3 + c];
            planar_c[c * n + i] = rgb[i * 3 + c];
            planar_v[c * n + i] = var[i * 3 + c];
        }
    for (variance_reduction how : {variance_reduction::mean, variance_reduction::luminance, variance_reduction::max})
        for (bool with_alpha : {false, true}) {
            image_view<const float> a;
            if (with_alpha) a = *make_image_view(static_cast<const float*>(alpha.data()), w, h, 1);
            std::vector<float> sd1(n), sd2(n), sd3(n);
            std::vector<std::uint8_t> l1(n), l2(n), l3(n);
            const stddev_counts k1 = compute_stddev(*make_image_view(static_cast<const float*>(rgb.data()), w, h, 3),
                                                    *make_image_view(static_cast<const float*>(var.data()), w, h, 3), a, how,
                                                    sd1.data(), l1.data());
            const auto cv = *make_image_view(static_cast<const float*>(rgba.data()), w, h, 4);
            const auto vv = *make_image_view(static_cast<const float*>(vara.data()), w, h, 4);
            const stddev_counts k2 = compute_stddev(*cv.channel_range(0, 3), *vv.channel_range(0, 3), a, how, sd2.data(), l2.data());
            const stddev_counts k3 = compute_stddev(*make_planar_view(static_cast<const float*>(planar_c.data()), w, h, 3),
                                                    *make_planar_view(static_cast<const float*>(planar_v.data()), w, h, 3), a,
                                                    how, sd3.data(), l3.data());
            INFO("reduction " << static_cast<int>(how) << " alpha " << with_alpha);
            CHECK(std::memcmp(sd1.data(), sd2.data(), n * 4) == 0);
            CHECK(std::memcmp(sd1.data(), sd3.data(), n * 4) == 0);
            CHECK(l1 == l2);
            CHECK(l1 == l3);
            CHECK(k1.valid == k3.valid);
            CHECK(k1.negative_variance == k2.negative_variance);
            CHECK(k1.nonfinite == k3.nonfinite);
            for (std::size_t i = 0; i < n; ++i) CHECK(!(sd1[i] > FLT_MAX));  // no overflow to Inf
        }
}

// An outside pixel (no geometry) is never read, not even when nothing else reaches a pixel,
// as an excluded one is then.
TEST_CASE("reconstruct: outside pixels are never read", "[reconstruct][alpha]") {
    img im(5, 5, 1);
    for (auto& v : im.px) v = 1e30f;  // outside: anything
    im.at(0, 0, 0) = 2.0f;            // the one source
    im.at(2, 2, 0) = 50.0f;           // to rebuild: reaches the source through the kernel
    std::vector<std::uint8_t> role_of(25, 2);  // 0 source, 1 rebuild, 2 outside
    role_of[0] = 0;
    role_of[12] = 1;
    auto role = [](std::uint8_t m) { return m == 1 ? pixel_role::rebuild : m == 2 ? pixel_role::outside : pixel_role::source; };
    reconstruct_scratch s;
    reconstruct_report r = reconstruct(im.view(), image_view<float>(), role_of.data(), {}, s, 0xFF, role);
    REQUIRE(r.error.ok());
    CHECK(im.at(2, 2, 0) == 2.0f);
    // A pixel whose neighbourhood is outside alone is left as it was and reported; an excluded
    // neighbourhood would have been read after all.
    img lone(3, 3, 1);
    for (auto& v : lone.px) v = 1e30f;
    lone.at(1, 1, 0) = 9.0f;
    std::vector<std::uint8_t> m(9, 2);
    m[4] = 1;
    r = reconstruct(lone.view(), image_view<float>(), m.data(), {}, s, 0xFF, role);
    CHECK(r.error.code() == errc::no_valid_pixels);
    CHECK(r.unreachable == 1);
    CHECK(lone.at(1, 1, 0) == 9.0f);
    auto excluded = [](std::uint8_t v) { return v == 1 ? pixel_role::rebuild : pixel_role::excluded; };
    r = reconstruct(lone.view(), image_view<float>(), m.data(), {}, s, 0xFF, excluded);
    CHECK(r.error.ok());
    CHECK(lone.at(1, 1, 0) == 1e30f);
}

TEST_CASE("reconstruct: a pixel only excluded ones reach reads them, and no other pixel does", "[reconstruct]") {
    // A cluster of two beside a kept highlight (excluded, 100) on a background of 1; far away, a
    // marked pixel inside a block of excluded pixels, which it reads after all. Before, that
    // fallback made every excluded pixel a source for the whole frame's phase 2, and the
    // cluster read the highlight: 5.01 and 13.1 instead of 1 and 1.
    const int w = 40, h = 12;
    auto run = [&](bool far_block, std::vector<float>& px) {
        px.assign(static_cast<std::size_t>(w * h), 1.0f);
        std::vector<std::uint8_t> m(px.size(), 0);  // 0 source, 1 rebuild, 2 excluded
        m[5 * w + 5] = m[5 * w + 6] = 1;
        px[5 * w + 5] = px[5 * w + 6] = 1000.0f;
        m[5 * w + 7] = 2;
        px[5 * w + 7] = 100.0f;
        if (far_block) {
            for (int y = 3; y <= 9; ++y)
                for (int x = 28; x <= 34; ++x) m[static_cast<std::size_t>(y * w + x)] = 2, px[static_cast<std::size_t>(y * w + x)] = 50.0f;
            m[6 * w + 31] = 1;
            px[6 * w + 31] = 1e4f;
        }
        reconstruct_scratch s;
        return reconstruct(*make_image_view(px.data(), w, h, 1), image_view<float>(), m.data(), {}, s, 0xFF,
                           [](std::uint8_t v) { return v == 1 ? pixel_role::rebuild : v == 2 ? pixel_role::excluded : pixel_role::source; });
    };
    std::vector<float> alone, with_far;
    REQUIRE(run(false, alone).error.ok());
    const reconstruct_report r = run(true, with_far);
    REQUIRE(r.error.ok());
    CHECK(alone[5 * w + 5] == 1.0f);
    CHECK(alone[5 * w + 6] == 1.0f);
    CHECK(with_far[5 * w + 5] == alone[5 * w + 5]);
    CHECK(with_far[5 * w + 6] == alone[5 * w + 6]);
    CHECK(with_far[6 * w + 31] == 50.0f);  // the block's level: all it can read
    CHECK(r.unreachable == 0);
}
