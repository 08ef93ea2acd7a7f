#include <firefly/image_view.hpp>

#include <cstdint>
#include <limits>
#include <vector>

#include "catch.hpp"

using namespace firefly;

// Traits: what the view accepts, checked at compile time.
static_assert(is_channel_type_v<float>);
static_assert(is_channel_type_v<const double>);
static_assert(is_channel_type_v<std::uint8_t>);
static_assert(!is_channel_type_v<int>);
static_assert(std::is_same_v<image_view<const float>::value_type, float>);
static_assert(std::is_convertible_v<image_view<float>, image_view<const float>>);
static_assert(!std::is_convertible_v<image_view<const float>, image_view<float>>);
static_assert(std::is_trivially_copyable_v<image_view<float>>);
static_assert(channel_traits<float>::load(0.5f) == 0.5);

namespace {
struct half_like {  // a user channel type: 16-bit fixed point in [0, 1]
    std::uint16_t bits;
};
}  // namespace
template <>
struct firefly::channel_traits<half_like> {
    static constexpr bool is_specialized = true;
    static double load(half_like v) noexcept { return v.bits / 65535.0; }
    static half_like store(double v) noexcept {
        return half_like{static_cast<std::uint16_t>(v <= 0 ? 0 : v >= 1 ? 65535 : v * 65535.0 + 0.5)};
    }
};
static_assert(is_channel_type_v<half_like>);

TEST_CASE("packed RGB float interleaved", "[image_view]") {
    std::vector<float> px(4 * 3 * 3);
    for (std::size_t i = 0; i < px.size(); ++i) px[i] = static_cast<float>(i);
    auto v = make_image_view(px.data(), 4, 3, 3);
    REQUIRE(v.ok());
    CHECK(v->is_packed());
    CHECK(v->width() == 4);
    CHECK(v->height() == 3);
    CHECK(v->channels() == 3);
    CHECK((*v)(2, 1, 1) == px[(1 * 4 + 2) * 3 + 1]);
    CHECK(v->load(3, 2, 2) == px.back());
    v->store(0, 0, 0, 42.0);
    CHECK(px[0] == 42.0f);
    image_view<const float> cv = *v;  // const view of the same pixels
    CHECK(cv(2, 1, 1) == px[(1 * 4 + 2) * 3 + 1]);
}

TEST_CASE("RGBA with alpha as a channel range", "[image_view]") {
    std::vector<float> px(5 * 2 * 4, 0.25f);
    for (int i = 0; i < 10; ++i) px[static_cast<std::size_t>(i) * 4 + 3] = static_cast<float>(i) / 10;
    auto rgba = make_image_view(px.data(), 5, 2, 4);
    REQUIRE(rgba.ok());
    auto rgb = rgba->channel_range(0, 3);
    auto a = rgba->channel_range(3, 1);
    REQUIRE(rgb.ok());
    REQUIRE(a.ok());
    CHECK(rgb->channels() == 3);
    CHECK(!rgb->is_packed());
    CHECK((*a)(4, 1) == Approx(0.9f));
    CHECK((*rgb)(4, 1, 2) == 0.25f);
    CHECK(!rgba->channel_range(2, 3).ok());
}

TEST_CASE("planar channels", "[image_view]") {
    const int w = 3, h = 2;
    std::vector<double> planes(static_cast<std::size_t>(w * h * 3));
    for (int c = 0; c < 3; ++c)
        for (int i = 0; i < w * h; ++i) planes[static_cast<std::size_t>(c * w * h + i)] = c * 100 + i;
    auto v = make_planar_view(planes.data(), w, h, 3);
    REQUIRE(v.ok());
    CHECK(!v->is_packed());
    CHECK((*v)(1, 1, 2) == 200 + 4);
    CHECK((*v)(2, 0, 1) == 100 + 2);
}

