// firefly: a non-owning, strided view of a 2-D image in the caller's memory.
//
// Every algorithm reads and writes pixels through this one type. Strides are in BYTES
// (the OpenImageIO / Open Image Denoise convention) between channels, pixels and rows,
// so interleaved RGB/RGBA, rows padded for alignment, planar channels and bottom-up
// images (negative row stride, data pointing at row 0) are all the same type.
// A stride of `auto_stride` (0) means "packed".
#pragma once

#include <cfloat>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <type_traits>

#include "status.hpp"

namespace firefly {

inline constexpr std::ptrdiff_t auto_stride = 0;

// ---------------------------------------------------------------------------------------
// Channel traits: how one channel value converts to and from double. Specialise for a user
// type (a half-float, a fixed-point type, a strong typedef) to use it in views.
template <class T>
struct channel_traits {
    static constexpr bool is_specialized = false;
};

template <>
struct channel_traits<float> {
    static constexpr bool is_specialized = true;
    static constexpr double load(float v) noexcept { return static_cast<double>(v); }
    // A finite value past the float range is held at +-FLT_MAX (the plain cast is undefined
    // there, +-inf in practice: finite input would give infinite output); inf and NaN stay.
    static constexpr float store(double v) noexcept {
        return v > static_cast<double>(FLT_MAX) && v <= DBL_MAX     ? FLT_MAX
               : v < -static_cast<double>(FLT_MAX) && v >= -DBL_MAX ? -FLT_MAX
                                                                    : static_cast<float>(v);
    }
};

template <>
struct channel_traits<double> {
    static constexpr bool is_specialized = true;
    static constexpr double load(double v) noexcept { return v; }
    static constexpr double store(double v) noexcept { return v; }
};

// 8-bit channels (masks): stored rounded and clamped to [0, 255].
template <>
struct channel_traits<std::uint8_t> {
    static constexpr bool is_specialized = true;
    static constexpr double load(std::uint8_t v) noexcept { return v; }
    static constexpr std::uint8_t store(double v) noexcept {
        return static_cast<std::uint8_t>(v >= 255.0 ? 255 : v > 0.0 ? static_cast<int>(v + 0.5) : 0);
    }
};

template <class T>
inline constexpr bool is_channel_type_v = channel_traits<std::remove_cv_t<T>>::is_specialized;

// Pixel traits: a pixel struct whose channels are consecutive values of one channel type
// (glm::vec3, a renderer's Color). Specialise with `using channel_type` and `channels`.
template <class P>
struct pixel_traits {
    static constexpr bool is_specialized = false;
};

// ---------------------------------------------------------------------------------------
namespace detail {

// The column and row of pixel index i (row-major, without padding) in a frame w wide.
inline int column_of(std::size_t i, int w) noexcept { return static_cast<int>(i % static_cast<std::size_t>(w)); }
inline int row_of(std::size_t i, int w) noexcept { return static_cast<int>(i / static_cast<std::size_t>(w)); }

// |a| * b + acc without overflow; false when it would not fit a ptrdiff_t.
inline bool add_extent(std::ptrdiff_t& acc, std::ptrdiff_t count, std::ptrdiff_t stride) noexcept {
    if (count <= 1) return true;
    const std::ptrdiff_t max = (std::numeric_limits<std::ptrdiff_t>::max)();
    if (stride == (std::numeric_limits<std::ptrdiff_t>::min)()) return false;  // before negating
    const std::ptrdiff_t s = stride < 0 ? -stride : stride;
    if (s != 0 && (count - 1) > (max - acc) / s) return false;
    acc += (count - 1) * s;
    return true;
}

struct axis {
    std::ptrdiff_t extent;
    std::ptrdiff_t stride;  // absolute, bytes
};

// Sufficient condition for no two elements to share memory: sorted by stride, each axis
// steps past everything the smaller axes span (gaps allowed, interleaving of axes not).
inline bool axes_disjoint(axis a, axis b, axis c, std::ptrdiff_t elem) noexcept {
    axis v[3] = {a, b, c};
    for (int i = 0; i < 3; ++i)
        for (int j = i + 1; j < 3; ++j)
            if (v[j].stride < v[i].stride) {
                axis t = v[i];
                v[i] = v[j];
                v[j] = t;
            }
    std::ptrdiff_t span = elem;  // bytes covered by the axes processed so far
    for (const axis& x : v) {
        if (x.extent <= 1) continue;
        if (x.stride < span) return false;
        span = x.stride * (x.extent - 1) + span;
    }
    return true;
}

template <class T>
using byte_pointer_t = std::conditional_t<std::is_const_v<T>, const unsigned char*, unsigned char*>;

}  // namespace detail

// ---------------------------------------------------------------------------------------
template <class T>
class image_view {
    static_assert(is_channel_type_v<T>,
                  "image_view<T>: T must be float, double or a type with channel_traits<T>");

public:
    using element_type = T;
    using value_type = std::remove_cv_t<T>;
    using traits = channel_traits<value_type>;

