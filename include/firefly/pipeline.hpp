// firefly: the whole pipeline over the two half buffers of a frame, and the detector object a
// renderer's denoise stage keeps from frame to frame (it owns the scratch memory and a lambda
// cache it may share with other detectors, so the second half buffer and every later frame
// reuse both).
//
//   per half      variance -> standard deviation; modified Z-score bound; one-sided
//                 generalized ESD on the standard deviations (top values from the pixels
//                 above the bound's cutoff, statistics built from the bottom up)
//   across halves the highlight check: an outlier in both halves may be kept (highlight_rule)
//   across halves a pixel bad in one half only is rebuilt from the other half at the same
//                 pixel, blended with the spatial estimate where that lowers the frame's
//                 expected error (cross_half.hpp)
//   per half      two-phase spatial reconstruction of what is bad in both halves, in place
//   per half      the removed fireflies' energy given back where many agree on it
//                 (energy.hpp; return_energy)
//
// Stages run as tasks on the executor; each writes disjoint memory, every cross-half value
// is computed before any is written, and the lambda cache is filled between the parallel
// stages, so every executor gives the same bytes.
#pragma once

#include <algorithm>
#include <cfloat>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <mutex>
#include <type_traits>
#include <utility>
#include <vector>

#include "bound.hpp"
#include "cross_half.hpp"
#include "dropped.hpp"
#include "density.hpp"
#include "energy.hpp"
#include "esd.hpp"
#include "fdr.hpp"
#include "highlight.hpp"
#include "image_view.hpp"
#include "implausible.hpp"
#include "local_test.hpp"
#include "parallel.hpp"
#include "reconstruct.hpp"
#include "scratch.hpp"
#include "statistics.hpp"
#include "status.hpp"
#include "stddev.hpp"

namespace firefly {

// One half buffer: colour (1 to 4 channels; the first three are colour, a 4th is carried
// along: checked for NaN/Inf and rebuilt with the rest, never taken as coverage), its
// variance (1 channel, or one per colour channel) and optional alpha (coverage; pixels with
// alpha <= 0 are left out of the statistics). Each may have its own channel type: float
// colour with half-float or double variance, alpha in a buffer of its own type. To use the
// 4th channel of an RGBA image as alpha: `hb.alpha = rgba.channel_range(3, 1).value();`.
// Const colour and variance views can be given to detector::detect(), which changes nothing.
template <class C, class V = C, class A = const std::remove_const_t<C>>
struct half_buffer {
    image_view<C> color;
    image_view<V> variance;
    image_view<A> alpha;  // empty: no alpha
};

// What replaces a firefly.
enum class rebuild_source : std::uint8_t {
    other_half,  // the other half's value at the same pixel where it is usable, blended with
                 // the spatial estimate where that lowers the expected error; spatial else
    spatial,     // the paper: the spatial (Gaussian) estimate from the pixel's own half only
};

struct detector_options {
    double alpha = 0.05;                // significance of the generalized ESD test
    double bound_threshold = 3.5;       // modified Z-score cut for the upper bound
    variance_reduction reduction = variance_reduction::mean;
    lambda_method lambdas = lambda_method::exact;
    highlight_options highlight{};
    reconstruct_options reconstruction{};
    bool local_test = true;             // add the local, brightness-invariant test's flags
                                        // (local_test.hpp) to the global ESD's outliers
    local_test_options local{};         // its variance_scale multiplies the frame's own measured
                                        // calibration (variance_calibration), which already
                                        // finds the convention: leave it 1
    rebuild_source rebuild = rebuild_source::other_half;
    bool blend_spatial = true;          // other_half: blend in the spatial estimate (false:
                                        // the other half's value alone)
    bool reconstruct = true;            // false: detect and report only, change nothing
    bool find_dropped = true;           // pixels black in one half where the other half shows
                                        // they cannot be (a failed bucket written black,
                                        // dropped.hpp) are rebuilt as non-finite ones are
    bool find_implausible = true;       // values the other half shows no Monte Carlo estimate
                                        // holds (a bucket of 1e30 with a sane variance,
                                        // implausible.hpp) are rebuilt as non-finite ones are
    bool return_energy = true;          // give back the rebuilt fireflies' energy where many
                                        // agree on it (energy.hpp; adds light to pixels near
                                        // dense fireflies, never lowers any; false: the
                                        // paper's removal alone)
    double energy_sigma = 8.0;          // its Gaussian's width in pixels (1 to 64)
    double energy_coarse_sigma = 32.0;  // the wider scale, used where the fine one cannot tell
                                        // them apart (sparse fireflies); 0 or not above
                                        // energy_sigma: none; else 2 to 256
    double energy_density_evidence = 8.0;  // the return's finest scale (density.hpp): removed
                                        // light given back where it fell, above the cleaned
                                        // image's level, where more than this many equal removed
                                        // samples of both halves agree (a bokeh disc, dense
                                        // fireflies); 0: none; else 1 to 1e6
};

inline status check_options(const detector_options& o) noexcept {
    if (const status e = check_alpha(o.alpha); !e.ok()) return e;
    if (!(o.bound_threshold >= 0.0) || !std::isfinite(o.bound_threshold))
        return status{errc::invalid_argument, "bound threshold must be finite and >= 0"};
    if (static_cast<unsigned>(o.reduction) > static_cast<unsigned>(variance_reduction::max) ||
        static_cast<unsigned>(o.lambdas) > static_cast<unsigned>(lambda_method::normal) ||
        static_cast<unsigned>(o.highlight.rule) > static_cast<unsigned>(highlight_rule::confident_and_agree) ||
        static_cast<unsigned>(o.rebuild) > static_cast<unsigned>(rebuild_source::spatial))
        return status{errc::invalid_argument, "an enum option holds a value outside its enumerators"};
    if (!(o.highlight.max_ratio >= 1.0) || !(o.highlight.max_relative_error >= 0.0) ||
        !(o.highlight.min_excess_z >= 0.0) || !(o.highlight.cluster_relative_error >= 0.0))
        return status{errc::invalid_argument,
                      "highlight: max_ratio >= 1, max_relative_error >= 0, min_excess_z >= 0"};
    if (status st = check_local_test_options(o.local); !st.ok()) return st;
    if (!(o.energy_sigma >= 1.0 && o.energy_sigma <= 64.0))
        return status{errc::invalid_argument, "energy_sigma must lie in [1, 64]"};
    if (status st = check_energy_coarse(o.energy_coarse_sigma); !st.ok()) return st;
    if (status st = check_density_evidence(o.energy_density_evidence); !st.ok()) return st;
    return check_reconstruct_options(o.reconstruction);
}

// Bits of the optional per-pixel masks.
namespace mask_bits {
inline constexpr std::uint8_t firefly = 1;    // outlier rebuilt (unless left)
inline constexpr std::uint8_t highlight = 2;  // outlier in both halves, kept
inline constexpr std::uint8_t nonfinite = 4;  // NaN/Inf repaired (unless left); also an
                                              // implausible value (implausible.hpp)
inline constexpr std::uint8_t consistent = 8; // outlier in one half, but within the noise of
                                              // the other half: kept (min_excess_z); or in
                                              // both, within its neighbourhood's noise
inline constexpr std::uint8_t other_half = 16;// rebuilt from the other half's value at this
                                              // pixel (with firefly or nonfinite): the halves
                                              // are correlated here
inline constexpr std::uint8_t energy = 32;    // light added by the energy return (energy.hpp):
                                              // the removed fireflies' energy given back
inline constexpr std::uint8_t left = 64;      // with firefly, nonfinite or dropped: to be rebuilt, but
                                              // no usable value reached it (process() only;
                                              // report.unreachable, no_valid_pixels; K buffers:
                                              // report.left): it keeps its input values
inline constexpr std::uint8_t dropped = 128;  // black here where the other half shows it
                                              // cannot be by chance (dropped.hpp): rebuilt as
                                              // a non-finite pixel (unless left)
}  // namespace mask_bits

struct half_report {
    std::size_t pixels = 0;
    std::size_t valid = 0;              // pixels in the statistics
    std::size_t ignored = 0;            // black or alpha <= 0
    std::size_t nonfinite = 0;          // NaN/Inf in colour, variance or alpha
    std::size_t dropped = 0;            // black where the other half shows it cannot be by
                                        // chance (find_dropped; not counted in ignored)
    std::size_t implausible = 0;        // finite, but beyond what the other half allows any
                                        // estimate (find_implausible; not counted in valid)
    std::size_t negative_variance = 0;  // pixels with a negative variance (taken as 0)
    double median = 0.0;                // of the standard deviations (NaN where valid is 0)
    double mad = 0.0;                   // their median absolute deviation (NaN likewise)
    std::size_t bound = 0;              // modified Z-score upper bound
    std::size_t outliers = 0;           // generalized ESD outliers and local flags
    std::size_t local = 0;              // of those, flagged by the local test only
    std::size_t highlights = 0;         // outliers kept (outlier in both halves)
    std::size_t consistent = 0;         // outliers kept (within the other half's noise, or
                                        // not kept by the frame's decision: frame_kept; pairs
                                        // within their neighbourhood's noise)
    std::size_t frame_kept = 0;         // one-half outliers the frame's decision kept (fdr.hpp)
    std::size_t fireflies = 0;          // outliers to rebuild (rebuilt unless reconstruct = false)
    std::size_t repaired = 0;           // non-finite, dropped and implausible pixels rebuilt
    std::size_t from_other_half = 0;    // of the rebuilt pixels, those taken from the other half
    std::size_t unreachable = 0;        // pixels to rebuild that no usable source could reach
    int phase1_rounds = 0;
    int phase2_iterations = 0;
    double final_change = 0.0;
    status reconstruction{};            // no_valid_pixels when pixels were left unreachable
    double energy_removed = 0.0;        // return_energy: sums over pixels of the mean colour
    double energy_returned = 0.0;       // the rebuild took away, and the energy return added
                                        // (both 0 for colour of 1 or 2 channels: no return)

    // What this half found to rebuild: fireflies, non-finite, dropped and implausible pixels
    // (as a K-buffer report counts a buffer: cross_buffer_report::per_buffer).
    std::size_t found() const noexcept { return fireflies + nonfinite + dropped + implausible; }
};

struct [[nodiscard]] frame_report {
    // True when the frame was checked and every pixel that needed it was rebuilt.
    bool ok() const noexcept { return error.ok(); }
    status error{};                     // why not ok(): inputs or options refused, or pixels
                                        // left without a usable source (they keep their values)
    half_report half[2];
    std::size_t both_outliers = 0;      // pixels that are outliers in both halves
    double variance_calibration = 1.0;  // variance -> variance of the mean (highlight rule)
    double single_level = 0.0;          // the largest p-value of a one-half firefly the frame's
                                        // decision kept (fdr.hpp; 0: none kept, or below 1e-308)
    double single_log_level = -HUGE_VAL;// its log, which does not underflow (-inf: none kept)
    std::size_t lambdas_computed = 0;   // lambda cache misses in this frame
    std::size_t scratch_bytes = 0;      // detector memory after this frame
    // Wall time of each stage, milliseconds (both halves): standard deviations, bound and
    // candidates; the ESD decisions; the calibration and the local test; the highlight
    // check; the other half's estimates; the writes, spatial reconstruction and masks.
    enum stage { candidates, esd, local, highlights, other_half, rebuild, stages };
    double stage_ms[stages] = {};
};

namespace detail {
// Laps of a steady clock into an array of milliseconds.
class stage_clock {
public:
    explicit stage_clock(double* ms) : ms_(ms), last_(std::chrono::steady_clock::now()) {}
    void lap(int stage) {
        const auto now = std::chrono::steady_clock::now();
        ms_[stage] = std::chrono::duration<double, std::milli>(now - last_).count();
        last_ = now;
    }

private:
    double* ms_;
    std::chrono::steady_clock::time_point last_;
};

// The steps of the calibration's lattice along x and y for `cells` = pixels / 16,384: the
// same step on both axes (sqrt(cells)), except that an axis shorter than two steps takes a
// step of at most half its length (two points at least) and the long one the rest. One step
// for both left no row of a frame of fewer rows than the step (a 70000 x 1 frame: no ratio,
// factor 1 unsaid).
// At most one axis is that short (both: w h / 4 < cells = w h / 16384), so a transposed frame
// gets the transposed steps.
inline void lattice_steps(double cells, int w, int h, int& sx, int& sy) noexcept {
    const int step = (std::max)(1, static_cast<int>(std::sqrt(cells)));
    const int most_x = (std::max)(1, w / 2), most_y = (std::max)(1, h / 2);
    sx = (std::min)(step, most_x);
    sy = (std::min)(step, most_y);
    auto rest = [cells](int other, int most) { return (std::min)((std::max)(1.0, cells / other), static_cast<double>(most)); };
    if (sx < step) sy = static_cast<int>(rest(sx, most_y));
    else if (sy < step) sx = static_cast<int>(rest(sy, most_x));
}
// The detector's lambda cache. A moved-from shared_ptr is null, and a moved-from detector
// used again dereferenced it (a crash): a move leaves the source sharing the cache instead,
// as detectors may (one per thread, say).
struct shared_cache {
    std::shared_ptr<lambda_cache> p;
    explicit shared_cache(std::shared_ptr<lambda_cache> q) noexcept : p(std::move(q)) {}
    shared_cache(const shared_cache&) = default;
    shared_cache& operator=(const shared_cache&) = default;
    shared_cache(shared_cache&& o) noexcept : p(o.p) {}
    shared_cache& operator=(shared_cache&& o) noexcept {
        p = o.p;
        return *this;
    }
};

// The detector's scratch: what one frame leaves for the next to reuse, kept apart from its
// options, executor and lambda cache so that a move leaves the source a fresh one
// (take_scratch, scratch.hpp).
struct detector_scratch {
    struct half_state {
        std::vector<float> sd;
        std::vector<std::uint8_t> label;
        sd_histogram hist;                   // of the valid standard deviations
        std::vector<float> select_f;         // median selection scratch
        std::vector<double> select;          // MAD selection scratch
        std::vector<std::uint32_t> order;    // ESD candidates, removal order
        std::vector<std::uint64_t> keys;     // sort keys for that order
        std::vector<std::uint64_t> keys_tmp; // and the radix sort's scratch
        std::vector<double> removed;         // their standard deviations
        summary rest;                        // summary of the valid pixels never removed
        std::size_t valid = 0;
        std::vector<std::uint32_t> fix;      // pixels to rebuild, row-major
        std::vector<std::uint32_t> cross;    // those rebuilt from the other half
        std::vector<double> cross_values;    // their new values, entry x channel
        std::vector<std::uint8_t> cross_kept;  // per entry: the other half keeps an outlier
                                               // there (read by neither half's spatial rebuild)
        std::vector<std::uint8_t> decision;  // per entry of a list: its outcome (chunked stages)
        std::vector<double> log_p;           // per outlier (order): the p-value (log) of a one-half
                                             // firefly, for the frame's decision; NaN: not one
        std::vector<stddev_counts> band_counts;  // the standard-deviation pass per row band
        std::vector<float> before;           // return_energy: colour of the pixels to rebuild
        std::vector<std::uint8_t> added;     // return_energy with a mask: light added here
        std::vector<std::uint8_t> outside;   // return_energy: the ignored pixels (any there)
        std::vector<std::uint32_t> held;     // return_energy: pixels that hold some of the rare
        std::vector<float> held_values;      // light already, how much (RGB), and of how many
        std::vector<std::uint8_t> held_shares;  // shares (list_held_light)
        std::vector<std::uint32_t> left;     // pixels to rebuild that nothing reached (this frame)
        std::vector<std::uint32_t> dropped;  // find_dropped: this half's dropped pixels, row-major
        std::vector<std::uint32_t> implausible;  // find_implausible: its implausible pixels, row-major
        reconstruct_scratch recon;
    };

