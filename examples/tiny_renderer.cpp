// A tiny Monte Carlo path tracer feeding K = 8 buffers (firefly/accumulator.hpp), cleaned
// across the buffers (firefly/buffers.hpp), against a high-sample render of the same scene.
//
// Scene: a diffuse floor under a sky, a glass sphere, a small bright light above it. The
// light is sampled directly (next-event estimation), but the glass blocks those shadow rays,
// so the caustic under the sphere is reached only by rare paths floor -> glass -> light:
// each a firefly. Usage: firefly_tiny_renderer [width height spp_per_buffer reference_spp]
#include <firefly/accumulator.hpp>
#include <firefly/buffers.hpp>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <thread>
#include <vector>

namespace {

struct vec {
    double x = 0, y = 0, z = 0;
};
vec operator+(vec a, vec b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
vec operator-(vec a, vec b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
vec operator*(vec a, double s) { return {a.x * s, a.y * s, a.z * s}; }
vec mul(vec a, vec b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }
double dot(vec a, vec b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
vec cross(vec a, vec b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }
vec normalize(vec a) { return a * (1.0 / std::sqrt(dot(a, a))); }

// Counter-based random numbers: the same pixel and sample index give the same path.
struct rng {
    std::uint64_t s;
    double next() {
        std::uint64_t z = (s += 0x9E3779B97F4A7C15ull);
        z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
        z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
        return static_cast<double>((z ^ (z >> 31)) >> 11) * 0x1.0p-53;
    }
};

const double pi = 3.14159265358979323846;
const vec glass_c{0, 1, 0}, light_c{-3, 3, -3}, sky{0.25, 0.3, 0.4}, floor_albedo{0.7, 0.65, 0.6};
const double glass_r = 1, light_r = 0.25, ior = 1.5;
const vec light_e{150, 140, 125};

// Distance along the ray to a sphere, or -1.
double hit_sphere(vec o, vec d, vec c, double r) {
    const vec oc = o - c;
    const double b = dot(oc, d), disc = b * b - (dot(oc, oc) - r * r);
    if (disc < 0) return -1;
    const double s = std::sqrt(disc);
    if (b - s > 1e-6) return -b - s;
    return -b + s > 1e-6 ? -b + s : -1;
}

// A cosine-weighted direction about n.
vec cosine_dir(vec n, rng& r) {
    const double u = r.next(), v = 2 * pi * r.next(), s = std::sqrt(u);
    const vec t = normalize(cross(std::fabs(n.x) > 0.5 ? vec{0, 1, 0} : vec{1, 0, 0}, n)), b = cross(n, t);
    return normalize(t * (s * std::cos(v)) + b * (s * std::sin(v)) + n * std::sqrt(1 - u));
}

// Light at a floor point from the small light, sampled in its cone; the glass shadows it.
vec direct_light(vec p, vec n, rng& r) {
    const vec to = light_c - p;
    const double d2 = dot(to, to), cos_max = std::sqrt(1 - light_r * light_r / d2);
    const double ct = 1 - r.next() * (1 - cos_max), st = std::sqrt(1 - ct * ct), ph = 2 * pi * r.next();
    const vec w = normalize(to), t = normalize(cross(std::fabs(w.x) > 0.5 ? vec{0, 1, 0} : vec{1, 0, 0}, w)), b = cross(w, t);
    const vec dir = normalize(t * (st * std::cos(ph)) + b * (st * std::sin(ph)) + w * ct);
    const double cos_n = dot(dir, n);
    if (cos_n <= 0 || hit_sphere(p, dir, glass_c, glass_r) > 0) return {};
    return light_e * (cos_n / pi * 2 * pi * (1 - cos_max));  // albedo applied by the caller
}

// One path from the camera.
vec radiance(vec o, vec d, rng& r) {
    vec sum{}, thr{1, 1, 1};
    bool specular = true;  // the light counts when hit after the camera or glass only
    for (int depth = 0; depth < 8; ++depth) {
        const double tg = hit_sphere(o, d, glass_c, glass_r), tl = hit_sphere(o, d, light_c, light_r);
        const double tf = d.y < 0 ? -o.y / d.y : -1;
        double t = 1e30;
        int what = 0;  // 0 sky, 1 glass, 2 light, 3 floor
        if (tg > 0 && tg < t) t = tg, what = 1;
        if (tl > 0 && tl < t) t = tl, what = 2;
        if (tf > 1e-6 && tf < t) t = tf, what = 3;
        if (what == 0) return sum + mul(thr, sky);
        if (what == 2) return specular ? sum + mul(thr, light_e) : sum;
        const vec p = o + d * t;
        if (what == 3) {
            const vec n{0, 1, 0};
            const bool checker = (static_cast<int>(std::floor(p.x)) + static_cast<int>(std::floor(p.z))) & 1;
            const vec albedo = checker ? floor_albedo * 0.6 : floor_albedo;
            thr = mul(thr, albedo);
            sum = sum + mul(thr, direct_light(p, n, r));
            o = p;
            d = cosine_dir(n, r);
            specular = false;
            continue;
        }
        vec n = normalize(p - glass_c);  // glass: Fresnel (Schlick) picks reflection or refraction
        double eta = 1 / ior, c = -dot(d, n);
        if (c < 0) n = n * -1, eta = ior, c = -c;
        const double k = 1 - eta * eta * (1 - c * c), f0 = (1 - ior) * (1 - ior) / ((1 + ior) * (1 + ior));
        const double fr = k < 0 ? 1 : f0 + (1 - f0) * std::pow(1 - c, 5);
        d = r.next() < fr ? normalize(d + n * (2 * c)) : normalize(d * eta + n * (eta * c - std::sqrt(k)));
        o = p;
        specular = true;  // the light seen through glass: the caustic's rare paths
    }
    return sum;
}

// Samples [first, first + count) of rows [y0, y1) into the accumulator.
void render_rows(firefly::sample_accumulator& acc, int y0, int y1, int first, int count, std::uint64_t seed) {
    const int w = acc.width(), h = acc.height();
    const vec eye{0, 2.2, 6}, fwd = normalize(vec{0, 0.6, 0} - eye), right = normalize(cross(fwd, {0, 1, 0})), up = cross(right, fwd);
    const double scale = std::tan(0.5 * 40 * pi / 180);
    for (int y = y0; y < y1; ++y)
        for (int x = 0; x < w; ++x)
            for (int s = first; s < first + count; ++s) {
                rng r{seed ^ ((static_cast<std::uint64_t>(y) * 4096 + static_cast<std::uint64_t>(x)) << 24) ^ static_cast<std::uint64_t>(s)};
                for (int i = 0; i < 4; ++i) r.next();
                const double px = (2 * (x + r.next()) / w - 1) * scale * w / h, py = (1 - 2 * (y + r.next()) / h) * scale;
                const vec c = radiance(eye, normalize(fwd + right * px + up * py), r);
                const float v[3] = {static_cast<float>(c.x), static_cast<float>(c.y), static_cast<float>(c.z)};
                (void)acc.add(x, y, static_cast<std::uint64_t>(s), v);
            }
}

// Two threads on disjoint halves of the rows: the accumulator needs no lock.
void render(firefly::sample_accumulator& acc, int first, int count, std::uint64_t seed) {
    const int mid = acc.height() / 2;
    std::thread top([&] { render_rows(acc, 0, mid, first, count, seed); });
    render_rows(acc, mid, acc.height(), first, count, seed);
    top.join();
}

double relmse(const std::vector<float>& x, const std::vector<float>& ref) {
    double s = 0;
    for (std::size_t i = 0; i < ref.size(); ++i) {
        const double d = x[i] - ref[i];
        s += d * d / (static_cast<double>(ref[i]) * ref[i] + 0.01);
    }
    return s / static_cast<double>(ref.size());
}

std::vector<float> mean_of(const std::vector<std::vector<float>>& b) {
    std::vector<float> m(b[0].size(), 0.0f);
    for (const auto& v : b)
        for (std::size_t i = 0; i < m.size(); ++i) m[i] += v[i] / static_cast<float>(b.size());
    return m;
}

}  // namespace

int main(int argc, char** argv) {
    const int w = argc > 2 ? std::atoi(argv[1]) : 160, h = argc > 2 ? std::atoi(argv[2]) : 120;
    const int spp = argc > 3 ? std::atoi(argv[3]) : 8, ref_spp = argc > 4 ? std::atoi(argv[4]) : 1024;
    const int k = 8;
    firefly::sample_accumulator acc, ref;
    if (!acc.reset(w, h, k).ok() || !ref.reset(w, h, 2).ok() || spp < 1 || ref_spp < 2) {
        std::fprintf(stderr, "usage: firefly_tiny_renderer [width height spp_per_buffer reference_spp]\n");
        return 2;
    }
    render(acc, 0, k * spp, 1);
    render(ref, 0, ref_spp, 2);  // an independent seed
    acc.finish();
    ref.finish();
    std::vector<float> truth(static_cast<std::size_t>(w * h * 3));
    for (std::size_t i = 0; i < truth.size(); ++i) truth[i] = 0.5f * (ref.color(0).data()[i] + ref.color(1).data()[i]);

    std::vector<std::vector<float>> color(k), variance(k);
    for (int b = 0; b < k; ++b) {
        color[static_cast<std::size_t>(b)].assign(acc.color(b).data(), acc.color(b).data() + w * h * 3);
        variance[static_cast<std::size_t>(b)].assign(acc.variance(b).data(), acc.variance(b).data() + w * h * 3);
    }
    const double e_mean = relmse(mean_of(color), truth);

    // K = 8 across the buffers, without and with the variance.
    double e_cross[2] = {0, 0};
    for (const bool with_var : {false, true}) {
        std::vector<std::vector<float>> c = color, v = variance;
        std::vector<firefly::buffer_view<float>> views;
        for (int b = 0; b < k; ++b)
            views.push_back({*firefly::make_image_view(c[static_cast<std::size_t>(b)].data(), w, h, 3),
                             with_var ? *firefly::make_image_view(v[static_cast<std::size_t>(b)].data(), w, h, 3)
                                      : firefly::image_view<float>{}});
        firefly::cross_buffer_options o;
        o.use_variance = with_var;
        firefly::cross_buffer_detector d(o);
        const firefly::cross_buffer_report r = d.process(views);
        if (!r.ok()) std::fprintf(stderr, "cross-buffer detector: %s\n", r.error.message());
        e_cross[with_var] = relmse(mean_of(c), truth);
        std::printf("K = 8 %s variance: %zu pixel-buffers rebuilt\n", with_var ? "with" : "without", r.fireflies + r.nonfinite);
    }

    // Two halves of the same samples (buffers 0-3 and 4-7) through firefly::detector.
    std::vector<std::vector<float>> halves(2, std::vector<float>(color[0].size())), hvar = halves;
    for (int half = 0; half < 2; ++half)
        for (std::size_t i = 0; i < color[0].size(); ++i) {
            double c = 0, v = 0;
            for (int b = 4 * half; b < 4 * half + 4; ++b) c += color[static_cast<std::size_t>(b)][i], v += variance[static_cast<std::size_t>(b)][i];
            halves[static_cast<std::size_t>(half)][i] = static_cast<float>(c / 4);
            hvar[static_cast<std::size_t>(half)][i] = static_cast<float>(v / 16);
        }
    firefly::detector pair;
    const firefly::frame_report pr =
        pair.process(firefly::half_buffer<float>{*firefly::make_image_view(halves[0].data(), w, h, 3), *firefly::make_image_view(hvar[0].data(), w, h, 3), {}},
                     firefly::half_buffer<float>{*firefly::make_image_view(halves[1].data(), w, h, 3), *firefly::make_image_view(hvar[1].data(), w, h, 3), {}});
    if (!pr.ok()) std::fprintf(stderr, "detector: %s\n", pr.error.message());
    const double e_pair = relmse(mean_of(halves), truth);

    std::printf("%dx%d, %d samples per pixel in %d buffers, reference %d samples\n", w, h, k * spp, k, ref_spp);
    std::printf("relMSE  mean of the buffers        %.4f\n", e_mean);
    std::printf("relMSE  K = 8, spread only          %.4f\n", e_cross[0]);
    std::printf("relMSE  K = 8, with variance        %.4f\n", e_cross[1]);
    std::printf("relMSE  two halves (4 + 4 buffers)  %.4f\n", e_pair);
    return e_cross[0] < e_mean && e_cross[1] < e_mean ? 0 : 1;
}
