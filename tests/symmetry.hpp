// Test helper: the 8 flips and transposes of a frame, for the tests that a result does not
// depend on the frame's orientation (scan order, lattices, the order of separable passes).
#pragma once

#include <cstddef>
#include <utility>
#include <vector>

namespace firefly_test {

// Symmetry sym of a w x h frame (bit 0: flip x, bit 1: flip y, bit 2: transpose), as a map
// from a pixel (x, y) of the transformed width() x height() frame to the source's index.
struct symmetry {
    int sym, w, h;
    bool transposed() const { return (sym & 4) != 0; }
    int width() const { return transposed() ? h : w; }
    int height() const { return transposed() ? w : h; }
    std::size_t source(int x, int y) const {
        int u = x, v = y;
        if (transposed()) std::swap(u, v);
        if (sym & 1) u = w - 1 - u;
        if (sym & 2) v = h - 1 - v;
        return static_cast<std::size_t>(v) * static_cast<std::size_t>(w) + static_cast<std::size_t>(u);
    }
    // The transformed copy of an interleaved image of `channels` values a pixel (empty stays
    // empty: a frame without alpha).
    template <class T>
    std::vector<T> apply(const std::vector<T>& in, int channels) const {
        std::vector<T> out(in.size());
        if (in.empty()) return out;
        const std::size_t nc = static_cast<std::size_t>(channels);
        for (int y = 0; y < height(); ++y)
            for (int x = 0; x < width(); ++x)
                for (std::size_t c = 0; c < nc; ++c)
                    out[(static_cast<std::size_t>(y) * static_cast<std::size_t>(width()) + static_cast<std::size_t>(x)) * nc + c] =
                        in[source(x, y) * nc + c];
        return out;
    }
};

}  // namespace firefly_test