    half_state halves_[2];
    variance_calibration calibration_;
    std::vector<std::uint32_t> pairs_;
    local_test_scratch local_scratch_;
    local_test_result local_result_;
    dropped_scratch dropped_scratch_;
    std::vector<dropped_pixel> dropped_found_;
    std::vector<std::vector<std::uint64_t>> implausible_found_;  // per row band: 2 pixel + half
    std::vector<double> frame_log_p_;  // the one-half fireflies' p-values (log), for the frame's level
    std::vector<double> pair_log_p_;   // per pair and half: the p-value (log) of its excess; NaN: none
    std::vector<double> pair_base_;    // per pair: the level its ordinary samples give (pair_rise)
    std::vector<std::pair<std::uint32_t, double>> risen_;  // return_energy: pairs with a level, by pixel
    std::vector<double> pair_level_log_p_;  // per pair: its level against its neighbourhood's
    std::vector<double> pair_family_;  // keep_pairs_within_noise: the p-values its level comes from
    std::vector<std::uint64_t> visit_, visit_tmp_;  // for_entries_by_row
    struct strict_pair {               // a pair kept by the strict limit, as it was judged
        std::uint32_t pixel;
        double sum, se;                // its rise (pair_rise) and standard error
    };
    std::vector<strict_pair> spots_;   // decide_pairs: the strict highlights, by pixel
    energy_scratch energy_;            // return_energy: one for both halves, which take turns
    density_scratch density_;          // return_energy: the density scale's arrays
    std::vector<density_return::light> density_light_;  // and the light it gives
    std::vector<float> density_excess_[2];  // and each half's removed excess, by list entry
    std::vector<std::uint32_t> density_entry_[2];  // and each pixel's entry, 1 + its index (0: none)
    double frame_level_ = 0;           // log of the largest p-value the frame's decision keeps
};
}  // namespace detail

class detector : private detail::detector_scratch {
public:
    // lambdas: a cache shared with other detectors (one per thread, say); null: its own.
    explicit detector(detector_options options = {}, executor exec = {},
                      std::shared_ptr<lambda_cache> lambdas = nullptr)
        : options_(options), exec_(std::move(exec)),
          cache_(lambdas ? std::move(lambdas) : std::make_shared<lambda_cache>()) {}
    // A moved-from detector stays usable: options and executor as moved, scratch as a fresh
    // detector's, and the lambda cache shared with the detector it was moved to.
    detector(const detector&) = default;
    detector& operator=(const detector&) = default;
    detector(detector&& o) noexcept
        : detail::detector_scratch(detail::take_scratch<detail::detector_scratch>(o)), options_(o.options_),
          exec_(std::move(o.exec_)), cache_(o.cache_) {}
    detector& operator=(detector&& o) noexcept {
        if (this == &o) return *this;
        static_cast<detail::detector_scratch&>(*this) = detail::take_scratch<detail::detector_scratch>(o);
        options_ = o.options_;
        exec_ = std::move(o.exec_);
        cache_ = o.cache_;
        return *this;
    }

    const detector_options& options() const noexcept { return options_; }
    void set_options(const detector_options& o) { options_ = o; }
    void set_executor(executor e) { exec_ = std::move(e); }
    lambda_cache& lambdas() noexcept { return *cache_.p; }
    // The cache, to hand to another detector.
    const std::shared_ptr<lambda_cache>& shared_lambdas() const noexcept { return cache_.p; }

    std::size_t scratch_bytes() const noexcept {
        std::size_t n = cache_.p->bytes() + local_scratch_.bytes() + local_result_.bytes() + calibration_.bytes() +
                        pairs_.capacity() * sizeof(std::uint32_t) +
                        (pair_log_p_.capacity() + pair_level_log_p_.capacity() + pair_base_.capacity() +
                         pair_family_.capacity()) * sizeof(double) +
                        (visit_.capacity() + visit_tmp_.capacity()) * sizeof(std::uint64_t) +
                        frame_log_p_.capacity() * sizeof(double) + spots_.capacity() * sizeof(strict_pair) +
                        dropped_scratch_.bytes() + dropped_found_.capacity() * sizeof(dropped_pixel) +
                        risen_.capacity() * sizeof(std::pair<std::uint32_t, double>);
        for (const auto& f : implausible_found_) n += f.capacity() * sizeof(std::uint64_t);
        for (const auto& h : halves_)
            n += h.sd.capacity() * sizeof(float) + h.label.capacity() +
                 h.hist.bytes() + h.select_f.capacity() * sizeof(float) +
                 h.select.capacity() * sizeof(double) + h.order.capacity() * sizeof(std::uint32_t) +
                 h.removed.capacity() * sizeof(double) + (h.keys.capacity() + h.keys_tmp.capacity()) * sizeof(std::uint64_t) +
                 (h.fix.capacity() + h.cross.capacity() + h.left.capacity() + h.dropped.capacity() +
                  h.implausible.capacity()) * sizeof(std::uint32_t) +
                 h.cross_values.capacity() * sizeof(double) + h.decision.capacity() +
                 h.band_counts.capacity() * sizeof(stddev_counts) + h.before.capacity() * sizeof(float) + h.added.capacity() +
                 h.outside.capacity() + h.cross_kept.capacity() +
                 h.held.capacity() * sizeof(std::uint32_t) + h.held_values.capacity() * sizeof(float) + h.held_shares.capacity() +
                 h.recon.bytes();
        return n + energy_.bytes() + density_.bytes() + density_light_.capacity() * sizeof(density_return::light) +
               (density_excess_[0].capacity() + density_excess_[1].capacity()) * sizeof(float) +
               (density_entry_[0].capacity() + density_entry_[1].capacity()) * sizeof(std::uint32_t);
    }

    // Cleans both halves in place and reports. mask_a / mask_b (optional, 1 channel, the
    // frame's size) receive mask_bits per pixel.
    template <class C, class V, class A>
    frame_report process(const half_buffer<C, V, A>& a, const half_buffer<C, V, A>& b,
                         const image_view<std::uint8_t>& mask_a = {},
                         const image_view<std::uint8_t>& mask_b = {}) {
        static_assert(!std::is_const_v<C> && !std::is_const_v<V>,
                      "process() cleans the half buffers in place: use detect() on const views");
        return run(a, b, mask_a, mask_b, options_.reconstruct);
    }

    // Detection only: the report and the masks (what process() would rebuild is marked
    // firefly / nonfinite), nothing written to the half buffers, which may be const.
    template <class C, class V, class A>
    frame_report detect(const half_buffer<C, V, A>& a, const half_buffer<C, V, A>& b,
                        const image_view<std::uint8_t>& mask_a = {},
                        const image_view<std::uint8_t>& mask_b = {}) {
        return run(a, b, mask_a, mask_b, false);
    }

private:
    // Label byte: pixel_class in the low two bits, then these flags.
    static constexpr std::uint8_t strict_bit = 4;       // highlight check, transient
    static constexpr std::uint8_t no_geometry_bit = 4;  // the spatial rebuild, transient (after
                                                        // the highlight check cleared strict_bit)
    static constexpr std::uint8_t outlier_bit = 8;
    static constexpr std::uint8_t highlight_bit = 16;
    static constexpr std::uint8_t fix_bit = 32;          // rebuild spatially
    static constexpr std::uint8_t consistent_bit = 64;
    static constexpr std::uint8_t other_half_bit = 128;  // rebuilt from the other half

    struct neighbourhood {             // neighbourhood_at
        detail::pooled_estimate pooled;  // the local test's r~ at the pixel
        double around = 0;               // the neighbourhood's level (noise_floor)
        double line = 0;                 // a line's through the pixel, as `around` (0: none)
        double spread = 0;               // its lower halves' MAD over their median
        double lower_noise = std::numeric_limits<double>::quiet_NaN();  // pairs: the lower halves' r
        std::size_t lower_count = 0;     // ... over this many neighbours
        // three standard deviations above the neighbourhood's level (relative terms)
        double detail_above() const { return around * std::exp(3.0 * std::sqrt(pooled.typical)); }
        // its lower halves spread more than three of the MADs a smooth neighbourhood gives
        // (0.6745 x 0.826 sqrt(t): the MAD of a normal's, and the sd of the lower of two
        // normal draws, relative terms)
        bool mixed() const { return spread > 3.0 * 0.6745 * 0.8257 * std::sqrt(pooled.typical); }
        // a line of detail runs through the pixel (neighbourhood_line_level)
        bool line_through() const { return detail_above() < line; }
        // the level the pixel's ordinary samples give, where the neighbourhood says it: known,
        // smooth, no line through the pixel (0: it does not say)
        double smooth_level() const {
            return pooled.nu == pooled.nu && !mixed() && !line_through() && around > 0 ? around : 0.0;
        }
    };

    static frame_report& fail(frame_report& r, status st) {
        r.error = st;
        return r;
    }
    static std::uint8_t cls(std::uint8_t label) noexcept { return label & pixel_class_bits; }
    static constexpr std::uint8_t valid_class = static_cast<std::uint8_t>(pixel_class::valid);
    static constexpr std::uint8_t ignored_class = static_cast<std::uint8_t>(pixel_class::ignored);
    static constexpr std::uint8_t nonfinite_class = static_cast<std::uint8_t>(pixel_class::nonfinite);
    static std::size_t index(int x, int y, int w) noexcept {
        return static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x);
    }

