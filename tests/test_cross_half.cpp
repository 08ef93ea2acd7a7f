// Rebuilding from the other half: reconstruction that never smears.
#include <firefly/firefly.hpp>
#include <firefly/sim/metrics.hpp>
#include <firefly/sim/scene.hpp>

#include <cfloat>
#include <cmath>
#include <cstring>
#include <deque>
#include <limits>
#include <thread>
#include <vector>

#include "catch.hpp"
#include "frame_views.hpp"
#include "symmetry.hpp"

using namespace firefly;

namespace {
using firefly_test::frame_views;

sim::frame flat(int w, int h, unsigned seed) { return sim::simulate(sim::named_scene("flat", w, h, seed)); }

// relMSE of the combined image over a rectangle.
double region_relmse(const sim::frame& f, const std::vector<float>* col, int x0, int y0, int x1, int y1) {
    std::vector<float> img, ref;
    for (int y = y0; y < y1; ++y)
        for (int x = x0; x < x1; ++x)
            for (int c = 0; c < 3; ++c) {
                const std::size_t j = (static_cast<std::size_t>(y) * static_cast<std::size_t>(f.width) + static_cast<std::size_t>(x)) * 3 + static_cast<std::size_t>(c);
                img.push_back(0.5f * (col[0][j] + col[1][j]));
                ref.push_back(f.expected[j]);
            }
    return sim::relmse(img.data(), ref.data(), img.size() / 3);
}
// The cross-half estimate of the centre of 3x3 RGB double halves (col[0] its own half,
// col[1] the other), every other pixel clean, with a 3x3 kernel of sigma 1; returns a.
double centre_estimate(const std::vector<double> (&col)[2], const std::vector<double> (&var)[2], double calibration,
                       double* out) {
    const half_views<double, double> own{*make_image_view<const double>(col[0].data(), 3, 3, 3),
                                         *make_image_view<const double>(var[0].data(), 3, 3, 3)};
    const half_views<double, double> other{*make_image_view<const double>(col[1].data(), 3, 3, 3),
                                           *make_image_view<const double>(var[1].data(), 3, 3, 3)};
    detail::gaussian_kernel k;
    k.set(3, 1.0);
    auto clean = [](int xx, int yy) { return xx != 1 || yy != 1; };
    return detail::cross_half_estimate(own, other, k, calibration, true, 1, 1, clean, clean, out);
}

}  // namespace

TEST_CASE("a one-half firefly on detail takes the other half's value, not its neighbours'", "[cross_half]") {
    // A bright one-pixel line (x = 20) on a dark ground; a firefly on the line in half A.
    frame_views v(flat(48, 40, 21));
    for (int y = 0; y < 40; ++y)
        for (int half = 0; half < 2; ++half) v.set(half, 20, y, 8.0f + 0.1f * static_cast<float>(half), 0.04f);
    v.set(0, 20, 15, 900.0f, 810000.0f);
    const float b_value = v.col(1, 20, 15);
    detector d;
    const frame_report r = d.process(v.h[0], v.h[1]);
    REQUIRE(r.ok());
    CHECK(r.half[0].fireflies == 1);
    CHECK(r.half[0].from_other_half == 1);
    // the neighbours along the line are outliers (excluded), the rest are ground at ~0.5: a
    // spatial estimate would be ~0.5; the other half says 8.1, and its bias test agrees.
    CHECK(std::fabs(v.col(0, 20, 15) - b_value) < 0.05f * b_value);
    // the rebuilt variance is the other half's (the estimate's own variance)
    CHECK(v.var(0, 20, 15) == Approx(v.var(1, 20, 15)).epsilon(0.05));
    // the paper's spatial rule smears the line's pixel into the ground
    frame_views p(flat(48, 40, 21));
    for (int y = 0; y < 40; ++y)
        for (int half = 0; half < 2; ++half) p.set(half, 20, y, 8.0f + 0.1f * static_cast<float>(half), 0.04f);
    p.set(0, 20, 15, 900.0f, 810000.0f);
    detector_options o;
    o.rebuild = rebuild_source::spatial;
    detector ds(o);
    REQUIRE(ds.process(p.h[0], p.h[1]).ok());
    CHECK(p.col(0, 20, 15) < 2.0f);
}

