// Test helper: what a move leaves. works(x) says whether x does its job as a new object would;
// check_moves asks it of the source and the target of a move construction from `used`, then
// of a move assignment from that target.
#pragma once

#include <utility>

#include "catch.hpp"

namespace firefly_test {

template <class T, class Works>
void check_moves(T& used, Works&& works) {
    T moved = std::move(used);
    CHECK(works(used));
    CHECK(works(moved));
    T assigned;
    assigned = std::move(moved);
    CHECK(works(moved));
    CHECK(works(assigned));
}

}  // namespace firefly_test