    template <class C, class V, class A>
    frame_report run(const half_buffer<C, V, A>& a, const half_buffer<C, V, A>& b,
                     const image_view<std::uint8_t>& mask_a, const image_view<std::uint8_t>& mask_b, bool clean) {
        frame_report rep;
        if (status st = check_inputs(a, b, mask_a, mask_b); !st.ok()) return fail(rep, st);
        const half_buffer<C, V, A>* hb[2] = {&a, &b};
        const image_view<std::uint8_t>* masks[2] = {&mask_a, &mask_b};
        // Stage 1 (parallel): standard deviations, bound, ESD candidates, per half.
        detail::stage_clock clock(rep.stage_ms);
        stddev_bands(hb);
        // (every frame: one before, with other options, may have left some)
        for (half_state& s : halves_) s.implausible.clear(), s.dropped.clear();
        if (options_.find_implausible) mark_implausible(a, b);
        exec_.run(2, [&](std::size_t h) { detect_candidates(halves_[h], rep.half[h]); });
        if (options_.find_dropped) mark_dropped(a, b, rep);
        clock.lap(frame_report::candidates);
        // Stage 2 (serial): the ESD decision, reading and filling the lambda cache.
        {
            const std::lock_guard<std::mutex> lock(cache_.p->mutex());
            const std::size_t before = cache_.p->computed();
            for (int h = 0; h < 2; ++h) decide(halves_[h], rep.half[h]);
            rep.lambdas_computed = cache_.p->computed() - before;
        }
        clock.lap(frame_report::esd);
        // Stage 3: the variance calibration, the local test, the highlight check.
        rep.variance_calibration = calibrate(a, b);
        for (int h = 0; h < 2; ++h) halves_[h].log_p.assign(rep.half[h].outliers, std::numeric_limits<double>::quiet_NaN());
        if (options_.local_test) add_local_flags(a, b, rep);
        clock.lap(frame_report::local);
        check_highlights(a, b, rep);
        exec_.run(2, [&](std::size_t h) { mark_fixes(halves_[h], rep.half[h]); });
        clock.lap(frame_report::highlights);
        // Stage 4 (parallel): what to rebuild; then the other half's estimates, all computed
        // before any is written; then writes, spatial reconstruction and masks.
        const bool cross = clean && options_.rebuild == rebuild_source::other_half;
        if (cross)
            for (int h = 0; h < 2; ++h) stage_cross_half(*hb[h], *hb[1 - h], halves_[h], halves_[1 - h], rep);
        clock.lap(frame_report::other_half);
        const bool energy = clean && options_.return_energy;
        if (energy) exec_.run(2, [&](std::size_t h) { keep_before(*hb[h], halves_[h]); });
        exec_.run(2, [&](std::size_t h) { finish(*hb[h], halves_[h], *masks[h], rep.half[h], clean, cross); });
        if (energy) {
            risen_.clear();
            for (std::size_t j = 0; j < pairs_.size(); ++j)
                if (pair_base_[j] > 0) risen_.emplace_back(pairs_[j], pair_base_[j]);
            std::sort(risen_.begin(), risen_.end());
            energy_totals density[2];
            give_density_back(hb, masks, density);
            for (int h = 0; h < 2; ++h) {
                give_energy_back(*hb[h], *hb[1 - h], halves_[h], halves_[1 - h], *masks[h], rep.half[h]);
                rep.half[h].energy_removed += density[h].removed;
                rep.half[h].energy_returned += density[h].returned;
            }
        }
        clock.lap(frame_report::rebuild);
        // A frame that could not be cleaned says so: pixels left with no source (an all-NaN
        // frame) make the reconstruction's status non-ok. A frame whose only other pixels are
        // black is cleaned (its NaN take the black they are among) and is ok.
        for (const half_report& hr : rep.half)
            if (!hr.reconstruction.ok()) rep.error = hr.reconstruction;
        rep.scratch_bytes = scratch_bytes();
        return rep;
    }

    template <class C, class V, class A>
    status check_inputs(const half_buffer<C, V, A>& a, const half_buffer<C, V, A>& b,
                        const image_view<std::uint8_t>& mask_a, const image_view<std::uint8_t>& mask_b) const {
        if (status st = check_options(options_); !st.ok()) return st;
        const half_buffer<C, V, A>* hb[2] = {&a, &b};
        const image_view<std::uint8_t>* masks[2] = {&mask_a, &mask_b};
        for (int h = 0; h < 2; ++h) {
            if (status st = check_half_views(hb[h]->color, hb[h]->variance, hb[h]->alpha); !st.ok()) return st;
            if (hb[h]->color.channels() > 4)
                return status{errc::channel_mismatch, "colour needs 1 to 4 channels"};
            if (!masks[h]->empty() && (!same_size(*masks[h], a.color) || masks[h]->channels() != 1))
                return status{errc::size_mismatch, "a mask must be 1 channel, frame-sized"};
        }
        if (!same_size(a.color, b.color)) return status{errc::size_mismatch, "the two halves differ in size"};
        if (a.color.channels() != b.color.channels() || a.variance.channels() != b.variance.channels())
            return status{errc::channel_mismatch, "the two halves differ in channels"};
        if (status st = detail::check_frame_extent(a.color); !st.ok()) return st;
        return check_no_aliasing(a, b, mask_a, mask_b);
    }

    // Every view process() writes must be apart from every other view it reads or writes:
    // the halves run on two threads, and a pixel read after it was rebuilt would change results.
    template <class C, class V, class A>
    static status check_no_aliasing(const half_buffer<C, V, A>& a, const half_buffer<C, V, A>& b,
                                    const image_view<std::uint8_t>& ma, const image_view<std::uint8_t>& mb) {
        if (views_may_overlap(a.color, b.color) || views_may_overlap(a.color, b.variance) ||
            views_may_overlap(a.variance, b.color) || views_may_overlap(a.variance, b.variance) ||
            views_may_overlap(a.color, a.variance) || views_may_overlap(b.color, b.variance))
            return status{errc::aliased_views, "colour and variance views of the two halves must not share memory"};
        const half_buffer<C, V, A>* hb[2] = {&a, &b};
        for (const auto* h : hb) {
            for (const auto* o : hb)
                if (views_may_overlap(h->color, o->alpha) || views_may_overlap(h->variance, o->alpha))
                    return status{errc::aliased_views, "an alpha view shares memory with a colour or variance view"};
            for (const auto* m : {&ma, &mb})
                if (views_may_overlap(h->color, *m) || views_may_overlap(h->variance, *m) ||
                    views_may_overlap(h->alpha, *m))
                    return status{errc::aliased_views, "a mask shares memory with another view"};
        }
        if (views_may_overlap(ma, mb)) return status{errc::aliased_views, "the two masks share memory"};
        return ok_status();
    }

    template <class C, class V, class A>
    void stddev_bands(const half_buffer<C, V, A>* const* hb) {
        const std::size_t bands = detail::stddev_bands(hb[0]->color.height());
        for (half_state& s : halves_) {
            s.sd.resize(hb[0]->color.pixel_count());
            s.label.resize(s.sd.size());
            s.band_counts.assign(bands, stddev_counts{});
        }
        exec_.run(2 * bands, [&](std::size_t t) {  // both halves' bands in one run
            const std::size_t which = t / bands, band = t % bands;
            const half_buffer<C, V, A>& b = *hb[which];
            half_state& s = halves_[which];
            s.band_counts[band] = detail::stddev_band(b.color, b.variance, b.alpha, options_.reduction, s.sd.data(),
                                                      s.label.data(), band);
        });
    }

    // find_dropped (dropped.hpp): a pixel black in one half (every colour channel 0) where the
    // other is valid is a lone black; those the window test finds become non-finite pixels of
    // their half (left out of every statistic, as black ones were, and rebuilt from the other
    // half where it is usable, spatially else), listed for their masks and counted.
    template <class C, class V, class A>
    void mark_dropped(const half_buffer<C, V, A>& a, const half_buffer<C, V, A>& b, frame_report& rep) {
        const half_buffer<C, V, A>* hb[2] = {&a, &b};
        const int w = a.color.width(), h = a.color.height();
        if (rep.half[0].ignored == 0 && rep.half[1].ignored == 0) return;
        const std::uint8_t* lab[2] = {halves_[0].label.data(), halves_[1].label.data()};
        auto black_at = [&](int x, int y) -> std::uint64_t {
            const std::size_t i = index(x, y, w);
            for (int k = 0; k < 2; ++k)
                if (cls(lab[k][i]) == ignored_class && cls(lab[1 - k][i]) == valid_class &&
                    detail::colour_is_black(hb[k]->color, x, y))
                    return std::uint64_t{1} << k;
            return 0;
        };
        (void)find_dropped_masks(w, h, 2, options_.alpha, black_at, dropped_scratch_, exec_, dropped_found_);
        for (const dropped_pixel& d : dropped_found_) {
            half_state& s = halves_[d.buffer];
            s.label[d.pixel] = static_cast<std::uint8_t>((s.label[d.pixel] & ~pixel_class_bits) | nonfinite_class);
            s.sd[d.pixel] = std::numeric_limits<float>::quiet_NaN();
            s.dropped.push_back(d.pixel);
            ++rep.half[d.buffer].dropped;
            --rep.half[d.buffer].ignored;
        }
    }

    // find_implausible (implausible.hpp): where both halves are valid, the half whose value the
    // other shows implausible becomes a non-finite pixel of its half (left out of every
    // statistic, rebuilt from the other half), listed and counted (detect_candidates). The
    // variances are the standard deviations' squares (the test is far from any rounding), in
    // row bands on the executor, listed in pixel order.
    template <class C, class V, class A>
    void mark_implausible(const half_buffer<C, V, A>& a, const half_buffer<C, V, A>& b) {
        const int w = a.color.width(), h = a.color.height();
        const double bound = detail::implausible_bound(a.color.pixel_count(), options_.alpha);
        const std::size_t bands = detail::stddev_bands(h);
        implausible_found_.assign(bands, {});
        exec_.run(bands, [&](std::size_t band) {
            const int y0 = static_cast<int>(band) * stddev_band_rows;
            const int y1 = (std::min)(h, y0 + stddev_band_rows);
            const std::uint8_t* lab[2] = {halves_[0].label.data(), halves_[1].label.data()};
            const float* sd[2] = {halves_[0].sd.data(), halves_[1].sd.data()};
            for (int y = y0; y < y1; ++y)
                for (int x = 0; x < w; ++x) {
                    const std::size_t i = index(x, y, w);
                    if (cls(lab[0][i]) != valid_class || cls(lab[1][i]) != valid_class) continue;
                    const double sa = static_cast<double>(sd[0][i]), sb = static_cast<double>(sd[1][i]);
                    const int k = detail::implausible_half(mean_colour(a.color, x, y), mean_colour(b.color, x, y),
                                                           sa * sa, sb * sb, bound);
                    if (k >= 0) implausible_found_[band].push_back(2 * static_cast<std::uint64_t>(i) + static_cast<std::uint64_t>(k));
                }
        });
        for (const std::vector<std::uint64_t>& found : implausible_found_)
            for (const std::uint64_t f : found) {
                const std::size_t i = static_cast<std::size_t>(f / 2);
                half_state& s = halves_[f % 2];
                s.label[i] = static_cast<std::uint8_t>((s.label[i] & ~pixel_class_bits) | nonfinite_class);
                s.sd[i] = std::numeric_limits<float>::quiet_NaN();
                s.implausible.push_back(static_cast<std::uint32_t>(i));
            }
    }

    void detect_candidates(half_state& s, half_report& r) {
        const std::size_t n = s.sd.size();
        stddev_counts c;
        for (const stddev_counts& b : s.band_counts) c += b;
        c.valid -= s.implausible.size();  // counted valid by their band, then marked
        s.hist.build(s.sd.data(), n);
        r.pixels = n;
        r.implausible = s.implausible.size();
        r.valid = c.valid;
        r.ignored = c.ignored;
        r.nonfinite = c.nonfinite;
        r.negative_variance = c.negative_variance;
        s.valid = c.valid;
        const float* sd = s.sd.data();  // valid: >= 0; ignored: -1; non-finite: NaN
        // Modified Z-score bound (exact median and MAD; see bound.hpp for the definition).
        bound_result b;
        b.threshold = options_.bound_threshold;
        b.n = c.valid;
        if (c.valid > 0) {
            b.median = s.hist.median(sd, n, s.select_f);
            b.mad = s.hist.mad(sd, n, b.median, s.select);
            set_bound_scale(b, [&] {
                return detail::blocked_sum(n, [&](std::size_t i) {
                           return sd[i] >= 0 ? std::fabs(static_cast<double>(sd[i]) - b.median) : 0.0;
                       }) / static_cast<double>(c.valid);
            });
        }
        // A half with no valid pixel has no median: NaN says so (0 would read as a frame of
        // noiseless pixels).
        r.median = c.valid > 0 ? b.median : std::numeric_limits<double>::quiet_NaN();
        r.mad = c.valid > 0 ? b.mad : std::numeric_limits<double>::quiet_NaN();
        // The bound's test as one float comparison: cut is the smallest float x with
        // b.above(x), found exactly (above() is monotone in x).
        float cut = HUGE_VALF;
        if (b.scale > 0) {
            const double guess = b.median + b.threshold * b.scale;
            cut = guess <= static_cast<double>(FLT_MAX) ? static_cast<float>(guess) : HUGE_VALF;
            while (cut > 0 && b.above(static_cast<double>(std::nextafter(cut, 0.0f))))
                cut = std::nextafter(cut, 0.0f);
            while (std::isfinite(cut) && !b.above(static_cast<double>(cut)))
                cut = std::nextafter(cut, HUGE_VALF);
        }
        const double med = b.median;
        // One pass: the candidates (>= cut: exactly the values the bound counts, the top
        // values) and the shifted sums of every other valid value, in fixed blocks.
        double s1 = 0, s2 = 0;
        std::size_t rest_n = 0;
        detail::shifted_sums_below(sd, n, cut, med, s1, s2, rest_n, s.order);
        r.bound = s.order.size();
        // Removal order: largest first, lower index first among equals. Packed keys (the bits
        // of a float >= 0 order like the float), put in order by a stable radix sort of their
        // high words: the list comes in index order, so equals keep it (std::sort's order of
        // the whole keys).
        s.keys.resize(s.order.size());
        for (std::size_t j = 0; j < s.order.size(); ++j) {
            std::uint32_t bits;
            std::memcpy(&bits, &sd[s.order[j]], 4);
            s.keys[j] = (static_cast<std::uint64_t>(~bits) << 32) | s.order[j];
        }
        detail::sort_by_high_word(s.keys, s.keys_tmp);
        for (std::size_t j = 0; j < s.order.size(); ++j) s.order[j] = static_cast<std::uint32_t>(s.keys[j]);
        // At most n - 2 steps: candidates beyond that rejoin the rest.
        const std::size_t m = (std::min)(s.order.size(), s.valid >= 2 ? s.valid - 2 : 0);
        for (std::size_t j = m; j < s.order.size(); ++j) {
            const double d = static_cast<double>(sd[s.order[j]]) - med;
            s1 += d;
            s2 += d * d;
            ++rest_n;
        }
        s.order.resize(m);
        s.removed.resize(m);
        for (std::size_t j = 0; j < m; ++j) s.removed[j] = static_cast<double>(sd[s.order[j]]);
        s.rest = summary{};
        if (rest_n > 0) {
            s.rest.count = rest_n;
            s.rest.mean = med + s1 / static_cast<double>(rest_n);
            s.rest.m2 = (std::max)(0.0, s2 - s1 * s1 / static_cast<double>(rest_n));
        }
    }