    // An empty view (0 x 0). empty() is true.
    constexpr image_view() noexcept = default;

    // Checked construction. Strides in bytes; auto_stride means packed interleaved:
    // channel_stride = sizeof(T), pixel_stride = channels * channel_stride,
    // row_stride = width * pixel_stride. Refuses layouts that overlap, overflow, are
    // misaligned for T, or have pixels but no pointer.
    static result<image_view> create(T* data, int width, int height, int channels = 1,
                                     std::ptrdiff_t pixel_stride = auto_stride,
                                     std::ptrdiff_t row_stride = auto_stride,
                                     std::ptrdiff_t channel_stride = auto_stride) noexcept {
        if (width < 0 || height < 0 || channels < 0)
            return status{errc::invalid_argument, "negative image size"};
        if (channels == 0 && width > 0 && height > 0)
            return status{errc::empty_image, "an image with pixels needs at least one channel"};
        // A stride of PTRDIFF_MIN has no absolute value: refuse it before anything negates it.
        constexpr std::ptrdiff_t lowest = (std::numeric_limits<std::ptrdiff_t>::min)();
        if (pixel_stride == lowest || row_stride == lowest || channel_stride == lowest)
            return status{errc::size_overflow, "a stride of PTRDIFF_MIN cannot be used"};
        const std::ptrdiff_t elem = static_cast<std::ptrdiff_t>(sizeof(T));
        if (channel_stride == auto_stride) channel_stride = elem;
        if (pixel_stride == auto_stride) {
            std::ptrdiff_t acc = elem;
            if (!detail::add_extent(acc, channels, channel_stride))
                return status{errc::size_overflow, "channels x channel stride overflows"};
            pixel_stride = (channel_stride < 0 ? -channel_stride : channel_stride) == elem
                               ? elem * channels
                               : acc;
        }
        if (row_stride == auto_stride) {
            const std::ptrdiff_t ps = pixel_stride < 0 ? -pixel_stride : pixel_stride;
            if (width > 0 && ps > (std::numeric_limits<std::ptrdiff_t>::max)() / width)
                return status{errc::size_overflow, "width x pixel stride overflows"};
            row_stride = ps * width;
        }
        const image_view v = unchecked(data, width, height, channels, pixel_stride, row_stride, channel_stride);
        if (width == 0 || height == 0) return v;  // an empty image: the pointer may be null
        if (data == nullptr) return status{errc::null_data, "image has pixels but data is null"};
        const auto a = static_cast<std::ptrdiff_t>(alignof(T));
        if (channel_stride % a != 0 || pixel_stride % a != 0 || row_stride % a != 0)
            return status{errc::bad_stride, "strides are not multiples of the element alignment"};
        std::ptrdiff_t span = elem;
        if (!detail::add_extent(span, width, pixel_stride) ||
            !detail::add_extent(span, height, row_stride) ||
            !detail::add_extent(span, channels, channel_stride))
            return status{errc::size_overflow, "image extent overflows"};
        auto absd = [](std::ptrdiff_t s) { return s < 0 ? -s : s; };
        if (!detail::axes_disjoint({width, absd(pixel_stride)}, {height, absd(row_stride)},
                                   {channels, absd(channel_stride)}, elem))
            return status{errc::bad_stride, "strides make pixels or channels overlap"};
        return v;
    }

