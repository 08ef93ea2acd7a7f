// What the local test adds to the global generalized ESD: recall, false positives and relMSE
// on simulated scenes (with ground truth) and on the shared real renders, with one stand-in
// reconstruction for every detector so the detectors are compared, not the rebuilds:
//   a pixel flagged in one half takes the other half's value; a pixel flagged in both halves
//   takes the mean of (A + B) / 2 over its unflagged 3x3 neighbours (unchanged if none).
// Rows: the global stage alone (detector::detect's firefly mask); then, at false-alarm
// levels q = 1e-4 (the default), 1e-3, 1e-2, 0.05: the local stage alone, the union of both,
// and "confirm" (a one-half global outlier is rebuilt only when the local test also flags it;
// both-half outliers the highlight check does not keep are rebuilt as before). "worse" is the
// share of changed pixels whose error against the reference grew; recall and FP (share of
// clean pixel-halves flagged) where the simulator gives the truth.
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
    std::printf("%-16s %-14s relMSE %8.4f  changed %6.4f  worse %5.3f  flagged %7.5f", scene, what, r.relmse,
                r.changed, r.worse, r.flagged);
    if (r.recall >= 0) std::printf("  recall %5.3f  FP %8.6f", r.recall, r.fp);
    std::printf("  %.2f ms\n", ms);
}

using flags = std::vector<std::uint8_t>;

// The global stage's firefly mask per half, and its time (best of 5, scratch warm).
double global_flags(const frame_data& d, flags (&out)[2]) {
    const std::size_t n = static_cast<std::size_t>(d.w) * d.h;
    firefly::half_buffer<const float> hb[2];
    flags mask[2];
    for (int i = 0; i < 2; ++i) {
        hb[i].color = *firefly::make_image_view(d.color[i].data(), d.w, d.h, 3);
        hb[i].variance = *firefly::make_image_view(d.variance[i].data(), d.w, d.h, 3);
        if (!d.alpha.empty()) hb[i].alpha = *firefly::make_image_view(d.alpha.data(), d.w, d.h, 1);
        mask[i].assign(n, 0);
    }
    firefly::detector det;
    const auto m0 = *firefly::make_image_view(mask[0].data(), d.w, d.h, 1);
    const auto m1 = *firefly::make_image_view(mask[1].data(), d.w, d.h, 1);
    double ms = 1e30;
    for (int k = 0; k < 5; ++k) {
        const auto t0 = std::chrono::steady_clock::now();
        const firefly::frame_report rep = det.detect(hb[0], hb[1], m0, m1);
        ms = std::min(ms, std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
        if (!rep.error.ok()) std::printf("detector: %s\n", rep.error.message());
    }
    for (int i = 0; i < 2; ++i) {
        out[i].assign(n, 0);
        for (std::size_t j = 0; j < n; ++j) out[i][j] = (mask[i][j] & firefly::mask_bits::firefly) != 0;
    }
    return ms;
}

// The local test's flags per half at false-alarm level q, and its time (best of 5).
double local_flags(const frame_data& d, double q, flags (&out)[2]) {
    const std::size_t n = static_cast<std::size_t>(d.w) * d.h;
    firefly::local_half<float> lh[2];
    for (int i = 0; i < 2; ++i) {
        lh[i].color = *firefly::make_image_view(d.color[i].data(), d.w, d.h, 3);
        lh[i].variance = *firefly::make_image_view(d.variance[i].data(), d.w, d.h, 3);
        if (!d.alpha.empty()) lh[i].alpha = *firefly::make_image_view(d.alpha.data(), d.w, d.h, 1);
    }
    firefly::local_test_options o;
    o.false_alarm = q;
    firefly::local_test_scratch scratch;
    firefly::local_test_result r;
    double ms = 1e30;
    for (int k = 0; k < 5; ++k) {
        const auto t0 = std::chrono::steady_clock::now();
        const firefly::status st = firefly::local_test(lh[0], lh[1], o, scratch, r);
        ms = std::min(ms, std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
        if (!st.ok()) std::printf("local: %s\n", st.message());
    }
    for (int i = 0; i < 2; ++i) {
        out[i].assign(n, 0);
        for (const std::uint32_t j : r.half[i].index) out[i][j] = 1;
    }
    return ms;
}

void run(const char* name, const frame_data& d, bool sweep) {
    const std::size_t n = static_cast<std::size_t>(d.w) * d.h;
    flags global[2], none[2] = {flags(n, 0), flags(n, 0)};
    const double global_ms = global_flags(d, global);
    print(name, "input", evaluate(d, none), 0);
    print(name, "global", evaluate(d, global), global_ms);
    for (const double q : {1e-4, 1e-3, 1e-2, 5e-2}) {
        if (!sweep && q != 1e-4) break;
        flags local[2], uni[2], confirm[2];
        const double local_ms = local_flags(d, q, local);
        for (int i = 0; i < 2; ++i) {
            uni[i] = confirm[i] = local[i];
            for (std::size_t j = 0; j < n; ++j) {
                const bool both = global[0][j] && global[1][j];
                uni[i][j] = global[i][j] || local[i][j];
                confirm[i][j] = both || (global[i][j] && local[i][j]);
            }
        }
        char label[3][32];
        std::snprintf(label[0], 32, "local %g", q);
        std::snprintf(label[1], 32, "union %g", q);
        std::snprintf(label[2], 32, "confirm %g", q);
        print(name, label[0], evaluate(d, local), local_ms);
        print(name, label[1], evaluate(d, uni), global_ms + local_ms);
        print(name, label[2], evaluate(d, confirm), global_ms + local_ms);
    }
}

}  // namespace

int main(int argc, char** argv) {
    const std::string data = argc > 1 ? argv[1] : "../shared/data";  // from the repository root
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
        run(name, d, true);
    }
    for (const char* name : {"decades", "interior", "fog", "sparse_fireflies", "dense_fireflies", "highlights",
                             "fine_detail", "black_alpha", "production", "null_k1_spp4", "null_k1_spp16",
                             "null_k4_spp64", "null_k16_spp1024"})
        run(name, from_sim(firefly::sim::simulate(firefly::sim::named_scene(name, 256, 256, 1))), true);
}