    void decide(half_state& s, half_report& r) {
        esd_options o;
        o.alpha = options_.alpha;
        o.max_outliers = s.order.size();
        o.method = options_.lambdas;
        esd_result res;
        if (!s.order.empty())
            detail::esd_from_removals(s.removed.data(), s.order.size(), s.rest, s.valid, o, *cache_.p, res);
        r.outliers = res.outliers;
        for (std::size_t j = 0; j < res.outliers; ++j) s.label[s.order[j]] |= outlier_bit;
    }

    // The factor that turns the given variance into a variance of the pixel mean, from
    // (A - B)^2 / (vA + vB) over ordinary pixels on a lattice of about 16k pixels, whatever
    // the resolution: a median of that many ratios is good to ~1%, and no one pixel moves it.
    // The lattice is laid from the nearer edge of each axis, by one rule for both: a flipped
    // or transposed frame samples the flipped or transposed pixels (from one edge, a 400-wide
    // frame at step 2 took the odd columns, and flipped the even ones: the Cycles caustics'
    // factor 1.1197 against 1.0910, and 36 decisions at the margin went the other way).
    template <class C, class V, class A>
    double calibrate(const half_buffer<C, V, A>& a, const half_buffer<C, V, A>& b) {
        const std::uint8_t* lab[2] = {halves_[0].label.data(), halves_[1].label.data()};
        const int w = a.color.width(), hgt = a.color.height();
        const int nc = colour_channels(a.color.channels()), nv = a.variance.channels();
        calibration_.clear();
        const double cells = static_cast<double>(w) * static_cast<double>(hgt) / 16384.0;
        int sx = 1, sy = 1;
        detail::lattice_steps(cells, w, hgt, sx, sy);
        auto on_lattice = [](int v, int n, int step) { return (std::min)(v, n - 1 - v) % step == step / 2; };
        for (int y = 0; y < hgt; ++y) {
            if (!on_lattice(y, hgt, sy)) continue;
            for (int x = 0; x < w; ++x) {
                const std::size_t i = index(x, y, w);
                if (!on_lattice(x, w, sx) || lab[0][i] != valid_class || lab[1][i] != valid_class) continue;
                for (int c = 0; c < nc; ++c)
                    calibration_.add(a.color.load(x, y, c), b.color.load(x, y, c),
                                     a.variance.load(x, y, nv == 1 ? 0 : c), b.variance.load(x, y, nv == 1 ? 0 : c));
            }
        }
        return calibration_.factor();
    }

    template <class C>
    static double mean_colour(const image_view<C>& v, int x, int y) {
        const int nc = colour_channels(v.channels());
        double s = 0;
        for (int c = 0; c < nc; ++c) s += v.load(x, y, c);
        return s / nc;
    }
    template <class V>
    double reduced_variance(const image_view<V>& v, int x, int y) const {
        bool nonfinite = false, negative = false;
        return detail::reduce_variance(&v(x, y, 0), v.channel_stride(), v.channels(), options_.reduction, nonfinite,
                                       negative);
    }

    template <class C, class V, class A>
    void check_highlights(const half_buffer<C, V, A>& a, const half_buffer<C, V, A>& b, frame_report& rep) {
        const std::uint8_t* lab1 = halves_[1].label.data();
        pairs_.clear();  // outliers come from the two lists, not from a pass over the frame
        bool single = false;
        for (std::size_t j = 0; j < rep.half[0].outliers; ++j) {
            const std::uint32_t i = halves_[0].order[j];
            if (lab1[i] & outlier_bit) pairs_.push_back(i);
            else single = true;
        }
        single |= rep.half[1].outliers > pairs_.size();
        rep.both_outliers = pairs_.size();
        if (single) decide_singles(a, b, rep);
        pair_excess(a, b, rep.variance_calibration);
        frame_level(rep);
        decide_pairs(a, b, rep.variance_calibration);
    }

    // The p-value (log) of "this half exceeds the other at (x, y)" for an outlier whose excess
    // passes min_excess_z, else NaN. Two estimates, the smaller doubled (Bonferroni): the
    // excess's normal tail in the other half's noise (as min_excess_z judges it), and where
    // the local test's levels allow, the exact pair test (local_test.hpp). Tried and dropped:
    // the larger of the two (stricter on frames without fireflies, but it lost a fifth of the
    // simulated interior's moderate fireflies, relMSE 0.047 -> 0.061), and the noise taken at
    // the geometric mean of the two levels (the null's level: frames without fireflies at 16
    // samples per half 65 -> 16 of 80 touched, but on the Cycles interior, whose samples are
    // heavier-tailed than any gamma, it kept 100x fireflies: relMSE 0.132 -> 0.197); and the
    // level of a line through the pixel where above the neighbourhood's (the least favourable
    // level, as pair_level_log_p takes it: at 4 samples per half a line pixel whose other half
    // drew low looks like background): frames without fireflies at 4 samples 0.047% -> 0.015%
    // of clean pixel-halves lowered, but the simulated caustics' recall 0.905 -> 0.893 (its
    // streaks are lines that fireflies light) and the Cycles interior 0.1130 -> 0.1146.
    // And the excess's tail under the gamma law (Wilson-Hilferty: cube roots, as buffers.hpp
    // tests; the normal tail on the raw scale is far too thin for a skewed law): frames without
    // fireflies at 4 samples 0.047% -> 0.006% of clean pixel-halves lowered, but the Cycles
    // interior 0.1114 -> 0.181 (its samples are heavier-tailed than any gamma); taken only
    // where the outlier's own relative variance is not above its neighbourhood's (a rare
    // sample carries the Cycles interior's: their own r is 6x the neighbourhood's, at the
    // median, the frames without fireflies' 1.4x), 0.017% and 0.1128, the simulated
    // caustics' recall 0.905 -> 0.891.
    template <class C, class V, class A>
    double excess_log_p(const half_buffer<C, V, A>* hb[2], int h, int x, int y, double cal,
                        const neighbourhood& nb, bool own_variance) const {
        const double l_out = mean_colour(hb[h]->color, x, y), l_other = mean_colour(hb[1 - h]->color, x, y);
        const double v = reduced_variance(hb[1 - h]->variance, x, y);
        const double v_other = noise_floor(v, l_other, l_out, cal, nb, own_variance);
        if (!exceeds_other_half(options_.highlight, l_out, l_other, v_other, cal)) return std::numeric_limits<double>::quiet_NaN();
        double log_p = normal_log_upper_tail(excess_z(l_out, l_other, v_other, cal));
        if (options_.local_test) {
            const int w = hb[0]->color.width();
            const double pair = detail::pair_log_p(local_scratch_, w, x, y, h, nb.pooled);
            if (pair == pair) log_p = (std::min)(log_p, pair) + std::log(2.0);
        }
        return log_p;
    }

    // For every pair (outlier in both halves): does one half carry a firefly on top of the
    // other (p-values, log, two per pair; NaN: no)? Decided with the one-half outliers.
    template <class C, class V, class A>
    void pair_excess(const half_buffer<C, V, A>& a, const half_buffer<C, V, A>& b, double cal) {
        const half_buffer<C, V, A>* hb[2] = {&a, &b};
        const int w = a.color.width();
        pair_log_p_.assign(pairs_.size() * 2, std::numeric_limits<double>::quiet_NaN());
        pair_level_log_p_.assign(pairs_.size(), -HUGE_VAL);  // unknown: the highlight rule alone
        pair_base_.assign(pairs_.size(), 0.0);
        if (!(options_.highlight.min_excess_z > 0)) return;
        for_entries_by_row(pairs_.data(), pairs_.size(), [&](std::size_t j, std::vector<float>& pool) {
            const int x = detail::column_of(pairs_[j], w), y = detail::row_of(pairs_[j], w);
            const neighbourhood nb = neighbourhood_at(x, y, w, a.color.height(), pool, true);  // both halves'
            for (int h = 0; h < 2; ++h)
                pair_log_p_[j * 2 + static_cast<std::size_t>(h)] = excess_log_p(hb, h, x, y, cal, nb, true);
            const double la = mean_colour(a.color, x, y), lb = mean_colour(b.color, x, y);
            pair_level_log_p_[j] = pair_level_log_p(la, lb, nb);
            pair_base_[j] = pair_base(la, lb, nb);
        });
    }

    // The level a pair's ordinary samples give, its rise measured from (pair_rise; 0: none):
    // its neighbourhood's, where that is smooth and both halves stand more than three standard
    // deviations above it. Nearer, the pixel shares its neighbourhood's law (a spot's pixel
    // among its own, whose neighbourhood's level is the spot's) and is judged at its own level.
    // la, lb: the pair's mean colour in each half.
    static double pair_base(double la, double lb, const neighbourhood& nb) {
        return (std::min)(la, lb) > nb.detail_above() ? nb.smooth_level() : 0.0;
    }

    // Does the pair's level stand out from its neighbourhood (the p-value, log; -inf where the
    // neighbourhood cannot tell, and the highlight rule alone decides)? Its mean over both
    // halves against the larger of the neighbourhood's level (noise_floor's) and the brightest
    // direction's through the pixel (neighbourhood_line_level, the same bias undone), each
    // half a gamma mean of the neighbours' lower halves' noise (local_test.hpp:
    // pixel_level_log_p). On a line of detail the direction along it gives the line's level: a
    // line one pixel wide has two of its eight neighbours at its level, so the median is the
    // background's, and a clean line pixel stood out from it (at 4 samples per half, 133 of
    // 262 judged pairs of a frame without fireflies were rebuilt, all on its lines). Elsewhere
    // the brightest of four directions is a slightly higher estimate of the same level, the
    // least favourable of the structures the pixel may lie on, and the test is the more
    // conservative for it: frames without fireflies at 4 samples per half (1024x540) 0.047%
    // of clean pixel-halves lowered, 0.070% with the line's level only where line_through()
    // says a line runs, 0.082% with the neighbourhood's alone (the pair's rise sends more
    // pairs here); a pair of fireflies, far above every direction, is rebuilt as before
    // (dense30 recall 0.956 against 0.957, the Cycles interior 0.1154 against 0.1149).
    // The gamma model needs a positive level (a filter's negative lobe is not a gamma mean) and
    // a relative variance of the mean within what non-negative samples give (at most 1 a
    // channel, 3 for one coloured sample carrying the pixel: above, the variance is not that of
    // the mean).
    static double pair_level_log_p(double la, double lb, const neighbourhood& nb) {
        const double level = 0.5 * (la + lb);
        if (!(nb.lower_noise > 0 && nb.lower_noise <= 3.0) || !(nb.around > 0) || !(level > 0) ||
            !std::isfinite(level))
            return -HUGE_VAL;
        const double reference = (std::max)(nb.around, nb.line);  // (line: 0 where none)
        return detail::pixel_level_log_p(level / reference, 1.0 / nb.lower_noise, nb.lower_count);
    }