    // A view over the same pixels that can only read them.
    constexpr operator image_view<const T>() const noexcept {  // NOLINT: implicit on purpose
        return image_view<const T>::unchecked(data_, width_, height_, channels_, pixel_stride_,
                                              row_stride_, channel_stride_);
    }

    // No checks; for code that derives a view from one already checked.
    static constexpr image_view unchecked(T* data, int width, int height, int channels,
                                          std::ptrdiff_t pixel_stride, std::ptrdiff_t row_stride,
                                          std::ptrdiff_t channel_stride) noexcept {
        image_view v;
        v.data_ = data;
        v.width_ = width;
        v.height_ = height;
        v.channels_ = channels;
        v.pixel_stride_ = pixel_stride;
        v.row_stride_ = row_stride;
        v.channel_stride_ = channel_stride;
        return v;
    }

    constexpr int width() const noexcept { return width_; }
    constexpr int height() const noexcept { return height_; }
    constexpr int channels() const noexcept { return channels_; }
    constexpr std::ptrdiff_t channel_stride() const noexcept { return channel_stride_; }
    constexpr std::ptrdiff_t pixel_stride() const noexcept { return pixel_stride_; }
    constexpr std::ptrdiff_t row_stride() const noexcept { return row_stride_; }
    constexpr T* data() const noexcept { return data_; }
    constexpr bool empty() const noexcept { return width_ == 0 || height_ == 0 || channels_ == 0; }
    constexpr std::size_t pixel_count() const noexcept {
        return static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_);
    }

    // Element (x, y, c). Unchecked, like operator[] of a span.
    T& operator()(int x, int y, int c = 0) const noexcept {
        return *reinterpret_cast<T*>(bytes() + y * row_stride_ + x * pixel_stride_ +
                                     c * channel_stride_);
    }
    // Channel c of pixel (x, y) as double, and the reverse.
    double load(int x, int y, int c = 0) const noexcept { return traits::load((*this)(x, y, c)); }
    template <class U = T, class = std::enable_if_t<!std::is_const_v<U>>>
    void store(int x, int y, int c, double v) const noexcept {
        (*this)(x, y, c) = traits::store(v);
    }
    // Pointer to channel 0 of row y's first pixel.
    T* row(int y) const noexcept { return reinterpret_cast<T*>(bytes() + y * row_stride_); }

    // Packed interleaved: channels adjacent, pixels adjacent, rows adjacent, top-down.
    // The fast paths take this and index data()[i * channels + c].
    constexpr bool is_packed() const noexcept {
        const auto e = static_cast<std::ptrdiff_t>(sizeof(T));
        return channel_stride_ == e && pixel_stride_ == e * channels_ &&
               row_stride_ == pixel_stride_ * width_;
    }

    // The rectangle [x, x + w) x [y, y + h); refused when it leaves the image.
    result<image_view> subview(int x, int y, int w, int h) const noexcept {
        if (x < 0 || y < 0 || w < 0 || h < 0 || x > width_ - w || y > height_ - h)
            return status{errc::invalid_argument, "subview outside the image"};
        T* p = (w == 0 || h == 0) ? data_ : &(*this)(x, y, 0);
        return unchecked(p, w, h, channels_, pixel_stride_, row_stride_, channel_stride_);
    }
    // Channels [first, first + count) of every pixel.
    result<image_view> channel_range(int first, int count) const noexcept {
        if (first < 0 || count <= 0 || first > channels_ - count)
            return status{errc::channel_mismatch, "channel range outside the image"};
        T* p = empty() ? data_ : &(*this)(0, 0, first);
        return unchecked(p, width_, height_, count, pixel_stride_, row_stride_, channel_stride_);
    }
    // The same pixels seen bottom-up (row 0 becomes row height-1).
    image_view flipped_vertically() const noexcept {
        T* p = empty() ? data_ : row(height_ - 1);
        return unchecked(p, width_, height_, channels_, pixel_stride_, -row_stride_,
                         channel_stride_);
    }

private:
    detail::byte_pointer_t<T> bytes() const noexcept {
        return reinterpret_cast<detail::byte_pointer_t<T>>(data_);
    }

