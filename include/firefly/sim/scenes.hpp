// firefly/sim: named scenes. Each turns on only the effects it is about; each says what it
// models.
#pragma once

#include <cctype>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "types.hpp"

namespace firefly::sim {

// Calibration: a frame with every effect on except fireflies, caustics and non-finite values
// (gradients over three decades, black background, alpha, fine detail, highlight spots and a
// wide highlight), ordinary samples gamma-distributed with the given shape (relative sd
// 1/sqrt(shape), highlights too), `spp` samples per half. A detector run on it should find
// nothing beyond what its significance promises.
inline scene null_scene(std::uint64_t seed, double shape, int spp, int width = 256, int height = 256) {
    scene s;
    char name[64];
    std::snprintf(name, sizeof name, "null_k%g_spp%d", shape, spp);
    s.name = name;
    s.width = width;
    s.height = height;
    s.seed = seed;
    s.spp = spp;
    s.effects = log_gradient | black_background | alpha_coverage | fine_detail | highlights | wide_highlight;
    s.samples = distribution::gamma;
    s.noise = shape > 0 ? 1.0 / std::sqrt(shape) : 1.0;
    s.highlight_noise = s.noise;
    return s;
}

namespace detail {
// The scenes for dense, interior and wide-range frames, beyond the first eight.
inline bool named_accuracy_scene(const std::string& name, scene& s) {
    if (name == "dense10" || name == "dense30") {  // 10% / 30% of pixels hit per half
        s.effects = gradient | varying_noise | fireflies;
        s.firefly_pixel_rate = name == "dense10" ? 0.10 : 0.30;
    } else if (name == "caustics") {
        // Real-render density (~3% of pixels per half hold a firefly): 1.5% spread over the
        // frame, as much again packed into a few bright caustic blobs and streaks, each firefly
        // raising its pixel 2-100x (as in ../shared/data/cycles-caustics, 32 spp per half).
        s.effects = gradient | caustics | fireflies | highlights;
        s.base = 0.25;  // ~90% of the pixels below 0.5, as in the render
        s.spp = 32;
        s.firefly_pixel_rate = 0.015;
        s.firefly_relative = true;
        s.firefly_energy = 2.0;
        s.firefly_energy_max = 100.0;
        s.caustic_count = 8;
        s.caustic_pixel_rate = 0.6;
        s.highlight_count = 30;
    } else if (name == "failed_bucket") {
        // A render bucket that failed in half A: a NaN square 1/8 of the width, half B intact.
        s.effects = gradient | fireflies | failed_bucket;
    } else if (name == "garbage_bucket") {
        // The bucket failed with finite garbage: 1e30 colour in half A, its variance sane.
        s.effects = gradient | fireflies | garbage_bucket;
    } else if (name == "dropped_bucket") {
        // The same bucket written black instead: colour and variance 0 in half A, half B intact.
        s.effects = gradient | fireflies | dropped_bucket;
    } else if (name == "interior") {
        // A room lit by bounce light (../shared/data/cycles-interior): dark (most pixels below
        // 0.5), every pixel noisy with heavy-tailed (lognormal) samples, dense moderate
        // fireflies raising a pixel 2-20x, and a bright, noisy ceiling patch that both halves
        // agree on (a highlight region).
        s.effects = gradient | fireflies | bright_region;
        s.base = 0.12;
        s.samples = distribution::lognormal;
        s.noise = 2.5;  // the render's median relative sd of the mean is ~0.3 at 64 spp
        s.firefly_pixel_rate = 0.03;
        s.firefly_relative = true;
        s.firefly_energy = 2.0;
        s.firefly_energy_max = 20.0;
        s.region_radiance = 25.0;
        s.region_noise = 2.5;
    } else if (name == "decades") {
        // Brightness over three decades (0.01 .. 10, a log ramp: a lamp and the shadow under a
        // table), light-tailed samples, 0.05% of pixels hit by fireflies raising them 30-1000x.
        s.effects = log_gradient | fireflies;
        s.noise = 0.5;
        s.firefly_pixel_rate = 0.0005;
        s.firefly_relative = true;
        s.firefly_energy = 30.0;
        s.firefly_energy_max = 1000.0;
    } else if (name == "fog") {
        // A fog-filled room crossed by a spot beam: every pixel noisy (exponential samples), 91%
        // dark, a bright noisy beam across the frame, and no fireflies at all.
        s.effects = gradient | bright_region;
        s.base = 0.1;
        s.samples = distribution::gamma;
        s.noise = 1.0;
        s.region_x0 = 0.15;
        s.region_y0 = 0.0;
        s.region_x1 = 0.6;
        s.region_y1 = 1.0;
        s.region_radius = 0.042;
        s.region_radiance = 15.0;
        s.region_noise = 1.0;
    } else {
        return false;
    }
    return true;
}

// "null_k<shape>_spp<n>" with shape > 0 and n from 2 to INT_MAX (strtol: sscanf's %d past
// int is undefined, and glibc read spp4294967298 as 2).
inline bool parse_null_name(const std::string& name, double& shape, int& spp) {
    if (name.compare(0, 6, "null_k") != 0) return false;
    const char* s = name.c_str() + 6;
    char* end = nullptr;
    shape = std::strtod(s, &end);
    if (end == s || std::strncmp(end, "_spp", 4) != 0 || !(shape > 0)) return false;
    const char* n = end + 4;
    if (!std::isdigit(static_cast<unsigned char>(*n))) return false;  // (no sign, no space)
    errno = 0;
    const long long v = std::strtoll(n, &end, 10);
    if (errno == ERANGE || *end != '\0' || v < 2 || v > INT_MAX) return false;
    spp = static_cast<int>(v);
    return true;
}
}  // namespace detail

// Named scenes; an unknown name gives the flat scene (no effect). "null_k<shape>_spp<n>" is
// null_scene(seed, shape, n).
inline scene named_scene(const std::string& name, int width = 256, int height = 256, std::uint64_t seed = 1) {
    double shape = 0;
    int spp = 0;
    if (detail::parse_null_name(name, shape, spp)) return null_scene(seed, shape, spp, width, height);
    scene s;
    s.name = name;
    s.width = width;
    s.height = height;
    s.seed = seed;
    if (name == "sparse_fireflies") {
        s.effects = gradient | fireflies;
        s.firefly_pixel_rate = 0.002;
    } else if (name == "dense_fireflies") {
        s.effects = gradient | varying_noise | fireflies;
        s.firefly_pixel_rate = 0.02;
    } else if (name == "highlights") {
        s.effects = gradient | highlights | fireflies;
        s.firefly_pixel_rate = 0.005;
    } else if (name == "wide_highlight") {
        s.effects = wide_highlight | fireflies;
        s.firefly_pixel_rate = 0.005;
    } else if (name == "fine_detail") {
        s.effects = fine_detail | fireflies;
        s.firefly_pixel_rate = 0.005;
    } else if (name == "black_alpha") {
        s.effects = black_background | alpha_coverage | gradient | fireflies;
        s.firefly_pixel_rate = 0.005;
    } else if (name == "nonfinite") {
        s.effects = gradient | nonfinite | negative | fireflies;
        s.firefly_pixel_rate = 0.003;
    } else if (name == "production") {
        s.effects = gradient | fine_detail | varying_noise | fireflies | highlights | wide_highlight |
                    black_background | alpha_coverage | nonfinite | negative;
        s.firefly_pixel_rate = 0.006;
    } else if (!detail::named_accuracy_scene(name, s)) {
        s.name = "flat";
        s.effects = 0;
    }
    return s;
}

// Every named scene: the first eight, the accuracy scenes, and three calibration scenes (no
// fireflies: shape 1 at 4 spp, shape 4 at 64 spp, shape 16 at 1024 spp).
inline const std::vector<std::string>& scene_names() {
    static const std::vector<std::string> names = {
        "sparse_fireflies", "dense_fireflies", "highlights", "wide_highlight", "fine_detail",
        "black_alpha",      "nonfinite",       "production", "dense10",        "dense30",
        "caustics",         "failed_bucket",   "interior",   "decades",        "fog",
        "null_k1_spp4",     "null_k4_spp64",   "null_k16_spp1024"};
    return names;
}

// The first eight named scenes (the ones the detector's original targets were set on).
inline const std::vector<std::string>& classic_scene_names() {
    static const std::vector<std::string> names(scene_names().begin(), scene_names().begin() + 8);
    return names;
}

}  // namespace firefly::sim