TEST_CASE("in a smooth region the spatial estimate is blended in", "[cross_half]") {
    frame_views v(flat(40, 40, 5));
    v.set(0, 20, 20, 500.0f, 250000.0f);
    const float b_value = v.col(1, 20, 20);
    detector_options no_blend;
    no_blend.blend_spatial = false;
    frame_views w(flat(40, 40, 5));
    w.set(0, 20, 20, 500.0f, 250000.0f);
    detector d, dn(no_blend);
    REQUIRE(d.process(v.h[0], v.h[1]).ok());
    REQUIRE(dn.process(w.h[0], w.h[1]).ok());
    CHECK(w.col(0, 20, 20) == b_value);  // the other half alone: its value, bit for bit
    CHECK(v.col(0, 20, 20) != b_value);  // blended: the neighbours carry weight
    // the blend has a smaller variance than the other half alone
    CHECK(v.var(0, 20, 20) < w.var(0, 20, 20));
    // and lies between the spatial estimate (~0.5) and the other half's value
    const double lo = std::min(0.5, static_cast<double>(b_value)) - 0.2, hi = std::max(0.5, static_cast<double>(b_value)) + 0.2;
    CHECK(v.col(0, 20, 20) > lo);
    CHECK(v.col(0, 20, 20) < hi);
}

TEST_CASE("a failed bucket is rebuilt from the other half, not smeared from its rim", "[cross_half]") {
    sim::scene sc = sim::named_scene("failed_bucket", 256, 192, 3);
    sc.effects |= sim::fine_detail;  // detail in the bucket: what a smear would lose
    sim::scene intact = sc;
    intact.effects &= ~sim::failed_bucket;
    frame_views v(sim::simulate(sc)), ref(sim::simulate(intact));
    // the bucket: non-finite in half A only
    int x0 = 1 << 30, y0 = 1 << 30, x1 = -1, y1 = -1;
    for (int y = 0; y < 192; ++y)
        for (int x = 0; x < 256; ++x)
            if (v.f.nonfinite[0][v.at(x, y)] && !std::isfinite(v.col(0, x, y))) {
                x0 = std::min(x0, x), y0 = std::min(y0, y), x1 = std::max(x1, x + 1), y1 = std::max(y1, y + 1);
            }
    REQUIRE(x1 - x0 >= 16);
    detector d, d_ref;
    const frame_report r = d.process(v.h[0], v.h[1]);
    REQUIRE(r.ok());
    CHECK(r.half[0].phase1_rounds <= 2);  // no filling from the rim inwards
    CHECK(r.half[0].from_other_half >= static_cast<std::size_t>((x1 - x0) * (y1 - y0)));
    REQUIRE(d_ref.process(ref.h[0], ref.h[1]).ok());
    const double bucket = region_relmse(v.f, v.f.color, x0, y0, x1, y1);
    const double intact_err = region_relmse(ref.f, ref.f.color, x0, y0, x1, y1);
    INFO("bucket relMSE " << bucket << ", intact " << intact_err);
    CHECK(bucket < 8.0 * intact_err);  // half the samples there (measured 5.6x), not a blur
    // the paper's spatial rule fills the square from its rim: a blur, far worse
    frame_views s(sim::simulate(sc));
    detector_options o;
    o.rebuild = rebuild_source::spatial;
    detector ds(o);
    REQUIRE(ds.process(s.h[0], s.h[1]).ok());
    CHECK(region_relmse(s.f, s.f.color, x0, y0, x1, y1) > 2.0 * bucket);  // measured 3.5x
}

TEST_CASE("spatial sources exclude every outlier: no firefly is rebuilt from a kept highlight", "[cross_half]") {
    frame_views v(flat(40, 40, 8));
    // a confident one-pixel highlight, and two pixels away (inside the kernel, outside the
    // cluster rule's 8 neighbours) a firefly in BOTH halves (two samples that met): rebuilt
    // spatially in each half, from clean neighbours only.
    for (int half = 0; half < 2; ++half) v.set(half, 20, 20, 30.0f, 0.5f);
    for (int half = 0; half < 2; ++half) v.set(half, 22, 20, 600.0f, 360000.0f);
    detector d;
    const frame_report r = v.process(d);
    REQUIRE(r.ok());
    const auto& ma = v.mask[0];
    CHECK(ma[v.at(20, 20)] == mask_bits::highlight);
    CHECK((ma[v.at(22, 20)] & mask_bits::firefly) != 0);
    CHECK((ma[v.at(22, 20)] & mask_bits::other_half) == 0);  // bad in both halves: spatial
    CHECK(v.col(0, 20, 20) == 30.0f);
    CHECK(v.col(0, 22, 20) < 1.5f);  // the ground's level, not pulled towards 30
    CHECK(v.col(1, 22, 20) < 1.5f);
}

