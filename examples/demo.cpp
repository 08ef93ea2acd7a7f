// firefly demo: simulates a frame with every effect (fireflies, highlights, a wide
// highlight, fine detail, black background with alpha, NaN/Inf, negative samples), cleans
// it with firefly and with the peer filters, prints what each did against the ground
// truth, and writes before/after images.
//
//   firefly_demo [--scene NAME] [--size WxH] [--seed N] [--out DIR]
//   scenes: sparse_fireflies dense_fireflies highlights wide_highlight fine_detail
//           black_alpha nonfinite production (default)
#include <firefly/firefly.hpp>
#include <firefly/sim/metrics.hpp>
#include <firefly/sim/scene.hpp>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <string>
#include <sys/stat.h>
#include <vector>

#include "image_io.hpp"
#include "peers.hpp"

using namespace firefly;

namespace {
struct method {
    const char* name;
    std::function<void(half_buffer<float>&, half_buffer<float>&)> run;
};

struct demo_args {
    std::string scene = "production", out = "firefly-demo";
    int w = 960, h = 540;
    unsigned long long seed = 7;
};

// The command line into args; an exit code when the demo should not run (-1: run).
int parse_args(int argc, char** argv, demo_args& args) {
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        auto next = [&]() -> const char* { return i + 1 < argc ? argv[++i] : ""; };
        if (a == "--scene") args.scene = next();
        else if (a == "--size") {
            if (std::sscanf(next(), "%dx%d", &args.w, &args.h) != 2 || args.w <= 0 || args.h <= 0 || args.w > 8192 ||
                args.h > 8192) {
                std::fprintf(stderr, "--size wants WxH, e.g. 960x540\n");
                return 2;
            }
        } else if (a == "--seed") args.seed = std::strtoull(next(), nullptr, 10);
        else if (a == "--out") args.out = next();
        else {
            std::fprintf(stderr, "usage: firefly_demo [--scene NAME] [--size WxH] [--seed N] [--out DIR]\n");
            return a == "--help" || a == "-h" ? 0 : 2;
        }
    }
    return -1;
}

// firefly at defaults (its report kept), firefly with the paper's rules, and the peers, each
// given the same NaN/Inf repair first so the table compares firefly handling.
std::vector<method> demo_methods(detector& d, detector& paper, frame_report& report) {
    auto peer = [](void (*fn)(const image_view<float>&, const image_view<float>&)) {
        return [fn](half_buffer<float>& a, half_buffer<float>& b) {
            (void)firefly_peers::repair_nonfinite(a.color, a.variance, b.color, b.variance);
            fn(a.color, a.variance);
            fn(b.color, b.variance);
        };
    };
    return {
        {"firefly", [&](half_buffer<float>& a, half_buffer<float>& b) { report = d.process(a, b); }},
        {"firefly (paper rules)", [&](half_buffer<float>& a, half_buffer<float>& b) { (void)paper.process(a, b); }},
        {"Cycles prefilter", peer(&firefly_peers::cycles_prefilter)},
        {"BCD spike removal", peer([](const image_view<float>& c, const image_view<float>& v) { firefly_peers::bcd_spikes(c, v); })},
        {"NRD anti-firefly", peer(&firefly_peers::nrd_clamp)},
        {"median 3x3", peer(&firefly_peers::median3x3)},
        {"clamp at 4", peer([](const image_view<float>& c, const image_view<float>& v) { firefly_peers::fixed_clamp(c, v, 4.0f); })},
    };
}

