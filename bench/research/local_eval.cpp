// What the local test adds to the global generalized ESD: recall, false positives and relMSE
// on simulated scenes (with ground truth) and on the shared real renders, with one stand-in
// reconstruction for every detector so the detectors are compared, not the rebuilds:
//   a pixel flagged in one half takes the other half's value; a pixel flagged in both halves
//   takes the mean of (A + B) / 2 over its unflagged 3x3 neighbours (unchanged if none).
// Rows: the global stage alone (detector::detect's firefly mask), the local stage alone, and
// their union; "worse" is the share of changed pixels whose error against the reference grew.
//
// Build: g++ -std=c++17 -O2 -Iinclude bench/research/local_eval.cpp -o local_eval
// Run:   ./local_eval [path to ../shared/data]
#include <firefly/firefly.hpp>
#include <firefly/local_test.hpp>
#include <firefly/sim/scene.hpp>
#include <firefly/sim/scenes.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

namespace {

struct frame_data {
    int w = 0, h = 0;
    std::vector<float> color[2], variance[2], alpha, reference;  // reference: RGB
    std::vector<std::uint8_t> truth[2];                          // empty: unknown
};

bool read_pfm(const std::string& path, int& w, int& h, std::vector<float>& rgb) {
    std::FILE* f = std::fopen(path.c_str(), "rb");
    if (!f) return false;
    char magic[3] = {};
    double scale = 0;
    const bool ok = std::fscanf(f, "%2s %d %d %lf", magic, &w, &h, &scale) == 4 && std::fgetc(f) != EOF &&
                    std::strcmp(magic, "PF") == 0 && scale < 0;
    std::vector<float> raw(static_cast<std::size_t>(w) * h * 3);
    const bool got = ok && std::fread(raw.data(), 4, raw.size(), f) == raw.size();
    std::fclose(f);
    if (!got) return false;
    rgb.resize(raw.size());
    for (int y = 0; y < h; ++y)  // bottom-up rows
        std::memcpy(&rgb[static_cast<std::size_t>(y) * w * 3], &raw[static_cast<std::size_t>(h - 1 - y) * w * 3],
                    sizeof(float) * 3 * w);
    return true;
}

frame_data from_sim(const firefly::sim::frame& f) {
    frame_data d;
    d.w = f.width;
    d.h = f.height;
    for (int i = 0; i < 2; ++i) {
        d.color[i] = f.color[i];
        d.variance[i] = f.variance[i];
        d.truth[i].assign(f.pixels(), 0);
        for (std::size_t j = 0; j < f.pixels(); ++j) d.truth[i][j] = f.firefly(i, j) > 0;
    }
    d.alpha = f.alpha;
    d.reference = f.expected;
    return d;
}

double pixel_error(const float* px, const float* ref) {
    double e = 0;
    for (int c = 0; c < 3; ++c) {
        const double diff = static_cast<double>(px[c]) - ref[c];
        e += diff * diff / (static_cast<double>(ref[c]) * ref[c] + 0.01);
    }
    return e / 3;
}

struct row {
    double relmse = 0, changed = 0, worse = 0, recall = -1, fp = 0, flagged = 0;
};

row evaluate(const frame_data& d, const std::vector<std::uint8_t> (&flag)[2]) {
    const std::size_t n = static_cast<std::size_t>(d.w) * d.h;
    std::vector<float> out(n * 3), in(n * 3);
    for (std::size_t j = 0; j < n * 3; ++j) in[j] = 0.5f * (d.color[0][j] + d.color[1][j]);
    out = in;
    for (int y = 0; y < d.h; ++y)
        for (int x = 0; x < d.w; ++x) {
            const std::size_t i = static_cast<std::size_t>(y) * d.w + x;
            const bool fa = flag[0][i], fb = flag[1][i];
            if (!fa && !fb) continue;
            for (int c = 0; c < 3; ++c) {
                float v;
                if (fa != fb) {
                    v = d.color[fa ? 1 : 0][i * 3 + c];
                } else {
                    double s = 0;
                    int k = 0;
                    for (int dy = -1; dy <= 1; ++dy)
                        for (int dx = -1; dx <= 1; ++dx) {
                            const int xx = x + dx, yy = y + dy;
                            if (xx < 0 || yy < 0 || xx >= d.w || yy >= d.h) continue;
                            const std::size_t j = static_cast<std::size_t>(yy) * d.w + xx;
                            if (flag[0][j] || flag[1][j] || !std::isfinite(in[j * 3 + c])) continue;
                            s += in[j * 3 + c];
                            ++k;
                        }
                    v = k ? static_cast<float>(s / k) : in[i * 3 + c];
                }
                out[i * 3 + c] = v;
            }
        }
    row r;
    std::size_t changed = 0, worse = 0, tp = 0, pos = 0, fp = 0, neg = 0, flagged = 0;
    double err = 0;
    for (std::size_t i = 0; i < n; ++i) {
        const double e_out = pixel_error(&out[i * 3], &d.reference[i * 3]);
        err += std::isfinite(e_out) ? e_out : 0;
        if (std::memcmp(&out[i * 3], &in[i * 3], 12) != 0) {
            ++changed;
            worse += e_out > pixel_error(&in[i * 3], &d.reference[i * 3]);
        }
        for (int h = 0; h < 2; ++h) {
            flagged += flag[h][i];
            if (d.truth[h].empty()) continue;
            const bool clean_px = d.alpha.empty() || d.alpha[i] > 0;
            if (d.truth[h][i]) {
                ++pos;
                tp += flag[h][i];
            } else if (clean_px) {
                ++neg;
                fp += flag[h][i];
            }
        }
    }
    r.relmse = err / n;
    r.changed = static_cast<double>(changed) / n;
    r.worse = changed ? static_cast<double>(worse) / changed : 0;
    r.flagged = static_cast<double>(flagged) / (2.0 * n);
    if (!d.truth[0].empty()) {
        r.recall = pos ? static_cast<double>(tp) / pos : 1;
        r.fp = neg ? static_cast<double>(fp) / neg : 0;
    }
    return r;
}

void print(const char* scene, const char* what, const row& r, double ms) {
    std::printf("%-16s %-8s relMSE %8.4f  changed %6.4f  worse %5.3f  flagged %7.5f", scene, what, r.relmse,
                r.changed, r.worse, r.flagged);
    if (r.recall >= 0) std::printf("  recall %5.3f  FP %8.6f", r.recall, r.fp);
    std::printf("  %.2f ms\n", ms);
}

void run(const char* name, const frame_data& d) {
    using clock = std::chrono::steady_clock;
    const std::size_t n = static_cast<std::size_t>(d.w) * d.h;
    firefly::half_buffer<const float> hb[2];
    std::vector<std::uint8_t> mask[2], global[2], local[2], both[2];
    for (int i = 0; i < 2; ++i) {
        hb[i].color = *firefly::make_image_view(d.color[i].data(), d.w, d.h, 3);
        hb[i].variance = *firefly::make_image_view(d.variance[i].data(), d.w, d.h, 3);
        if (!d.alpha.empty()) hb[i].alpha = *firefly::make_image_view(d.alpha.data(), d.w, d.h, 1);
        mask[i].assign(n, 0);
    }
    firefly::detector det;
    auto m0 = *firefly::make_image_view(mask[0].data(), d.w, d.h, 1);
    auto m1 = *firefly::make_image_view(mask[1].data(), d.w, d.h, 1);
    // Times: the best of 5 runs (scratch memory warm, as in a renderer's frame loop).
    firefly::frame_report rep;
    double global_ms = 1e30, local_ms = 1e30;
    for (int k = 0; k < 5; ++k) {
        const auto t0 = clock::now();
        rep = det.detect(hb[0], hb[1], m0, m1);
        global_ms = std::min(global_ms, std::chrono::duration<double, std::milli>(clock::now() - t0).count());
    }
    if (!rep.error.ok()) std::printf("%s: detector: %s\n", name, rep.error.message());
    firefly::local_half<float> lh[2];
    for (int i = 0; i < 2; ++i) {
        lh[i].color = hb[i].color;
        lh[i].variance = hb[i].variance;
        lh[i].alpha = hb[i].alpha;
    }
    firefly::local_test_scratch scratch;
    firefly::local_test_result lr;
    firefly::status st;
    for (int k = 0; k < 5; ++k) {
        const auto t0 = clock::now();
        st = firefly::local_test(lh[0], lh[1], firefly::local_test_options{}, scratch, lr);
        local_ms = std::min(local_ms, std::chrono::duration<double, std::milli>(clock::now() - t0).count());
    }
    if (!st.ok()) std::printf("%s: local: %s\n", name, st.message());
    for (int i = 0; i < 2; ++i) {
        global[i].assign(n, 0);
        local[i].assign(n, 0);
        for (std::size_t j = 0; j < n; ++j) global[i][j] = (mask[i][j] & firefly::mask_bits::firefly) != 0;
        for (const std::uint32_t j : lr.half[i].index) local[i][j] = 1;
        both[i] = global[i];
        for (std::size_t j = 0; j < n; ++j) both[i][j] |= local[i][j];
    }
    std::vector<std::uint8_t> none[2] = {std::vector<std::uint8_t>(n, 0), std::vector<std::uint8_t>(n, 0)};
    print(name, "input", evaluate(d, none), 0);
    print(name, "global", evaluate(d, global), global_ms);
    print(name, "local", evaluate(d, local), local_ms);
    print(name, "union", evaluate(d, both), global_ms + local_ms);
}

}  // namespace

int main(int argc, char** argv) {
    const std::string data = argc > 1 ? argv[1] : "/work/shared/data";
    for (const char* name : {"cycles-caustics", "cycles-interior"}) {
        frame_data d;
        const std::string dir = data + "/" + name + "/";
        int w, h;
        const bool ok = read_pfm(dir + "a_color.pfm", d.w, d.h, d.color[0]) &&
                        read_pfm(dir + "a_variance.pfm", w, h, d.variance[0]) &&
                        read_pfm(dir + "b_color.pfm", w, h, d.color[1]) &&
                        read_pfm(dir + "b_variance.pfm", w, h, d.variance[1]) &&
                        read_pfm(dir + "reference.pfm", w, h, d.reference);
        if (!ok) {
            std::printf("%s: cannot read\n", name);
            continue;
        }
        run(name, d);
    }
    for (const char* name : {"decades", "interior", "fog", "sparse_fireflies", "dense_fireflies", "highlights",
                             "fine_detail", "black_alpha", "production", "null_k1_spp4", "null_k1_spp16",
                             "null_k4_spp64", "null_k16_spp1024"})
        run(name, from_sim(firefly::sim::simulate(firefly::sim::named_scene(name, 256, 256, 1))));
}