TEST_CASE("rows padded to 64 bytes", "[image_view]") {
    const int w = 5, h = 3;
    const std::ptrdiff_t row = 64;  // 5 RGB floats = 60 bytes, padded to 64
    std::vector<float> buf(static_cast<std::size_t>(row / 4 * h), -1.0f);
    auto v = make_image_view(buf.data(), w, h, 3, row);
    REQUIRE(v.ok());
    CHECK(!v->is_packed());
    (*v)(4, 2, 2) = 7.0f;
    CHECK(buf[static_cast<std::size_t>(2 * 16 + 4 * 3 + 2)] == 7.0f);
    CHECK(v->row_stride() == 64);
    // Too small a row stride overlaps rows: refused.
    auto bad = make_image_view(buf.data(), w, h, 3, 56);
    REQUIRE(!bad.ok());
    CHECK(bad.error().code() == errc::bad_stride);
}

TEST_CASE("bottom-up rows through a negative row stride", "[image_view]") {
    const int w = 2, h = 3;
    std::vector<float> buf = {0, 1, 10, 11, 20, 21};  // memory row 0 is the image's bottom row
    auto v = image_view<float>::create(buf.data() + 4, w, h, 1, auto_stride, -8);
    REQUIRE(v.ok());
    CHECK((*v)(0, 0) == 20);  // top row of the image = last row in memory
    CHECK((*v)(1, 2) == 1);
    auto flipped = v->flipped_vertically();
    CHECK(flipped(0, 0) == 0);
    CHECK(flipped(1, 2) == 21);
}

TEST_CASE("double and user channel types", "[image_view]") {
    std::vector<double> d(6, 0.5);
    auto v = make_image_view(d.data(), 2, 1, 3);
    REQUIRE(v.ok());
    v->store(1, 0, 2, 1e300);
    CHECK(d[5] == 1e300);
    std::vector<half_like> u(4, half_like{0});
    auto hv = make_image_view(u.data(), 2, 2, 1);
    REQUIRE(hv.ok());
    hv->store(1, 1, 0, 0.5);
    CHECK(hv->load(1, 1) == Approx(0.5).margin(1e-4));
}

TEST_CASE("sub-views", "[image_view]") {
    std::vector<float> px(6 * 4);
    for (std::size_t i = 0; i < px.size(); ++i) px[i] = static_cast<float>(i);
    auto v = make_image_view(px.data(), 6, 4, 1);
    REQUIRE(v.ok());
    auto s = v->subview(2, 1, 3, 2);
    REQUIRE(s.ok());
    CHECK(s->width() == 3);
    CHECK((*s)(0, 0) == px[1 * 6 + 2]);
    CHECK((*s)(2, 1) == px[2 * 6 + 4]);
    CHECK(!v->subview(4, 0, 3, 1).ok());
    CHECK(!v->subview(-1, 0, 1, 1).ok());
    CHECK(v->subview(6, 4, 0, 0).ok());  // an empty rectangle at the corner is fine
}

TEST_CASE("refused layouts are errors, not UB", "[image_view]") {
    std::vector<float> px(64);
    CHECK(image_view<float>::create(nullptr, 2, 2, 3).error().code() == errc::null_data);
    CHECK(image_view<float>::create(px.data(), -1, 2).error().code() == errc::invalid_argument);
    CHECK(image_view<float>::create(px.data(), 2, 2, 0).error().code() == errc::empty_image);
    // channels overlapping each other
    CHECK(image_view<float>::create(px.data(), 2, 2, 3, 12, 24, 2).error().code() == errc::bad_stride);
    // pixels overlapping each other
    CHECK(image_view<float>::create(px.data(), 4, 1, 3, 8).error().code() == errc::bad_stride);
    // misaligned stride
    CHECK(image_view<float>::create(px.data(), 2, 2, 1, 4, 10).error().code() == errc::bad_stride);
    // width x stride overflow
    const auto big = std::numeric_limits<std::ptrdiff_t>::max() / 2;
    CHECK(image_view<float>::create(px.data(), 1 << 30, 4, 1, big).error().code() == errc::size_overflow);
    // empty images need no data
    auto e = image_view<float>::create(nullptr, 0, 0, 3);
    REQUIRE(e.ok());
    CHECK(e->empty());
    CHECK(image_view<float>().empty());
}
