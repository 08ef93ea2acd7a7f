// firefly: what a move leaves behind in the objects that keep work between frames.
//
// A table built once and reused keeps a key (its width, K, size) next to its storage. Moved
// member-wise, the storage went with the move and the key stayed: the next call saw its key
// and used storage that was gone (a Gaussian kernel with no weights rebuilt nothing, a
// binomial table read rows that were not there, an accumulator indexed empty sums). So a
// key is a reset_on_move, which a move returns to its default (nothing built), and a class
// whose scratch is many members moves it with take_scratch, which leaves the source fresh.
#pragma once

#include <utility>

#include "floating_point.hpp"

namespace firefly {
namespace detail {

// A value that a move takes and resets to T{} in the source; a copy copies it.
template <class T>
class reset_on_move {
public:
    constexpr reset_on_move() noexcept = default;
    constexpr reset_on_move(T v) noexcept : v_(v) {}  // (implicit: written as the T it holds)
    reset_on_move(const reset_on_move&) = default;
    reset_on_move& operator=(const reset_on_move&) = default;
    reset_on_move(reset_on_move&& o) noexcept : v_(std::exchange(o.v_, T{})) {}
    reset_on_move& operator=(reset_on_move&& o) noexcept {
        if (this != &o) v_ = std::exchange(o.v_, T{});
        return *this;
    }
    reset_on_move& operator=(T v) noexcept {
        v_ = v;
        return *this;
    }
    constexpr operator T() const noexcept { return v_; }

private:
    T v_{};
};

// Moves s out and leaves it a default-constructed Scratch (no allocation: empty containers).
template <class Scratch>
Scratch take_scratch(Scratch& s) noexcept {
    Scratch out(std::move(s));
    s = Scratch{};
    return out;
}

}  // namespace detail
}  // namespace firefly
