// The default detector on simulator seeds the accuracy tables do not use (they use seed 1):
// recall, highlights kept, false positives and relMSE (sim/metrics.hpp) per scene, seed and
// sample count, so that a change tuned to the tables' frames shows up as one that does not
// carry to others. Built against two trees (the change and its parent), the two outputs side
// by side are the comparison.
//
// Build: g++ -std=c++17 -O2 -Iinclude bench/research/held_out.cpp -o held_out
// Run:   ./held_out [WxH]   (default 960x540)
#include <firefly/firefly.hpp>
#include <firefly/sim/metrics.hpp>
#include <firefly/sim/scene.hpp>
#include <firefly/sim/scenes.hpp>

#include <cstdio>
#include <vector>

using namespace firefly;

namespace {

// Cleans a simulated frame at the defaults and scores it against its ground truth.
sim::accuracy clean_and_score(const sim::frame& f) {
    std::vector<float> col[2] = {f.color[0], f.color[1]}, var[2] = {f.variance[0], f.variance[1]};
    half_buffer<float> hb[2];
    for (int i = 0; i < 2; ++i) {
        hb[i].color = *make_image_view(col[i].data(), f.width, f.height, 3);
        hb[i].variance = *make_image_view(var[i].data(), f.width, f.height, 3);
        if (!f.alpha.empty()) hb[i].alpha = *make_image_view(f.alpha.data(), f.width, f.height, 1);
    }
    detector d;
    (void)d.process(hb[0], hb[1]);
    const std::vector<float>* cleaned[2] = {&col[0], &col[1]};
    return sim::evaluate(f, cleaned);
}

}  // namespace

int main(int argc, char** argv) {
    int w = 960, h = 540;
    if (argc > 1 && (std::sscanf(argv[1], "%dx%d", &w, &h) != 2 || w < 16 || h < 16)) {
        std::fprintf(stderr, "usage: held_out [WxH]\n");
        return 2;
    }
    const char* scenes[] = {"caustics", "production", "highlights", "dense30", "wide_highlight", "interior"};
    std::printf("scene            seed  spp  recall  highlights_kept  false_pos  relmse\n");
    for (const char* name : scenes)
        for (const unsigned long long seed : {2ull, 3ull, 4ull})
            for (const int spp : {0, 16}) {  // 0: the scene's own sample count
                sim::scene sc = sim::named_scene(name, w, h, seed);
                if (spp) sc.spp = spp;
                const sim::accuracy a = clean_and_score(sim::simulate(sc));
                std::printf("%-16s %4llu %4d  %.4f  %.4f           %.5f    %.5g\n", name, seed, sc.spp, a.recall,
                            a.highlight_kept, a.false_positive, a.relmse);
            }
    return 0;
}