    // Pixels that are outliers in both halves. A pair that passes the rule strictly is a
    // highlight; a pair next to such a highlight is held to the looser cluster limit (a real
    // highlight is a spot; pairs of fireflies meeting by chance are not, even side by side
    // on a dense frame, since neither passes the strict limit). A pair with a firefly on one
    // half is kept on the other, but seeds no spot: one half's value says nothing of a
    // highlight that both halves agree on (in a caustic lit by fireflies, such pixels had
    // passed as strict and held the pairs around them to the cluster limit).
    template <class C, class V, class A>
    void decide_pairs(const half_buffer<C, V, A>& a, const half_buffer<C, V, A>& b, double calibration) {
        std::uint8_t* lab[2] = {halves_[0].label.data(), halves_[1].label.data()};
        const highlight_options& ho = options_.highlight;
        const int w = a.color.width(), hgt = a.color.height();
        // 0 no; 1 strict; 2 kept in a cluster, or on one half under the other's firefly
        auto decide_pair = [&](std::size_t j, bool cluster) -> int {
            const std::uint32_t i = pairs_[j];
            const int x = detail::column_of(i, w), y = detail::row_of(i, w);
            double la = mean_colour(a.color, x, y), lb = mean_colour(b.color, x, y);
            double va = reduced_variance(a.variance, x, y), vb = reduced_variance(b.variance, x, y);
            // A firefly may sit on top of a highlight in one half: that half then exceeds the
            // other by far more than the other's noise (and the frame's decision keeps it,
            // frame_level). It is rebuilt, and the other half is judged on its own (as if both
            // halves held its value).
            const bool a_over = kept_by_frame(pair_log_p_[j * 2]);
            const bool b_over = kept_by_frame(pair_log_p_[j * 2 + 1]);
            if (a_over) la = lb, va = vb;
            else if (b_over) lb = la, vb = va;
            const double base = pair_base_[j];
            if (!is_highlight(ho, la, lb, va, vb, calibration, cluster, cluster ? spot_at(x, y, w, hgt) : highlight_spot{}, base))
                return 0;
            if (!a_over) lab[0][i] |= highlight_bit;
            if (!b_over) lab[1][i] |= highlight_bit;
            if (cluster || a_over || b_over) return 2;
            spots_.push_back({i, pair_rise(la, lb, base), pair_standard_error(va, vb, calibration)});
            return 1;
        };
        spots_.clear();
        for (std::size_t j = 0; j < pairs_.size(); ++j)
            if (decide_pair(j, false) == 1) lab[0][pairs_[j]] |= strict_bit;
        std::sort(spots_.begin(), spots_.end(), [](const strict_pair& p, const strict_pair& q) { return p.pixel < q.pixel; });
        int min_pairs[9];
        const double q = static_cast<double>(pairs_.size()) /
                         static_cast<double>((std::max<std::size_t>)(1, halves_[0].valid + halves_[1].valid) / 2 + 1);
        for (int n = 0; n <= 8; ++n) min_pairs[n] = detail::binomial_tail_count(n, q, 1e-3);
        if (ho.cluster_relative_error > ho.max_relative_error)
            for (std::size_t j = 0; j < pairs_.size(); ++j)
                if (!(lab[0][pairs_[j]] & strict_bit) && in_cluster(a, b, pairs_[j], min_pairs, calibration))
                    (void)decide_pair(j, true);
        for (const std::uint32_t i : pairs_) lab[0][i] &= static_cast<std::uint8_t>(~strict_bit);
        keep_pairs_within_noise(lab);
    }

    // The spot around (x, y): its strict neighbours as they were judged (spots_, by pixel).
    highlight_spot spot_at(int x, int y, int w, int hgt) const {
        const std::uint8_t* lab0 = halves_[0].label.data();
        highlight_spot spot;
        int n = 0;
        detail::for_each_neighbour(w, hgt, x, y, 1, [&](std::size_t j) {
            if (!(lab0[j] & strict_bit)) return;
            const std::uint32_t q = static_cast<std::uint32_t>(j);
            const auto it = std::lower_bound(spots_.begin(), spots_.end(), q,
                                             [](const strict_pair& s, std::uint32_t p) { return s.pixel < p; });
            if (it == spots_.end() || it->pixel != q) return;  // (every strict pixel has one)
            spot.sum += it->sum;
            spot.se = (std::max)(spot.se, it->se);
            ++n;
        });
        if (n) spot.sum /= n;
        return spot;
    }

    // In a cluster: next to a strict highlight, or next to more pairs than the frame's
    // density of pairs explains (binomial tail below 1e-3 for the neighbours it has). One-half
    // fireflies among the neighbours (one_half_firefly: one half far above the other's own
    // noise, whatever the frame decided for it) say fireflies are dense here, and there pairs
    // meet side by side by chance (a caustic lit by them, where both counts are high): the
    // pair is then in a cluster only where its strict neighbours outnumber them, or its pairs
    // outnumber them more than twice (by chance, with each half hit at rate p, a neighbour is
    // a pair at p^2 and a one-half firefly at 2p(1 - p): more than twice as many pairs needs
    // p > 4/5). A highlight's neighbours are its own pixels or background, with a firefly
    // among them only at the frame's rate (simulated caustics: recall 0.853 -> 0.905, relMSE
    // 0.0325 -> 0.0285, every highlight of the accuracy tables' scenes kept as before; on
    // other seeds, bench/research/held_out.cpp, 6 of 36 frames lose 1 or 2 spot pixels that
    // drew low beside one-half fireflies). Counting
    // every one-half outlier instead reached 0.907 but broke noisy spots up where one of
    // their pixels was NaN or confident in one half (an outlier in the other only); counting
    // only the one-half outliers decided as fireflies left 0.890 (in a caustic's core the
    // other half's neighbourhood is as noisy as the firefly, and many are kept as consistent).
    // min_pairs[n]: the pairs among n neighbours that chance no longer explains.
    template <class C, class V, class A>
    bool in_cluster(const half_buffer<C, V, A>& a, const half_buffer<C, V, A>& b, std::uint32_t i,
                    const int (&min_pairs)[9], double calibration) const {
        const std::uint8_t* lab[2] = {halves_[0].label.data(), halves_[1].label.data()};
        const int w = a.color.width(), hgt = a.color.height();
        const int x = detail::column_of(i, w), y = detail::row_of(i, w);
        int neighbours = 0, pairs = 0, strict = 0, fireflies = 0;
        detail::for_each_neighbour(w, hgt, x, y, 1, [&](std::size_t j) {
            strict += (lab[0][j] & strict_bit) != 0;
            ++neighbours;
            pairs += (lab[0][j] & outlier_bit) && (lab[1][j] & outlier_bit);
            fireflies += one_half_firefly(a, b, j, calibration);
        });
        if (fireflies > 0) return strict > fireflies || (pairs >= min_pairs[neighbours] && pairs > 2 * fireflies);
        return strict > 0 || pairs >= min_pairs[neighbours];
    }

    // Is pixel j an outlier in one half only that exceeds its other half by more than
    // min_excess_z of that half's own noise (the variance it gives, not its neighbourhood's
    // floor, which is high where fireflies are dense)? What the cluster rule counts as a firefly
    // among a pair's neighbours. Not: an outlier kept as a highlight, one whose other half is
    // non-finite or dropped (nothing to compare: a failed bucket says nothing of fireflies), or a
    // highlight pixel that one half's sample spread kept under the global test's threshold (the
    // halves agree: a spot's own pixel).
    template <class C, class V, class A>
    bool one_half_firefly(const half_buffer<C, V, A>& a, const half_buffer<C, V, A>& b, std::size_t j,
                          double calibration) const {
        const std::uint8_t* lab[2] = {halves_[0].label.data(), halves_[1].label.data()};
        const bool oa = lab[0][j] & outlier_bit, ob = lab[1][j] & outlier_bit;
        if (oa == ob) return false;
        const int h = oa ? 0 : 1;
        if ((lab[h][j] & highlight_bit) || cls(lab[1 - h][j]) == nonfinite_class) return false;
        const half_buffer<C, V, A>* hb[2] = {&a, &b};
        const int w = a.color.width();
        const int x = detail::column_of(j, w), y = detail::row_of(j, w);
        return exceeds_other_half(options_.highlight, mean_colour(hb[h]->color, x, y),
                                  mean_colour(hb[1 - h]->color, x, y), reduced_variance(hb[1 - h]->variance, x, y),
                                  calibration);
    }

    // A pair that is no highlight is rebuilt only where its level stands out from its
    // neighbourhood at the level of Benjamini-Hochberg over the frame's one-half decisions'
    // p-values and these (fdr.hpp; the one-half decisions keep their own level, frame_level).
    // Where it does not, its outlying standard deviations are the neighbourhood's noise, not
    // two fireflies that met: both halves are kept (consistent). The highlight rule is a bound,
    // not a test: at 4 samples per half of exponential samples an ordinary pixel's halves
    // carry one sample each as often as not (simulated frames without fireflies: 0.046% of
    // the clean pixel-halves rebuilt as pairs, 0.024% now). A firefly on a highlight (one half
    // over the other) is decided as before; a pair whose neighbourhood cannot tell is rebuilt.
    void keep_pairs_within_noise(std::uint8_t* const (&lab)[2]) {
        const std::size_t tested = (std::max<std::size_t>)(1, halves_[0].valid + halves_[1].valid);
        auto judged = [&](std::size_t j) {  // no highlight, no firefly on one
            const std::uint32_t i = pairs_[j];
            return !((lab[0][i] | lab[1][i]) & highlight_bit) && !kept_by_frame(pair_log_p_[j * 2]) &&
                   !kept_by_frame(pair_log_p_[j * 2 + 1]);
        };
        // the frame's family: the one-half decisions' p-values and these
        pair_family_.assign(frame_log_p_.begin(), frame_log_p_.end());
        for (std::size_t j = 0; j < pairs_.size(); ++j)
            if (judged(j) && pair_level_log_p_[j] != -HUGE_VAL)  // tested: -inf is "cannot tell"
                pair_family_.push_back(pair_level_log_p_[j]);
        if (pair_family_.size() == frame_log_p_.size()) return;  // no pair to judge
        const double level = bh_log_threshold(pair_family_, tested, options_.alpha);
        for (std::size_t j = 0; j < pairs_.size(); ++j) {
            if (!judged(j) || pair_level_log_p_[j] == -HUGE_VAL || !(pair_level_log_p_[j] > level)) continue;
            lab[0][pairs_[j]] |= consistent_bit;
            lab[1][pairs_[j]] |= consistent_bit;
        }
    }

    // Outliers of one half only: kept when they do not stand out against the other half.
    // Where the other half is non-finite (a failed bucket) there is nothing to compare
    // with: the outlier is judged on its own relative error, as the pair rule would judge
    // two halves holding its value (a line of detail passes, a lone firefly sample does not).
    // Tried: an outlier kept here whose other half also stands out from its neighbourhood
    // (pair_level_log_p of that half alone below 0.01) judged as a pair (both rebuilt unless a
    // highlight): the Cycles interior 0.1114 -> 0.1084 (its worst kept pixels hold a moderate
    // firefly in each half, one of them under the global test), the simulated interior 0.0181
    // -> 0.0179, but frames without fireflies at 4 samples per half lowered 0.047% -> 0.048%
    // of their clean pixel-halves and kept 0.9965 -> 0.9960 of their highlights; at 1e-5,
    // nearer a frame-wide level, the Cycles interior 0.1109.
    template <class C, class V, class A>
    void decide_singles(const half_buffer<C, V, A>& a, const half_buffer<C, V, A>& b, const frame_report& rep) {
        std::uint8_t* lab[2] = {halves_[0].label.data(), halves_[1].label.data()};
        const half_buffer<C, V, A>* hb[2] = {&a, &b};
        const int w = a.color.width();
        const double cal = rep.variance_calibration;
        const highlight_rule rule = options_.highlight.rule;
        const bool judges_confidence = rule == highlight_rule::confident || rule == highlight_rule::confident_and_agree;
        // The bit each outlier gains (or 0), decided from labels that no decision changes, in
        // chunks across the executor; then written.
        auto decide = [&](int h, std::uint32_t i, std::vector<float>& pool, double& log_p) -> std::uint8_t {
            if (lab[1 - h][i] & outlier_bit) return 0;  // a pair, decided above
            const int x = detail::column_of(i, w), y = detail::row_of(i, w);
            if (cls(lab[1 - h][i]) == nonfinite_class) {
                const double l = mean_colour(hb[h]->color, x, y), v = reduced_variance(hb[h]->variance, x, y);
                return judges_confidence && is_highlight(options_.highlight, l, l, v, v, cal) ? highlight_bit : 0;
            }
            if (!(options_.highlight.min_excess_z > 0)) return 0;  // the paper: one half is a firefly
            log_p = excess_log_p(hb, h, x, y, cal, neighbourhood_at(x, y, w, hb[h]->color.height(), pool), false);
            return log_p == log_p ? 0 : consistent_bit;
        };
        for (int h = 0; h < 2; ++h) {
            const std::size_t n = rep.half[h].outliers - rep.half[h].local;  // local flags exceed
            std::vector<std::uint8_t>& bits = halves_[h].decision;         // the other half already
            bits.assign(n, 0);
            for_entries_by_row(halves_[h].order.data(), n, [&](std::size_t j, std::vector<float>& pool) {
                halves_[h].log_p[j] = std::numeric_limits<double>::quiet_NaN();
                bits[j] = decide(h, halves_[h].order[j], pool, halves_[h].log_p[j]);
            });
        }
        for (int h = 0; h < 2; ++h)
            for (std::size_t j = 0; j < halves_[h].decision.size(); ++j) lab[h][halves_[h].order[j]] |= halves_[h].decision[j];
    }