TEST_CASE("a decision depends on the pixel and its neighbourhood, not on a far firefly", "[cross_half][highlight]") {
    for (highlight_rule rule : {highlight_rule::agree, highlight_rule::same_pixel, highlight_rule::confident}) {
        std::vector<float> results;
        for (bool far_firefly : {false, true}) {
            frame_views v(flat(128, 64, 4));
            // a firefly on a highlight pixel in half A (the pair: A 140, B 40)
            v.set(0, 30, 30, 140.0f, 10009.0f);
            v.set(1, 30, 30, 40.0f, 9.0f);
            if (far_firefly) v.set(1, 115, 30, 500.0f, 250000.0f);  // 85 pixels away, one half
            detector_options o;
            o.highlight.rule = rule;
            detector d(o);
            REQUIRE(d.process(v.h[0], v.h[1]).ok());
            results.push_back(v.col(0, 30, 30));
        }
        CHECK(results[0] == results[1]);
    }
}

TEST_CASE("detect() and reconstruct = false change nothing and count nothing as repaired", "[cross_half]") {
    frame_views v(flat(32, 32, 9));
    v.set(0, 5, 5, 400.0f, 160000.0f);
    v.f.color[1][v.at(7, 7) * 3] = std::numeric_limits<float>::quiet_NaN();
    const sim::frame before = v.f;
    std::vector<std::uint8_t> mb(32 * 32);
    detector d;
    const half_buffer<const float> ca{v.h[0].color, v.h[0].variance, v.h[0].alpha};
    const half_buffer<const float> cb{v.h[1].color, v.h[1].variance, v.h[1].alpha};
    const frame_report r = d.detect(ca, cb, {}, *make_image_view(mb.data(), 32, 32));
    REQUIRE(r.ok());
    CHECK(r.half[0].fireflies == 1);
    CHECK(r.half[1].nonfinite == 1);
    CHECK(r.half[1].repaired == 0);
    CHECK((mb[v.at(7, 7)] & mask_bits::nonfinite) != 0);
    for (int k = 0; k < 2; ++k) CHECK(std::memcmp(before.color[k].data(), v.f.color[k].data(), before.color[k].size() * 4) == 0);
    detector_options o;
    o.reconstruct = false;
    detector dn(o);
    const frame_report rn = dn.process(v.h[0], v.h[1]);
    CHECK(rn.half[1].repaired == 0);
    CHECK(rn.half[0].from_other_half == 0);
    for (int k = 0; k < 2; ++k) CHECK(std::memcmp(before.color[k].data(), v.f.color[k].data(), before.color[k].size() * 4) == 0);
}

TEST_CASE("rebuilding from the other half is bit-identical under flips, transposes and threads", "[cross_half][invariant]") {
    const int w = 96, h = 96;
    const sim::frame base = sim::simulate(sim::named_scene("production", w, h, 17));
    auto transform = [&](const std::vector<float>& in, int s) { return firefly_test::symmetry{s, w, h}.apply(in, 3); };
    auto run = [&](int s, executor e) {
        sim::frame f = base;
        for (int k = 0; k < 2; ++k) {
            f.color[k] = transform(base.color[k], s);
            f.variance[k] = transform(base.variance[k], s);
        }
        f.alpha.clear();
        frame_views v(std::move(f));
        detector d(detector_options{}, std::move(e));
        (void)d.process(v.h[0], v.h[1]);
        return std::vector<std::vector<float>>{v.f.color[0], v.f.color[1], v.f.variance[0]};
    };
    const auto ref = run(0, executor{});
    for (int s = 1; s < 8; ++s) {
        const auto out = run(s, s == 5 ? executor::threads(2) : executor{});
        for (std::size_t k = 0; k < ref.size(); ++k) {
            const std::vector<float> back = transform(ref[k], s);  // the reference, moved the same way
            CHECK(std::memcmp(back.data(), out[k].data(), back.size() * 4) == 0);
        }
    }
}

TEST_CASE("detectors share one lambda cache", "[cross_half][pipeline]") {
    auto cache = std::make_shared<lambda_cache>();
    detector a(detector_options{}, executor{}, cache), b(detector_options{}, executor{}, a.shared_lambdas());
    frame_views v(flat(64, 64, 2)), w(flat(64, 64, 2));
    v.set(0, 10, 10, 500.0f, 250000.0f);
    w.set(0, 10, 10, 500.0f, 250000.0f);
    const frame_report ra = a.process(v.h[0], v.h[1]);
    const frame_report rb = b.process(w.h[0], w.h[1]);
    CHECK(ra.lambdas_computed > 0);
    CHECK(rb.lambdas_computed == 0);  // every lambda the second needs, the first computed
    CHECK(&a.lambdas() == &b.lambdas());
}

