// How a renderer's denoise stage adopts firefly: it keeps one firefly::detector for the
// whole sequence (the Student-t critical values and the scratch memory are reused frame
// after frame), cleans the two half buffers in place right after rendering, and hands the
// cleaned halves and their variance to the denoiser.
//
// The renderer here keeps its buffers as glm::vec3, so firefly/glm.hpp makes the views.
#include <firefly/firefly.hpp>
#include <firefly/glm.hpp>
#include <firefly/sim/scene.hpp>

#include <glm/vec3.hpp>

#include <cstdio>
#include <vector>

namespace renderer {

// What a path tracer keeps per half buffer: the mean of its samples and the variance of
// that mean, per pixel.
struct half_buffers {
    std::vector<glm::vec3> color, variance;
};

// The input the denoiser wants: the two cleaned halves (for its cross-validation) and the
// combined image with its variance.
struct denoiser_input {
    int width = 0, height = 0;
    const half_buffers* a = nullptr;
    const half_buffers* b = nullptr;
    std::vector<glm::vec3> combined, combined_variance;
};

class denoise_stage {
public:
    explicit denoise_stage(firefly::detector_options o = {}) : detector_(o, firefly::executor::threads(2)) {}

    // Cleans the frame's halves in place and prepares the denoiser's input. Returns false
    // (and says why) when the buffers cannot be used; they are then left as they were.
    bool run(int width, int height, half_buffers& a, half_buffers& b, denoiser_input& out) {
        firefly::half_buffer<float> ha, hb;
        if (!view(width, height, a, ha) || !view(width, height, b, hb)) return false;
        const firefly::frame_report r = detector_.process(ha, hb);
        if (!r.ok()) {
            std::fprintf(stderr, "firefly: %s\n", r.error.message());
            return false;
        }
        out.width = width;
        out.height = height;
        out.a = &a;
        out.b = &b;
        out.combined.resize(a.color.size());
        out.combined_variance.resize(a.color.size());
        auto comb = *firefly::make_glm_view(out.combined.data(), width, height);
        auto comb_var = *firefly::make_glm_view(out.combined_variance.data(), width, height);
        (void)firefly::combine_halves(ha.color, hb.color, comb, ha.variance, hb.variance, comb_var);
        frames_ += 1;
        fireflies_ += r.half[0].fireflies + r.half[1].fireflies;
        std::printf("frame %d: %zu + %zu fireflies removed, %zu highlights kept, %zu new lambdas\n", frames_,
                    r.half[0].fireflies, r.half[1].fireflies, r.half[0].highlights, r.lambdas_computed);
        return true;
    }

    std::size_t fireflies() const { return fireflies_; }

private:
    static bool view(int w, int h, half_buffers& hb, firefly::half_buffer<float>& out) {
        auto c = firefly::make_glm_view(hb.color.data(), w, h);
        auto v = firefly::make_glm_view(hb.variance.data(), w, h);
        if (!c || !v || hb.color.size() != hb.variance.size()) {
            std::fprintf(stderr, "firefly: %s\n", !c ? c.error().message() : v.error().message());
            return false;
        }
        out.color = *c;
        out.variance = *v;
        return true;
    }

    firefly::detector detector_;
    int frames_ = 0;
    std::size_t fireflies_ = 0;
};

}  // namespace renderer

int main() {
    // Three "rendered" frames of a moving sequence, from the simulator.
    const int w = 320, h = 180;
    renderer::denoise_stage stage;
    for (int frame = 0; frame < 3; ++frame) {
        const firefly::sim::frame f =
            firefly::sim::simulate(firefly::sim::named_scene("highlights", w, h, 100 + static_cast<unsigned>(frame)));
        renderer::half_buffers a, b;
        for (renderer::half_buffers* hb : {&a, &b}) {
            const int i = hb == &a ? 0 : 1;
            hb->color.resize(f.pixels());
            hb->variance.resize(f.pixels());
            for (std::size_t p = 0; p < f.pixels(); ++p) {
                hb->color[p] = glm::vec3(f.color[i][p * 3], f.color[i][p * 3 + 1], f.color[i][p * 3 + 2]);
                hb->variance[p] = glm::vec3(f.variance[i][p * 3], f.variance[i][p * 3 + 1], f.variance[i][p * 3 + 2]);
            }
        }
        renderer::denoiser_input input;
        if (!stage.run(w, h, a, b, input)) return 1;
        // The denoiser takes over from here; this example reports what it would receive.
        double mean = 0, var = 0;
        for (std::size_t p = 0; p < input.combined.size(); ++p) {
            mean += (input.combined[p].x + input.combined[p].y + input.combined[p].z) / 3.0;
            var += (input.combined_variance[p].x + input.combined_variance[p].y + input.combined_variance[p].z) / 3.0;
        }
        std::printf("  to the denoiser: %dx%d, mean radiance %.4f, mean variance %.3g\n", input.width, input.height,
                    mean / static_cast<double>(input.combined.size()), var / static_cast<double>(input.combined.size()));
    }
    return stage.fireflies() > 0 ? 0 : 1;
}