    // The frame's decision on the one-half fireflies (fdr.hpp): the global outliers that exceed
    // their other half, the local test's flags and the halves of pairs that exceed the other
    // (a firefly on a highlight), each with its p-value, go to Benjamini-Hochberg at alpha
    // over the tested pixel-halves; the one-half outliers it does not keep are kept as they
    // are (consistent), the pairs judged as pairs. A frame without fireflies is then left
    // alone in 1 - alpha of cases, while a frame with many keeps the per-test levels. Pixels
    // whose other half is non-finite are decided as before.
    void frame_level(frame_report& rep) {
        frame_log_p_.clear();
        // A pair (an outlier in both halves, a local flag among them) is decided by its own
        // p-values (pair_log_p_) and the pair rule alone, not here: its local flag's p-value
        // was once counted here too, twice in the family, and where refused here kept as
        // consistent what decide_pairs rebuilt (a firefly left at 55 beside its other half's
        // 10, or under `agree` copied into the other half).
        auto one_half = [&](int h, std::size_t j) {
            const half_state& s = halves_[h];
            return s.log_p[j] <= 0 && !(s.label[s.order[j]] & (highlight_bit | consistent_bit)) &&
                   !(halves_[1 - h].label[s.order[j]] & outlier_bit);
        };
        for (int h = 0; h < 2; ++h) {
            halves_[h].log_p.resize(rep.half[h].outliers, std::numeric_limits<double>::quiet_NaN());
            for (std::size_t j = 0; j < rep.half[h].outliers; ++j)
                if (one_half(h, j)) frame_log_p_.push_back(halves_[h].log_p[j]);
        }
        for (const double l : pair_log_p_)
            if (l <= 0) frame_log_p_.push_back(l);
        frame_level_ = bh_log_threshold(frame_log_p_, rep.half[0].valid + rep.half[1].valid, options_.alpha);
        rep.single_log_level = frame_level_;
        rep.single_level = frame_level_ == -HUGE_VAL ? 0.0 : std::exp(frame_level_);
        for (int h = 0; h < 2; ++h) {
            half_state& s = halves_[h];
            for (std::size_t j = 0; j < rep.half[h].outliers; ++j) {
                if (one_half(h, j) && !kept_by_frame(s.log_p[j])) {
                    s.label[s.order[j]] |= consistent_bit;
                    ++rep.half[h].frame_kept;
                }
            }
        }
    }
    bool kept_by_frame(double log_p) const noexcept {
        return log_p <= 0 && (std::max)(log_p, -DBL_MAX) <= frame_level_;
    }

    // A list of n entries in fixed chunks on the executor: f(first, last) per chunk. The
    // chunks do not depend on the thread count, so neither does any result.
    template <class F>
    void for_chunks(std::size_t n, F&& f) const {
        constexpr std::size_t chunk = 4096;
        exec_.run((n + chunk - 1) / chunk, [&](std::size_t c) { f(c * chunk, (std::min)(n, (c + 1) * chunk)); });
    }

    // f(j, pool) for the n entries of a list of pixels (list[j], distinct), in chunks as
    // for_chunks, taken in row-major order of the pixels: f reads each pixel's neighbourhood,
    // and the lists come in ESD order, scattered over the frame (by row, neighbours share cache
    // lines). f(j) writes only entry j's results, so the order changes nothing.
    template <class F>
    void for_entries_by_row(const std::uint32_t* list, std::size_t n, F&& f) {
        visit_.resize(n);
        for (std::size_t j = 0; j < n; ++j) visit_[j] = (static_cast<std::uint64_t>(list[j]) << 32) | j;
        detail::sort_by_high_word(visit_, visit_tmp_);
        for_chunks(n, [&](std::size_t k0, std::size_t k1) {
            std::vector<float> pool;
            for (std::size_t k = k0; k < k1; ++k) f(static_cast<std::size_t>(visit_[k] & 0xffffffffu), pool);
        });
    }

    // The other half's variance at (x, y), but never below what its neighbourhood's typical
    // relative variance (the median over both halves, the pixel left out; local_test.hpp)
    // predicts at the pixel's level: one pixel's variance from few heavy-tailed samples is
    // often far too low, and a noisy pixel would then "exceed" its other half. For an outlier
    // of one half only (own_variance false) the other half's variance is also often far too
    // high, where that half drew a rare sample of its own (a moderate firefly below the
    // tests' reach, common where fireflies are dense), and the larger firefly on top of it was
    // then "within the noise". One sample that lifts a mean by e adds ~e^2 to the variance of
    // the mean, so the other half's variance is taken less the square of its rise above the
    // neighbourhood's level (still never below the prediction): the Cycles interior 0.1201 ->
    // 0.1153, frames without fireflies at 4 samples per half 0.066% -> 0.069% of clean
    // pixel-halves lowered (relMSE 0.05998 -> 0.06001). (The prediction alone
    // gave 0.1124, but a pixel noisier than a smooth or noiseless neighbourhood, a silhouette
    // or a glossy pixel against a converged backdrop, then "exceeded" its other half at any
    // difference, and so did one whose level is 0 or below.) A pair keeps the other half's whole
    // variance: a highlight's rise above a dark surround is the highlight's, and so is its
    // noise (with the prediction alone for pairs too, the simulated highlights kept 0.997 ->
    // 0.84). The median, not
    // the mean-corrected estimate: fireflies around the pixel inflate the spread that corrects
    // it. The level is the neighbourhood's, held between the other half's level and the
    // outlier's: without a firefly both halves are noisy draws around the same value, and a
    // pair far apart by chance has its low half below that value (at the low half's level,
    // noise that scales with the level is underestimated: a bright, noisy beam without a
    // single firefly had 12 pixels "exceed" their other half at z > 5); a firefly on a smooth
    // region leaves the neighbourhood at the other half's level (power kept); at an edge or on
    // detail the clamp keeps the level within the pixel's own two values. The neighbourhood's
    // level is the median of each neighbour's lower half (one value a neighbour, so half the
    // local test's count of values; fireflies in one half of many neighbours do not lift it),
    // times exp(0.545 sqrt(t) + t / 2) for the lower half's bias on a clean pixel: the median of
    // the smaller of two normal draws sits 0.545 sd below their mean (Phi(-0.545) = 1 -
    // 1 / sqrt 2), in log terms for relative variance t. Where the neighbourhood is darker than
    // the other half by more than three of that half's standard deviations (log terms), the
    // pixel is detail (a line, a spot, an edge's bright side) and the neighbourhood says nothing
    // of its level; the two halves are then its only estimates, and the level is their
    // geometric mean (the null's: the common value of two draws). Taken at the other half's
    // level there, a clean line pixel whose other half was a low draw "exceeded" it: frames
    // without fireflies at 64 samples per half were changed 21 times in 80 (alpha 0.1), 10 then.
    // The same where the neighbourhood is mixed (its lower halves spread, MAD over median, more
    // than three times what a smooth one's do at relative variance t): a pixel of fine detail
    // between dark and bright neighbours has a median neighbour level below its own but not
    // three standard deviations below, and its other half's low draw again "exceeded" it;
    // null frames (80, alpha 0.1) at 256 / 64 / 16 / 4 samples per half: 4 / 10 / 45 / 76
    // changed -> 3 / 2 / 16 / 50 (at 16: 75 of 320 over seeds 1-160, twice alpha), the
    // renders and simulated scenes within 0.1%. (A small neighbourhood's MAD may call a smooth
    // one mixed by chance: the level there is then the geometric mean, also the null's.)
    // The same where a line runs through the pixel (neighbourhood_line_level: along one
    // direction, the pixels one and two steps away on both sides, by their lower halves, all
    // but one more than three standard deviations above the neighbourhood): a line one pixel
    // wide has two of its eight neighbours at its level, so the median is the background's,
    // and where the other half drew low it is no sign of detail either; the line's pixels are
    // independent of the pixel's halves (no selection). At 4 samples per half (1024x540, gamma
    // of shape 1): clean pixel-halves lowered 0.097% -> 0.066%, highlights kept 0.9956 ->
    // 0.9969. (The two neighbours at one step alone: 0.071%, but where fireflies are dense
    // two of them meet on both sides of a pixel often enough to make a line: dense30 0.3625
    // -> 0.3636; with four pixels, 0.3627.) The price: a one-pixel gap in a line is "on" it
    // too, and a firefly there no brighter than the line is kept (the halves of a line pixel
    // whose other half drew low); twice the line's level is rebuilt.
    // A firefly on detail is still far above both (100x: the geometric mean is 10x the other
    // half), and on smooth regions nothing changes (the Cycles renders within 0.5%). Renderer
    // units, like v.
    double noise_floor(double v, double l_other, double l_out, double calibration, const neighbourhood& nb,
                       bool own_variance) const {
        // too few neighbours: the pixel's own variance
        if (!(calibration > 0) || !(nb.pooled.nu == nb.pooled.nu)) return v;
        const double t = nb.pooled.typical;
        double level = nb.around > l_other ? (std::min)(nb.around, (std::max)(l_out, l_other)) : l_other;
        if (l_other > 0 && l_out > l_other && (nb.mixed() || nb.detail_above() < l_other || nb.line_through()))
            level = std::sqrt(l_out) * std::sqrt(l_other);  // detail (l_other > 0 here)
        const double pooled = t * level * level / calibration;
        if (own_variance || !(level > 0)) return (std::max)(v, pooled);
        // a single: less what the other half's own rise above the neighbourhood explains
        const double rise = nb.around > 0 ? (std::max)(0.0, l_other - nb.around) : 0.0;
        return (std::max)(v - rise * rise / calibration, pooled);
    }

    // What the local test's levels say about the neighbourhood of (x, y), computed once for
    // both halves' excess_log_p: the pooled relative variance (nu NaN: none, or no local test)
    // and the neighbourhood's level with its bias undone (noise_floor).
    neighbourhood neighbourhood_at(int x, int y, int w, int h, std::vector<float>& pool, bool pair = false) const {
        const local_test_scratch& ls = local_scratch_;
        const std::size_t i = index(x, y, w);
        neighbourhood nb;
        if (!options_.local_test || ls.rel_var[0].size() <= i || ls.rel_var[1].size() <= i) return nb;
        nb.pooled = detail::pooled_relative_variance(ls.rel_var, w, h, x, y, options_.local.radius,
                                                     options_.local.min_neighbours, pool);
        if (!(nb.pooled.nu == nb.pooled.nu)) return nb;
        const double t = nb.pooled.typical;
        double mad = 0;
        const double med = detail::neighbourhood_lower_level(ls.level, w, h, x, y, options_.local.radius,
                                                             (options_.local.min_neighbours + 1) / 2, pool, &mad);
        nb.spread = med > 0 ? mad / med : 0.0;
        const double bias = std::exp((std::min)(0.5449521356 * std::sqrt(t) + 0.5 * t, 700.0));
        nb.around = med * bias;
        const double line = detail::neighbourhood_line_level(ls.level, w, h, x, y);
        nb.line = line == line ? line * bias : 0.0;
        if (pair)
            nb.lower_noise = detail::neighbourhood_lower_noise(ls, w, h, x, y, options_.local.radius,
                                                               (options_.local.min_neighbours + 1) / 2, pool, nb.lower_count);
        return nb;
    }

    // The local test's flags join the outliers (after the global ones in each half's list).
    template <class C, class V, class A>
    void add_local_flags(const half_buffer<C, V, A>& a, const half_buffer<C, V, A>& b, frame_report& rep) {
        using L = local_half<std::remove_const_t<C>, std::remove_const_t<V>, std::remove_const_t<A>>;
        const L halves[2] = {L{a.color, a.variance, a.alpha, halves_[0].label.data()},
                             L{b.color, b.variance, b.alpha, halves_[1].label.data()}};
        local_test_options lo = options_.local;
        lo.variance_scale *= rep.variance_calibration;
        // (the options are checked, but a huge variance_scale times the calibration can pass
        // DBL_MAX: then no local test, and none of an earlier frame's scratch read either)
        if (!local_test(halves[0], halves[1], lo, local_scratch_, local_result_, exec_).ok()) {
            for (auto& v : local_scratch_.rel_var) v.clear();
            return;
        }
        for (int h = 0; h < 2; ++h) {
            half_state& s = halves_[h];
            s.order.resize(rep.half[h].outliers);  // candidates past the ESD's count are not outliers
            const local_flags& f = local_result_.half[h];
            for (std::size_t j = 0; j < f.index.size(); ++j) {
                const std::uint32_t i = f.index[j];
                if (s.label[i] & outlier_bit) continue;
                s.label[i] |= outlier_bit;
                s.order.push_back(i);
                s.log_p.push_back(f.log_p[j]);
                ++rep.half[h].local;
            }
            rep.half[h].outliers = s.order.size();
        }
    }