TEST_CASE("detectors sharing one lambda cache run on two threads at once", "[cross_half][pipeline][threads]") {
    // Each frame grows, so each needs lambdas the cache does not hold yet; a frame's end asks
    // the cache its size (scratch_bytes) while the other thread fills it: a data race that
    // ThreadSanitizer found (scripts/test.sh --threads) before the cache locked its bytes().
    // Here: both threads' outputs are those of a detector alone.
    auto frames = [](int seed) {
        std::deque<frame_views> out;  // frame_views stay where they are made (their views point in)
        for (int i = 0; i < 12; ++i) {
            out.emplace_back(flat(40 + 9 * i + seed, 30 + 5 * i, 2));
            out.back().set(0, 3 + i, 4, 500.0f, 250000.0f);
            out.back().set(1, 7, 5 + i, 300.0f, 90000.0f);
        }
        return out;
    };
    detector_options other;
    other.alpha = 0.01;  // a second table in the shared cache
    detector a(detector_options{}), b(other, executor{}, a.shared_lambdas());
    std::deque<frame_views> fa = frames(1), fb = frames(2), ra = frames(1), rb = frames(2);
    std::thread ta([&] { for (frame_views& v : fa) (void)a.process(v.h[0], v.h[1]); });
    std::thread tb([&] { for (frame_views& v : fb) (void)b.process(v.h[0], v.h[1]); });
    ta.join();
    tb.join();
    detector alone_a(detector_options{}), alone_b(other);
    for (frame_views& v : ra) (void)alone_a.process(v.h[0], v.h[1]);
    for (frame_views& v : rb) (void)alone_b.process(v.h[0], v.h[1]);
    for (std::size_t i = 0; i < fa.size(); ++i) {
        CHECK(fa[i].f.color[0] == ra[i].f.color[0]);
        CHECK(fb[i].f.color[1] == rb[i].f.color[1]);
    }
    CHECK(a.lambdas().bytes() > 0);
}

TEST_CASE("enum options outside their enumerators are errors", "[cross_half][errors]") {
    detector_options o;
    o.rebuild = static_cast<rebuild_source>(7);
    CHECK(check_options(o).code() == errc::invalid_argument);
    o = {};
    o.highlight.rule = static_cast<highlight_rule>(9);
    CHECK(check_options(o).code() == errc::invalid_argument);
    o = {};
    o.reduction = static_cast<variance_reduction>(200);
    CHECK(check_options(o).code() == errc::invalid_argument);
    o = {};
    o.lambdas = static_cast<lambda_method>(3);
    CHECK(check_options(o).code() == errc::invalid_argument);
}

TEST_CASE("the blend's variance stays finite where the spatial estimate's bias overflows", "[cross_half][numerics]") {
    // Found by fuzz_buffers (tests/fuzz/regressions/buffers/variance_nan_where_the_bias_overflowed):
    // the other half's neighbours 1e151 above its pixel make the spatial estimate's squared
    // bias ~1e302, finite, but at a calibration of 1e-8 it overflows in renderer units, while
    // the spatial weight a = 2 vB / (MSE(S) + vB) ~ 1e-186 stays positive and a^2 underflows
    // to 0: a^2 (var + bias^2) was 0 x Inf = NaN. The term is a^2 bias^2 ~ 1e-62 here.
    const int w = 3, h = 3;
    std::vector<double> col[2], var[2];
    for (int half = 0; half < 2; ++half) {
        col[half].assign(static_cast<std::size_t>(w) * h * 3, half ? 1e151 : 2.0);
        var[half].assign(col[half].size(), 1.0);
    }
    for (int c = 0; c < 3; ++c) {
        col[1][(1 * w + 1) * 3 + c] = 0.5;     // the other half's value at the pixel
        var[1][(1 * w + 1) * 3 + c] = 1e124;   // ... and its variance
        col[0][(1 * w + 1) * 3 + c] = 1e300;   // the firefly
    }
    double out[6];
    const double a = centre_estimate(col, var, 1e-8, out);
    CHECK(a > 0.0);
    CHECK(a < 1e-150);
    for (int c = 0; c < 3; ++c) {
        CHECK(std::isfinite(out[c]));
        CHECK(out[3 + c] == Approx(1e124).epsilon(1e-9));  // (1 - a)^2 vB, the rest ~1e-62
    }
}

