// firefly: errors as values. Nothing in the library throws or aborts on user data,
// so every fallible call returns a [[nodiscard]] status (or a result<T> carrying one).
#pragma once

#include <utility>

#include "floating_point.hpp"

namespace firefly {

enum class errc : int {
    ok = 0,
    null_data,            // a view with pixels but no pointer
    empty_image,          // width or height (or channel count) is zero where pixels are needed
    bad_stride,           // strides that cannot describe an image (overlap, too small)
    size_overflow,        // width x stride (or similar) does not fit in a ptrdiff_t
    size_mismatch,        // two views that must have the same width/height do not
    channel_mismatch,     // a view has a channel count the call cannot use
    invalid_argument,     // an option out of its documented range
    no_valid_pixels,      // nothing to reconstruct from: every pixel is an outlier or ignored
    aliased_views,        // two views share memory that one of them writes
};

// A readable name for an error code; never null.
constexpr const char* to_string(errc e) noexcept {
    switch (e) {
        case errc::ok: return "ok";
        case errc::null_data: return "null data pointer";
        case errc::empty_image: return "empty image";
        case errc::bad_stride: return "strides cannot describe an image";
        case errc::size_overflow: return "image size overflows";
        case errc::size_mismatch: return "image sizes do not match";
        case errc::channel_mismatch: return "wrong channel count";
        case errc::invalid_argument: return "invalid argument";
        case errc::no_valid_pixels: return "no valid pixel to reconstruct from";
        case errc::aliased_views: return "views share memory";
    }
    return "unknown error";
}

// An error code and a message with static storage duration (a literal), so the status
// is trivially copyable and never allocates. Test it with ok(): a status has no conversion
// to bool, because "if (error)" meaning "if fine" reads backwards.
class [[nodiscard]] status {
public:
    constexpr status() noexcept = default;
    constexpr status(errc code, const char* message) noexcept
        : code_(code), message_(message ? message : to_string(code)) {}

    constexpr bool ok() const noexcept { return code_ == errc::ok; }
    constexpr errc code() const noexcept { return code_; }
    constexpr const char* message() const noexcept { return message_; }

private:
    errc code_ = errc::ok;
    const char* message_ = "ok";
};

constexpr status ok_status() noexcept { return status{}; }

// A value or an error. The value is default-constructed when there is an error.
template <class T>
class [[nodiscard]] result {
public:
    result(T value) : value_(std::move(value)) {}  // NOLINT: implicit on purpose
    result(status error) : status_(error) {}        // NOLINT
    bool ok() const noexcept { return status_.ok(); }
    explicit operator bool() const noexcept { return ok(); }
    const status& error() const noexcept { return status_; }
    const T& value() const& noexcept { return value_; }
    T& value() & noexcept { return value_; }
    T&& value() && noexcept { return std::move(value_); }
    const T* operator->() const noexcept { return &value_; }
    T* operator->() noexcept { return &value_; }
    const T& operator*() const& noexcept { return value_; }
    T& operator*() & noexcept { return value_; }

private:
    T value_{};
    status status_{};
};

}  // namespace firefly