    // The pixels to rebuild: outliers not kept, and non-finite pixels (row-major list).
    void mark_fixes(half_state& s, half_report& r) {
        std::uint8_t* label = s.label.data();
        s.fix.clear();
        std::size_t highlights = 0, consistent = 0;
        for (std::size_t j = 0; j < r.outliers; ++j) {
            const std::uint32_t i = s.order[j];
            if (label[i] & highlight_bit) ++highlights;
            else if (label[i] & consistent_bit) ++consistent;
            else {
                label[i] |= fix_bit;
                s.fix.push_back(i);
            }
        }
        r.highlights = highlights;
        r.consistent = consistent;
        r.fireflies = s.fix.size();
        if (r.nonfinite + r.dropped + r.implausible > 0)
            for (std::size_t i = 0; i < s.label.size(); ++i)
                if (cls(label[i]) == nonfinite_class) {
                    label[i] |= fix_bit;
                    s.fix.push_back(static_cast<std::uint32_t>(i));
                }
        std::sort(s.fix.begin(), s.fix.end());
    }

    // Whether pixel (x, y) of a half has geometry (alpha > 0, or no alpha): only then is its
    // colour the image's (an alpha-0 pixel's colour is anything under straight alpha), and a
    // rebuild may read it.
    template <class C, class V, class A>
    static bool covered(const half_buffer<C, V, A>& hb, int x, int y) {
        return hb.alpha.empty() || hb.alpha.load(x, y) > 0;
    }

    // The other half's estimates of this half's pixels to rebuild, where the other half is
    // usable there (finite, not itself to be rebuilt, covered). Reads both halves, writes
    // nothing but s.cross / s.cross_values.
    template <class C, class V, class A>
    void stage_cross_half(const half_buffer<C, V, A>& own, const half_buffer<C, V, A>& other, half_state& s,
                          const half_state& o, const frame_report& rep) {
        s.cross.clear();
        s.cross_values.clear();
        s.cross_kept.clear();
        const int w = own.color.width();
        const int nch = own.color.channels() + own.variance.channels();
        s.recon.kernel_.set(options_.reconstruction.kernel_width, options_.reconstruction.sigma);
        const half_views<std::remove_const_t<C>, std::remove_const_t<V>> hv[2] = {{own.color, own.variance},
                                                                               {other.color, other.variance}};
        const std::uint8_t* lo = o.label.data();
        const std::uint8_t* ls = s.label.data();
        auto clean = [](std::uint8_t l) { return !(l & outlier_bit) && cls(l) != nonfinite_class; };
        // (a pixel without geometry is read by neither estimate: under straight alpha its
        // colour is anything)
        auto readable = [&](int xx, int yy) {
            const std::size_t q = index(xx, yy, w);
            return clean(ls[q]) && clean(lo[q]) && covered(own, xx, yy) && covered(other, xx, yy);
        };
        auto readable_other = [&](int xx, int yy) { return clean(lo[index(xx, yy, w)]) && covered(other, xx, yy); };
        // Every entry's estimate in chunks across the executor, then the taken ones compacted
        // in list order.
        const std::size_t n = s.fix.size(), stride = static_cast<std::size_t>(nch);
        s.cross_values.resize(n * stride);
        s.decision.assign(n, 0);
        for_chunks(n, [&](std::size_t e0, std::size_t e1) {
            for (std::size_t e = e0; e < e1; ++e) {
                const std::uint32_t p = s.fix[e];
                const int x = detail::column_of(p, w), y = detail::row_of(p, w);
                if (cls(lo[p]) == nonfinite_class || (lo[p] & fix_bit)) continue;
                if (!other.alpha.empty() && !(other.alpha.load(x, y) > 0)) continue;
                (void)detail::cross_half_estimate(hv[0], hv[1], s.recon.kernel_, rep.variance_calibration,
                                                  options_.blend_spatial, x, y, readable, readable_other,
                                                  &s.cross_values[e * stride]);
                s.decision[e] = lo[p] & outlier_bit ? 2 : 1;  // a kept highlight, say
            }
        });
        for (std::size_t e = 0; e < n; ++e) {
            if (!s.decision[e]) continue;
            if (s.cross.size() != e)
                std::copy_n(&s.cross_values[e * stride], stride, &s.cross_values[s.cross.size() * stride]);
            s.cross.push_back(s.fix[e]);
            s.cross_kept.push_back(s.decision[e] == 2);
        }
        s.cross_values.resize(s.cross.size() * stride);
    }