TEST_CASE("the spatial estimate stays finite where double neighbours near DBL_MAX overflow its sums", "[cross_half][numerics]") {
    // Found by fuzz_buffers (tests/fuzz/regressions/buffers/inf_where_double_sums_overflowed):
    // the kernel adds opposite neighbours first, and two at -DBL_MAX made -inf, so a pixel
    // rebuilt from finite data came out -inf. Their weighted mean is finite: the sums are now
    // taken again at overflow_scale (kernel.hpp), and the colour and the variance are finite.
    const int w = 3, h = 3;
    std::vector<double> col[2], var[2];
    for (int half = 0; half < 2; ++half) {
        col[half].assign(static_cast<std::size_t>(w) * h * 3, half ? 4.0 : -DBL_MAX);
        var[half].assign(col[half].size(), 1.0);
    }
    for (int c = 0; c < 3; ++c) col[0][(1 * w + 1) * 3 + c] = 1.0;  // the firefly's own value
    double out[6];
    // The other half agrees with its neighbours (no bias seen), so the spatial estimate is
    // taken whole: the neighbours' mean, -DBL_MAX.
    CHECK(centre_estimate(col, var, 1.0, out) == 1.0);
    for (int c = 0; c < 3; ++c) {
        CHECK(std::isfinite(out[c]));
        CHECK(out[c] == Approx(-DBL_MAX).epsilon(1e-12));
        CHECK(std::isfinite(out[3 + c]));
        CHECK(out[3 + c] >= 0.0);
    }
    // The neighbours' variances at DBL_MAX too: their sum overflowed as well.
    for (std::size_t i = 0; i < var[0].size(); ++i) var[0][i] = DBL_MAX;
    const double a = centre_estimate(col, var, 1.0, out);
    CHECK(a > 0.0);
    CHECK(a < 1e-300);  // a spatial estimate that noisy is all but left out
    for (int c = 0; c < 6; ++c) CHECK(std::isfinite(out[c]));
    for (int c = 0; c < 3; ++c) CHECK(out[c] == Approx(a * -DBL_MAX + (1 - a) * 4.0));  // a S ~ -15
}

TEST_CASE("float halves near FLT_MAX: a rebuilt variance is held within the float range", "[cross_half][numerics]") {
    // Half B's variance FLT_MAX everywhere, A's (FLT_MAX, 0, 0), the colour 3.5e19; A fails at
    // one pixel, where B reads 1. The blend's variance of one channel passes FLT_MAX (the bias
    // term is the channels' mean); before, the float store made it +inf from finite input.
    const int w = 16, h = 16, n = w * h;
    const float level = 3.5e19f;
    std::vector<float> ac(n * 3, level), av(n * 3, 0.0f), bc(n * 3, level), bv(n * 3, FLT_MAX);
    for (int i = 0; i < n; ++i) av[static_cast<std::size_t>(i) * 3] = FLT_MAX;
    const std::size_t p = 8 * w + 8;
    for (std::size_t c = 0; c < 3; ++c) ac[p * 3 + c] = std::numeric_limits<float>::quiet_NaN(), bc[p * 3 + c] = 1.0f;
    half_buffer<float> a{*make_image_view(ac.data(), w, h, 3), *make_image_view(av.data(), w, h, 3), {}};
    half_buffer<float> b{*make_image_view(bc.data(), w, h, 3), *make_image_view(bv.data(), w, h, 3), {}};
    std::vector<std::uint8_t> ma(n), mb(n);
    detector d;
    const frame_report r = d.process(a, b, *make_image_view(ma.data(), w, h, 1), *make_image_view(mb.data(), w, h, 1));
    REQUIRE(r.error.ok());
    CHECK((ma[p] & mask_bits::other_half) != 0);
    for (const std::vector<float>* v : {&ac, &av, &bc, &bv})
        for (const float x : *v) REQUIRE(std::isfinite(x));
    // the store itself: finite doubles past the range are held, inf and NaN stay
    using ct = channel_traits<float>;
    CHECK(ct::store(1e39) == FLT_MAX);
    CHECK(ct::store(-DBL_MAX) == -FLT_MAX);
    CHECK(ct::store(static_cast<double>(FLT_MAX)) == FLT_MAX);
    CHECK(std::isinf(ct::store(HUGE_VAL)));
    CHECK(ct::store(-HUGE_VAL) < 0);
    CHECK(std::isnan(ct::store(std::nan(""))));
    CHECK(ct::store(1e-46) == 0.0f);  // below the denormals: rounds as ever
}