    T* data_ = nullptr;
    int width_ = 0;
    int height_ = 0;
    int channels_ = 0;
    std::ptrdiff_t pixel_stride_ = 0;
    std::ptrdiff_t row_stride_ = 0;
    std::ptrdiff_t channel_stride_ = 0;
};

// Packed interleaved view (RGB, RGBA, ...).
template <class T>
result<image_view<T>> make_image_view(T* data, int width, int height, int channels = 1,
                                      std::ptrdiff_t row_stride = auto_stride) noexcept {
    return image_view<T>::create(data, width, height, channels, auto_stride, row_stride);
}

// Planar view: channel c is a whole width x height plane; planes and rows may be padded.
template <class T>
result<image_view<T>> make_planar_view(T* data, int width, int height, int channels,
                                       std::ptrdiff_t row_stride = auto_stride,
                                       std::ptrdiff_t plane_stride = auto_stride) noexcept {
    const auto e = static_cast<std::ptrdiff_t>(sizeof(T));
    if (width < 0 || height < 0) return status{errc::invalid_argument, "negative image size"};
    if (row_stride == auto_stride) row_stride = e * width;
    if (plane_stride == auto_stride) {
        const std::ptrdiff_t rs = row_stride < 0 ? -row_stride : row_stride;
        if (height > 0 && rs > (std::numeric_limits<std::ptrdiff_t>::max)() / height)
            return status{errc::size_overflow, "height x row stride overflows"};
        plane_stride = rs * height;
    }
    return image_view<T>::create(data, width, height, channels, e, row_stride, plane_stride);
}

// View over an array of pixel structs (see pixel_traits; firefly/glm.hpp specialises it).
template <class P, class Traits = pixel_traits<std::remove_cv_t<P>>>
auto make_pixel_view(P* pixels, int width, int height, std::ptrdiff_t row_stride = auto_stride) noexcept
    -> result<image_view<std::conditional_t<std::is_const_v<P>, const typename Traits::channel_type,
                                            typename Traits::channel_type>>> {
    using C = std::conditional_t<std::is_const_v<P>, const typename Traits::channel_type,
                                 typename Traits::channel_type>;
    static_assert(sizeof(P) >= Traits::channels * sizeof(C), "pixel smaller than its channels");
    return image_view<C>::create(reinterpret_cast<C*>(pixels), width, height, Traits::channels,
                                 static_cast<std::ptrdiff_t>(sizeof(P)), row_stride,
                                 static_cast<std::ptrdiff_t>(sizeof(C)));
}

// The bytes a view can touch: [first, last) as addresses. Empty views touch nothing.
struct byte_extent {
    std::uintptr_t first = 0, last = 0;
    bool empty() const noexcept { return first == last; }
};

template <class T>
byte_extent extent_of(const image_view<T>& v) noexcept {
    if (v.empty()) return {};
    const auto base = reinterpret_cast<std::uintptr_t>(v.data());
    std::ptrdiff_t lo = 0, hi = 0;  // offsets of the lowest and highest element
    auto span = [&](int count, std::ptrdiff_t stride) {
        const std::ptrdiff_t reach = static_cast<std::ptrdiff_t>(count - 1) * stride;
        (reach < 0 ? lo : hi) += reach;
    };
    span(v.width(), v.pixel_stride());
    span(v.height(), v.row_stride());
    span(v.channels(), v.channel_stride());
    return {base + static_cast<std::uintptr_t>(lo), base + static_cast<std::uintptr_t>(hi) + sizeof(T)};
}