    // return_energy, its finest scale (density.hpp): both halves' removed excess pooled, the
    // density's light added to each half, and each rebuilt pixel's `before` lowered by the
    // share the density gave back (the wider scales return the rest). A pixel where either
    // half kept an outlier holds its light already and gets none; a rebuilt pixel at most f e.
    template <class C, class V, class A>
    void give_density_back(const half_buffer<C, V, A>* hb[2], const image_view<std::uint8_t>* masks[2],
                           energy_totals (&totals)[2]) {
        if constexpr (!std::is_const_v<C>) {
            const int w = hb[0]->color.width(), h = hb[0]->color.height();
            if (!(options_.energy_density_evidence > 0) || hb[0]->color.channels() < 3) return;
            density_return d;
            d.prepare(w, h, density_);
            for (int k = 0; k < 2; ++k) {  // each half's excess, once, by list entry
                const half_state& s = halves_[k];
                density_excess_[k].assign(s.fix.size() * 3, 0.0f);
                for (std::size_t e = 0; e < s.fix.size(); ++e)
                    if (detail::rebuilt_excess(hb[k]->color, detail::column_of(s.fix[e], w), detail::row_of(s.fix[e], w),
                                               &s.before[e * 3], &density_excess_[k][e * 3]))
                        density_.removed[s.fix[e]] = 1;
            }
            if (!d.needed(options_.energy_density_evidence, density_)) return;
            for (int k = 0; k < 2; ++k) {  // each pixel's list entry, 1 + its index (0: none)
                density_entry_[k].assign(static_cast<std::size_t>(w) * static_cast<std::size_t>(h), 0);
                for (std::size_t e = 0; e < halves_[k].fix.size(); ++e) density_entry_[k][halves_[k].fix[e]] = static_cast<std::uint32_t>(e + 1);
            }
            auto load = [&](int x, int y, double* v) {  // both halves' excess, |e_A + e_B|^2, the level
                const std::size_t p = static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x);
                v[6] = v[7] = 0;
                for (int c = 0; c < 3; ++c) {
                    double l = 0;  // the cleaned halves' level, positive finite parts
                    for (int k = 0; k < 2; ++k) {
                        const std::uint32_t e = density_entry_[k][p];
                        v[3 * k + c] = static_cast<double>(
                            e ? density_excess_[k][(e - 1) * 3 + static_cast<std::size_t>(c)] : 0.0f);
                        if (cls(halves_[k].label[p]) == ignored_class) continue;
                        const double c_k = hb[k]->color.load(x, y, c);  // (ignored: no part of the level)
                        l += std::isfinite(c_k) && c_k > 0 ? c_k : 0.0;
                    }
                    // fused the one way (fused.hpp): a tile's and one pixel's sums both inline it
                    const double both = v[c] + v[3 + c];
#ifdef FIREFLY_DETAIL_TARGET_FMA
                    v[6] = std::fma(both, both, v[6]);
#else
                    v[6] += both * both;
#endif
                    v[7] += static_cast<double>(
                        static_cast<float>((std::min)(l, static_cast<double>(FLT_MAX))));
                }
            };
            // Light cannot land on an ignored or non-finite pixel (in either half: one s); a kept
            // outlier's share counts as given, though it gets none (add_density_light): it holds
            // that light already, and the wider scales must not give it a second time
            // (re-giving it: the simulated caustics 0.0310 -> 0.0313, the Cycles caustics
            // 0.02482 -> 0.02490).
            auto receives = [&](int x, int y) {
                const std::size_t p = static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x);
                return cls(halves_[0].label[p]) == valid_class && cls(halves_[1].label[p]) == valid_class;
            };
            if (!d.run(options_.energy_density_evidence, density_, density_light_, exec_, load, receives)) return;
            for (int k = 0; k < 2; ++k) add_density_light(*hb[k], halves_[k], halves_[1 - k], d, k, *masks[k], totals[k]);
        } else {
            (void)hb, (void)masks, (void)totals;
        }
    }

    // One half's density light (density_light_, half k), then its list's `before` lowered by
    // the share given: the wider scales see the rest of each rebuilt pixel's excess
    // (density_excess_[k], by list entry).
    template <class C, class V, class A>
    void add_density_light(const half_buffer<C, V, A>& hb, half_state& s, const half_state& o, const density_return& d,
                           int k, const image_view<std::uint8_t>& mask, energy_totals& t) {
        const int w = hb.color.width();
        constexpr std::uint8_t kept = highlight_bit | consistent_bit;
        const std::vector<float>& excess = density_excess_[static_cast<std::size_t>(k)];
        auto xy = [w](std::uint32_t i) { return std::pair<int, int>(detail::column_of(i, w), detail::row_of(i, w)); };
        auto taken = [&](std::size_t e) {  // the share f of entry e's excess given (0: none removed)
            const float* ex = &excess[e * 3];
            return ex[0] > 0 || ex[1] > 0 || ex[2] > 0 ? d.taken(s.fix[e]) : 0.0;
        };
        std::size_t e = 0;  // the list's entry at or after the pixel
        for (const density_return::light& l : density_light_) {
            const std::uint32_t i = l.pixel;
            while (e < s.fix.size() && s.fix[e] < i) ++e;
            if ((s.label[i] & kept) || (o.label[i] & kept)) continue;  // (valid in both: receives)
            const auto [x, y] = xy(i);
            double add[3], old[3];
            const bool rebuilt = e < s.fix.size() && s.fix[e] == i;
            const double f = rebuilt ? taken(e) : 0.0;
            for (int c = 0; c < 3; ++c) {
                add[c] = static_cast<double>(l.add[k][c]);
                if (rebuilt) {
                    const float ex = excess[e * 3 + static_cast<std::size_t>(c)];
                    add[c] = (std::min)(add[c], f * static_cast<double>(ex));
                }
            }
            if (!(add[0] + add[1] + add[2] > 0)) continue;
            if (!add_light(hb.color, x, y, add, old)) {
                restore_light(hb.color, x, y, old, add);
                continue;
            }
            t.returned += (add[0] + add[1] + add[2]) / 3.0;
            if (!mask.empty()) mask(x, y) = static_cast<std::uint8_t>(mask(x, y) | mask_bits::energy);
        }
        for (std::size_t j = 0; j < s.fix.size(); ++j) {
            const double f = taken(j);
            if (!(f > 0)) continue;  // the list's entry as it was, bit for bit
            const auto [x, y] = xy(s.fix[j]);
            for (int c = 0; c < 3; ++c) {
                const float ex = excess[j * 3 + static_cast<std::size_t>(c)];
                const double rest = hb.color.load(x, y, c) + static_cast<double>(ex) * (1.0 - f);
                float b = static_cast<float>(rest);
                if (static_cast<double>(b) > rest) b = std::nextafter(b, -HUGE_VALF);
                s.before[j * 3 + static_cast<std::size_t>(c)] = b;
                t.removed += static_cast<double>(ex) * f / 3.0;
            }
        }
    }

    // return_energy: the colour of every pixel to rebuild, before the rebuild.
    template <class C, class V, class A>
    void keep_before(const half_buffer<C, V, A>& hb, half_state& s) {
        const int w = hb.color.width(), nc = (std::min)(hb.color.channels(), 3);
        s.before.assign(s.fix.size() * 3, 0.0f);
        for (std::size_t e = 0; e < s.fix.size(); ++e) {
            if (!s.implausible.empty() &&  // an implausible value is no light: none returned
                std::binary_search(s.implausible.begin(), s.implausible.end(), s.fix[e])) {
                for (int c = 0; c < 3; ++c) s.before[e * 3 + static_cast<std::size_t>(c)] = std::numeric_limits<float>::quiet_NaN();
                continue;
            }
            for (int c = 0; c < nc; ++c) {
                const double v = hb.color.load(detail::column_of(s.fix[e], w), detail::row_of(s.fix[e], w), c);
                float f = static_cast<float>(v);
                if (static_cast<double>(f) > v)
                    f = std::nextafter(f, -HUGE_VALF);  // never above the input (a double view)
                s.before[e * 3 + static_cast<std::size_t>(c)] = f;
            }
        }
    }

    // return_energy: energy.hpp on the cleaned half; never onto ignored (black, alpha 0) or
    // non-finite pixels, nor onto an outlier kept within its noise (consistent_bit): that half
    // kept its high draw and the rare light in it, which a return would add a second time.
    // Pixels that hold some of that light already get the rest of their share (list_held_light).
    // The pixels it adds light to get mask_bits::energy.
    template <class C, class V, class A>
    void give_energy_back(const half_buffer<C, V, A>& hb, const half_buffer<C, V, A>& other, half_state& s,
                          const half_state& o, const image_view<std::uint8_t>& mask, half_report& r) {
        if constexpr (!std::is_const_v<C>) {
            const int w = hb.color.width();
            s.decision.resize(s.label.size());
            for (std::size_t i = 0; i < s.label.size(); ++i)
                s.decision[i] = cls(s.label[i]) == valid_class && !(s.label[i] & consistent_bit);
            list_held_light(hb, other, s, o);
            s.added.assign(mask.empty() ? 0 : s.label.size(), 0);
            // an ignored pixel's colour (alpha 0 may hold anything) is no part of the shape
            s.outside.resize(r.ignored > 0 ? s.label.size() : 0);
            for (std::size_t i = 0; i < s.outside.size(); ++i)
                s.outside[i] = cls(s.label[i]) == ignored_class;
            const energy_totals t = return_energy_to_image(hb.color, s.fix.data(),
                                                           s.before.data(), s.fix.size(), s.decision.data(),
                                                           energy_scales(options_.energy_sigma, options_.energy_coarse_sigma), energy_, exec_,
                                                           mask.empty() ? nullptr : s.added.data(),
                                                           held_light{s.held.data(), s.held_values.data(), s.held_shares.data(), s.held.size()},
                                                           s.outside.empty() ? nullptr : s.outside.data());
            r.energy_removed = t.removed;
            r.energy_returned = t.returned;
            for (int y = 0; y < mask.height(); ++y)
                for (int x = 0; x < w; ++x)
                    if (s.added[index(x, y, w)]) mask(x, y) = static_cast<std::uint8_t>(mask(x, y) | mask_bits::energy);
        } else {
            (void)hb, (void)other, (void)s, (void)o, (void)mask, (void)r;
        }
    }

    // The pixels of this half, among those the return may reach, that hold some of the rare
    // light already (energy.hpp, held_light), in pixel order: where the other half kept an
    // outlier, what it holds above this half (of the pair's share, 2 returns: the pair's mean
    // holds it); a half of a kept pair standing above a smooth neighbourhood (pair_base), its
    // rise above that level (of its own share: were it fireflies that met, the rise is their
    // light; a highlight spot takes no glow onto its own light). None where a value is not
    // finite. risen_: the kept pairs' levels, by pixel.
    template <class C, class V, class A>
    void list_held_light(const half_buffer<C, V, A>& hb, const half_buffer<C, V, A>& other, half_state& s,
                         const half_state& o) {
        s.held.clear();
        s.held_values.clear();
        s.held_shares.clear();
        if (hb.color.channels() < 3) return;
        const int w = hb.color.width();
        auto risen = risen_.cbegin();
        for (std::size_t i = 0; i < s.label.size(); ++i) {
            while (risen != risen_.cend() && risen->first < i) ++risen;
            if (!s.decision[i]) continue;
            const bool paired = (o.label[i] & consistent_bit) != 0;
            const bool rose = !paired && (s.label[i] & highlight_bit) && risen != risen_.cend() && risen->first == i;
            if (!paired && !rose) continue;
            const int x = detail::column_of(i, w), y = detail::row_of(i, w);
            double v[3], level = 0;
            for (int c = 0; c < 3; ++c) level += (v[c] = hb.color.load(x, y, c)) / 3.0;
            const double rise = rose && level > 0 ? (std::max)(0.0, 1.0 - risen->second / level) : 0.0;
            float held[3];
            bool finite = true;
            for (int c = 0; c < 3; ++c) {
                const double d = paired ? static_cast<double>(other.color.load(x, y, c)) - v[c] : v[c] * rise;
                finite = finite && std::isfinite(d);
                held[c] = d > 0 ? static_cast<float>((std::min)(d, static_cast<double>(FLT_MAX))) : 0.0f;
            }
            if (!finite) continue;
            s.held.push_back(static_cast<std::uint32_t>(i));
            s.held_values.insert(s.held_values.end(), held, held + 3);
            s.held_shares.push_back(paired ? 2 : 1);
        }
    }

    template <class C, class V, class A>
    void finish(const half_buffer<C, V, A>& hb, half_state& s, const image_view<std::uint8_t>& mask, half_report& r,
                bool clean, bool cross) {
        s.left.clear();
        if constexpr (!std::is_const_v<C> && !std::is_const_v<V>) {
            if (clean) rebuild(hb, s, r, cross);
        } else {
            (void)hb, (void)cross;
        }
        if (!clean) r.repaired = 0;
        if (!mask.empty()) write_mask(s, mask);
    }

    template <class C, class V, class A>
    void rebuild(const half_buffer<C, V, A>& hb, half_state& s, half_report& r, bool cross) {
        std::uint8_t* label = s.label.data();
        const int w = hb.color.width();
        const int nc = hb.color.channels(), nv = hb.variance.channels();
        if (cross) {
            for (std::size_t e = 0; e < s.cross.size(); ++e) {
                const std::uint32_t p = s.cross[e];
                const int x = detail::column_of(p, w), y = detail::row_of(p, w);
                const double* v = &s.cross_values[e * static_cast<std::size_t>(nc + nv)];
                for (int c = 0; c < nc; ++c) hb.color.store(x, y, c, v[c]);
                for (int c = 0; c < nv; ++c) hb.variance.store(x, y, c, v[nc + c]);
                label[p] = static_cast<std::uint8_t>((label[p] & ~fix_bit) | (s.cross_kept[e] ? 0 : other_half_bit));
            }
            r.from_other_half = s.cross.size();
        }
        // Spatially: what is bad in both halves (or everything, with rebuild = spatial).
        // Sources exclude every outlier and non-finite pixel not rebuilt from the other half,
        // and those rebuilt from an outlier the other half keeps (a firefly on a highlight:
        // the highlight's value, excluded in both halves; other_half_bit set after); a pixel
        // without geometry is never read (no_geometry_bit, set for the rebuild alone).
        const bool uncovered = mark_no_geometry(hb, s, r);
        auto role = [](std::uint8_t m) {
            if (m & fix_bit) return pixel_role::rebuild;
            if (m & other_half_bit) return pixel_role::source;
            if (m & no_geometry_bit) return pixel_role::outside;
            if ((m & outlier_bit) || cls(m) == nonfinite_class) return pixel_role::excluded;
            return pixel_role::source;
        };
        constexpr std::uint8_t interesting = fix_bit | other_half_bit | outlier_bit | nonfinite_class | no_geometry_bit;
        const reconstruct_report rr =
            reconstruct(hb.color, hb.variance, label, options_.reconstruction, s.recon, interesting, role);
        if (uncovered)
            for (std::uint8_t& l : s.label) l = static_cast<std::uint8_t>(l & ~no_geometry_bit);
        if (cross)
            for (std::size_t e = 0; e < s.cross.size(); ++e)
                if (s.cross_kept[e]) label[s.cross[e]] |= other_half_bit;
        r.phase1_rounds = rr.phase1_rounds;
        r.phase2_iterations = rr.phase2_iterations;
        r.final_change = rr.final_change;
        r.reconstruction = rr.error;
        r.unreachable = rr.unreachable;
        std::size_t repaired = 0;
        for (const std::uint32_t p : s.fix) {  // unreachable pixels are still marked pending
            const bool left = (label[p] & fix_bit) && s.recon.state_[p] == 1;
            repaired += cls(label[p]) == nonfinite_class && !left;
            if (left) s.left.push_back(p);
        }
        r.repaired = repaired;
    }

    // Sets no_geometry_bit on this half's ignored pixels without geometry; whether there can
    // be any (alpha given, some pixel ignored).
    template <class C, class V, class A>
    static bool mark_no_geometry(const half_buffer<C, V, A>& hb, half_state& s, const half_report& r) {
        if (hb.alpha.empty() || r.ignored == 0) return false;
        const int w = hb.color.width();
        for (std::size_t i = 0; i < s.label.size(); ++i)
            if (cls(s.label[i]) == ignored_class && !covered(hb, detail::column_of(i, w), detail::row_of(i, w)))
                s.label[i] = static_cast<std::uint8_t>(s.label[i] | no_geometry_bit);
        return true;
    }

    static void write_mask(const half_state& s, const image_view<std::uint8_t>& mask) {
        const int w = mask.width();
        for (int y = 0; y < mask.height(); ++y)
            for (int x = 0; x < w; ++x) {
                const std::uint8_t l = s.label[index(x, y, w)];
                std::uint8_t m = 0;
                if ((l & outlier_bit) && !(l & (highlight_bit | consistent_bit))) m |= mask_bits::firefly;
                if (l & highlight_bit) m |= mask_bits::highlight;
                if (l & consistent_bit) m |= mask_bits::consistent;
                if (cls(l) == nonfinite_class) m |= mask_bits::nonfinite;
                if (l & other_half_bit) m |= mask_bits::other_half;
                mask(x, y) = m;
            }
        for (const std::uint32_t p : s.dropped) {  // non-finite to the rebuild, not to the user
            std::uint8_t& m = mask(detail::column_of(p, w), detail::row_of(p, w));
            m = static_cast<std::uint8_t>((m & ~mask_bits::nonfinite) | mask_bits::dropped);
        }
        for (const std::uint32_t p : s.left) {  // process() only: detect() rebuilds nothing
            const int x = detail::column_of(p, w), y = detail::row_of(p, w);
            mask(x, y) = static_cast<std::uint8_t>(mask(x, y) | mask_bits::left);
        }
    }

    detector_options options_;
    executor exec_;
    detail::shared_cache cache_;
};

namespace detail {
// The same elements in the same order: the same type, start and strides (sizes checked apart).
template <class T, class U>
bool same_elements(const image_view<T>& a, const image_view<U>& b) noexcept {
    return std::is_same_v<std::remove_const_t<T>, std::remove_const_t<U>> &&
           static_cast<const void*>(a.data()) == static_cast<const void*>(b.data()) &&
           a.pixel_stride() == b.pixel_stride() && a.row_stride() == b.row_stride() &&
           a.channel_stride() == b.channel_stride();
}

}  // namespace detail

// The final image of a frame, (A + B) / 2, and the variance of that mean, (vA + vB) / 4 (a
// quarter each first where the sum overflows: FLT_MAX or DBL_MAX variances stay finite).
// out_variance may be empty. Views must share size and channel counts. A written view may be
// the very input it replaces (out on a or b, out_variance on var_a or var_b: each element is
// read before it is written) and must otherwise share no memory with another view; a shifted
// overlap would overwrite elements still to be read, and is refused (aliased_views) before
// anything is written.
template <class T, class U>
status combine_halves(const image_view<T>& a, const image_view<T>& b, const image_view<U>& out,
                      const image_view<T>& var_a = {}, const image_view<T>& var_b = {},
                      const image_view<U>& out_variance = {}) {
    if (!same_size(a, b) || !same_size(a, out)) return status{errc::size_mismatch, "combine: sizes differ"};
    if (a.channels() != b.channels() || out.channels() != a.channels())
        return status{errc::channel_mismatch, "combine: channel counts differ"};
    const bool var = !out_variance.empty();
    if (var && (!same_size(var_a, out_variance) || !same_size(var_b, out_variance) ||
                var_a.channels() != out_variance.channels() || var_b.channels() != out_variance.channels()))
        return status{errc::size_mismatch, "combine: variance views do not match"};
    auto apart = [](const auto& written, const auto& other, bool may_be_it) {
        return !views_may_overlap(written, other) || (may_be_it && detail::same_elements(written, other));
    };
    bool ok = apart(out, a, true) && apart(out, b, true);
    if (var)
        ok = ok && apart(out, var_a, false) && apart(out, var_b, false) && apart(out, out_variance, false) &&
             apart(out_variance, var_a, true) && apart(out_variance, var_b, true) && apart(out_variance, a, false) &&
             apart(out_variance, b, false);
    if (!ok) return status{errc::aliased_views, "combine: an output shares memory with another view"};
    for (int y = 0; y < a.height(); ++y)
        for (int x = 0; x < a.width(); ++x) {
            for (int c = 0; c < a.channels(); ++c) out.store(x, y, c, detail::scaled_sum(a.load(x, y, c), b.load(x, y, c), 0.5));
            if (var)
                for (int c = 0; c < out_variance.channels(); ++c)
                    out_variance.store(x, y, c, detail::scaled_sum(var_a.load(x, y, c), var_b.load(x, y, c), 0.25));
        }
    return ok_status();
}

}  // namespace firefly