// Runs every method on copies of the frame's halves and prints a row each; firefly's cleaned
// halves are kept in firefly_out.
void print_table(const sim::frame& f, const std::vector<method>& methods, std::vector<float> (&firefly_out)[2]) {
    const int w = f.width, h = f.height;
    const std::vector<float>* input[2] = {&f.color[0], &f.color[1]};
    const sim::accuracy none = sim::evaluate(f, input);
    std::printf("\n%-22s %9s %9s %10s %10s %9s\n", "method", "recall", "changed", "highlights", "relMSE", "ms");
    std::printf("%-22s %9s %9s %10s %10.5f %9s\n", "(input)", "-", "-", "-", none.relmse, "-");
    for (const method& m : methods) {
        std::vector<float> col[2] = {f.color[0], f.color[1]}, var[2] = {f.variance[0], f.variance[1]};
        half_buffer<float> hb[2];
        for (int i = 0; i < 2; ++i) {
            hb[i].color = *make_image_view(col[i].data(), w, h, 3);
            hb[i].variance = *make_image_view(var[i].data(), w, h, 3);
            if (!f.alpha.empty()) hb[i].alpha = *make_image_view(f.alpha.data(), w, h, 1);
        }
        const auto t0 = std::chrono::steady_clock::now();
        m.run(hb[0], hb[1]);
        const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
        const std::vector<float>* cleaned[2] = {&col[0], &col[1]};
        const sim::accuracy a = sim::evaluate(f, cleaned);
        std::printf("%-22s %9.4f %8.3f%% %10.4f %10.5f %9.1f\n", m.name, a.recall,
                    100.0 * a.false_positive, a.highlight_kept, a.relmse, ms);
        if (std::strcmp(m.name, "firefly") == 0) {
            firefly_out[0] = col[0];
            firefly_out[1] = col[1];
        }
    }
    std::printf("\nrecall: visible fireflies removed; changed: clean pixels changed (false positives);\n"
                "highlights: highlight pixels left untouched; relMSE of (A+B)/2 against the expected image.\n");
}

// The combined input, the combined firefly output and the expected image, as EXR and PNG
// where the build has them.
void write_images(const sim::frame& f, const std::vector<float> (&cleaned)[2], const std::string& out) {
    const int w = f.width, h = f.height;
    ::mkdir(out.c_str(), 0755);
    const std::size_t np = f.pixels();
    std::vector<float> before(np * 3), after(np * 3);
    for (std::size_t i = 0; i < np * 3; ++i) {
        before[i] = 0.5f * (f.color[0][i] + f.color[1][i]);
        after[i] = 0.5f * (cleaned[0][i] + cleaned[1][i]);
    }
    struct named {
        const char* file;
        const std::vector<float>* px;
    } images[] = {{"before", &before}, {"after", &after}, {"expected", &f.expected}};
    bool wrote = false;
    for (const named& n : images) {
        firefly_tools::image img{w, h, {"R", "G", "B"}, *n.px};
        if (firefly_tools::have_exr()) {
            const std::string e = firefly_tools::write_exr(out + "/" + n.file + ".exr", img);
            if (!e.empty()) std::fprintf(stderr, "%s\n", e.c_str());
            else wrote = true;
        }
        if (firefly_tools::have_png()) {
            const std::string e = firefly_tools::write_png_preview(out + "/" + n.file + ".png", n.px->data(), w, h);
            if (!e.empty()) std::fprintf(stderr, "%s\n", e.c_str());
            else wrote = true;
        }
    }
    if (wrote)
        std::printf("\nimages: %s/{before,after,expected}.%s\n", out.c_str(),
                    firefly_tools::have_exr() && firefly_tools::have_png() ? "{exr,png}" : firefly_tools::have_exr() ? "exr" : "png");
    else
        std::printf("\nimages skipped: build with libopenexr-dev and/or libpng-dev to write EXR and PNG files\n");
}
}  // namespace

int main(int argc, char** argv) {
    demo_args args;
    if (const int code = parse_args(argc, argv, args); code >= 0) return code;
    const sim::scene sc = sim::named_scene(args.scene, args.w, args.h, args.seed);
    std::printf("firefly %d.%d.%d demo: scene '%s', %dx%d, %d samples per pixel per half\n", FIREFLY_VERSION_MAJOR,
                FIREFLY_VERSION_MINOR, FIREFLY_VERSION_PATCH, sc.name.c_str(), args.w, args.h, sc.spp);
    const sim::frame f = sim::simulate(sc);

    detector_options paper;
    paper.highlight.rule = highlight_rule::same_pixel;
    paper.highlight.min_excess_z = 0;
    paper.rebuild = rebuild_source::spatial;
    paper.local_test = false;
    detector d, dp(paper);
    frame_report report;
    std::vector<float> cleaned[2];
    print_table(f, demo_methods(d, dp, report), cleaned);
    for (int i = 0; i < 2; ++i)
        std::printf("firefly, half %c: %zu outliers (bound %zu), %zu fireflies rebuilt, %zu highlights and %zu "
                    "consistent outliers kept, %zu non-finite repaired\n",
                    'A' + i, report.half[i].outliers, report.half[i].bound, report.half[i].fireflies,
                    report.half[i].highlights, report.half[i].consistent, report.half[i].repaired);
    write_images(f, cleaned, args.out);
    return report.error.ok() ? 0 : 1;
}