namespace detail {
inline std::uintptr_t stride_gcd(std::uintptr_t g, std::ptrdiff_t stride) noexcept {
    std::uintptr_t v = stride < 0 ? std::uintptr_t{0} - static_cast<std::uintptr_t>(stride) : static_cast<std::uintptr_t>(stride);
    while (v != 0) {
        const std::uintptr_t t = g % v;
        g = v;
        v = t;
    }
    return g;
}

// Whether the elements of a and b lie on disjoint residues of one lattice: every element
// starts at its view's origin plus a sum of strides, so modulo g, the gcd of all six strides,
// a's elements start at pa and b's at pb (a stride taken by no step, as that of a single
// channel, does not count); they share no byte when the gap r = (pb - pa) mod g
// leaves room for both element sizes (r >= sizeof A, g - r >= sizeof B). K buffers stacked
// innermost ((H, W, C, K) memory, each buffer a view with channel stride K elements), or
// colour and variance interleaved channel by channel, are disjoint so.
template <class A, class B>
bool lattice_disjoint(const image_view<A>& a, const image_view<B>& b) noexcept {
    std::uintptr_t g = 0;
    auto add = [&g](const auto& v) {  // a stride only counts where it is taken
        if (v.width() > 1) g = stride_gcd(g, v.pixel_stride());
        if (v.height() > 1) g = stride_gcd(g, v.row_stride());
        if (v.channels() > 1) g = stride_gcd(g, v.channel_stride());
    };
    add(a);
    add(b);
    if (g == 0) return false;
    const std::uintptr_t pa = reinterpret_cast<std::uintptr_t>(a.data()) % g;
    const std::uintptr_t pb = reinterpret_cast<std::uintptr_t>(b.data()) % g;
    const std::uintptr_t r = (pb + g - pa) % g;
    return r >= sizeof(A) && g - r >= sizeof(B);
}
}  // namespace detail

// Whether two views may share a byte. Exact for views whose extents are apart, for two
// interleaved views with the same pixel and row strides (colour and variance as channels
// [0, 3) and [3, 6) of one 6-channel image, the layout OpenImageIO gives for an EXR holding
// both), and for views on disjoint residues of their strides' lattice (detail::
// lattice_disjoint: buffers interleaved element by element); any other interleaving of
// extents is taken as an overlap.
template <class A, class B>
bool views_may_overlap(const image_view<A>& a, const image_view<B>& b) noexcept {
    const byte_extent ea = extent_of(a), eb = extent_of(b);
    if (ea.empty() || eb.empty() || ea.last <= eb.first || eb.last <= ea.first) return false;
    if (detail::lattice_disjoint(a, b)) return false;
    const std::ptrdiff_t ps = a.pixel_stride();
    if (ps <= 0 || ps != b.pixel_stride() || a.row_stride() != b.row_stride() || a.row_stride() % ps != 0)
        return true;
    // Each view's pixel footprint [0, f) must lie within one pixel slot of ps bytes.
    auto footprint = [](auto& v) -> std::ptrdiff_t {
        using E = std::remove_reference_t<decltype(*v.data())>;
        if (v.channel_stride() <= 0) return -1;
        return static_cast<std::ptrdiff_t>(v.channels() - 1) * v.channel_stride() +
               static_cast<std::ptrdiff_t>(sizeof(E));
    };
    const std::ptrdiff_t fa = footprint(a), fb = footprint(b);
    if (fa < 0 || fb < 0 || fa > ps || fb > ps) return true;
    // Both sit on one lattice of period ps: compare the footprints modulo ps.
    const std::uintptr_t pa = reinterpret_cast<std::uintptr_t>(a.data());
    const std::uintptr_t pb = reinterpret_cast<std::uintptr_t>(b.data());
    const auto ups = static_cast<std::uintptr_t>(ps);
    const auto d = static_cast<std::ptrdiff_t>(((pb % ups) + ups - (pa % ups)) % ups);  // b's start in a's slot
    // a covers [0, fa); b covers [d, d + fb) and, wrapped, [d - ps, d + fb - ps).
    return d < fa || d + fb > ps;
}

// Same width and height.
template <class A, class B>
constexpr bool same_size(const image_view<A>& a, const image_view<B>& b) noexcept {
    return a.width() == b.width() && a.height() == b.height();
}

namespace detail {
// The detectors' longest side: the energy return's half-pixel positions (2 x + 1) stay in int.
inline constexpr int max_side = 1 << 30;

// A frame both detectors can index: fewer than 2^32 pixels (32-bit pixel lists) and no side
// past max_side.
template <class T>
status check_frame_extent(const image_view<T>& v) noexcept {
    if (v.pixel_count() >= (std::size_t{1} << 32)) return status{errc::size_overflow, "more than 2^32 pixels"};
    if (v.width() > max_side || v.height() > max_side) return status{errc::size_overflow, "a side longer than 2^30 pixels"};
    return ok_status();
}
}  // namespace detail

}  // namespace firefly
