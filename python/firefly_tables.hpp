// firefly Python module: every detector option and every report field, each listed once.
// The module's keywords, attributes and as_dict(), and the reference program's arguments
// and output, are all generated from these lists, so a new option or field is one line here.
// No pybind11 in this header: the C++ reference program (firefly_py_reference) uses it too.
#pragma once

#include <cstddef>
#include <iterator>
#include <type_traits>
#include <utility>

#include <firefly/buffers.hpp>
#include <firefly/pipeline.hpp>

namespace firefly_py {

// The names of an enum's values, spelt as the library's identifiers.
template <class E>
struct enum_names;

template <>
struct enum_names<firefly::highlight_rule> {
    using E = firefly::highlight_rule;
    static constexpr std::pair<const char*, E> values[] = {
        {"same_pixel", E::same_pixel}, {"agree", E::agree}, {"confident", E::confident},
        {"confident_and_agree", E::confident_and_agree}};
};

template <>
struct enum_names<firefly::variance_reduction> {
    using E = firefly::variance_reduction;
    static constexpr std::pair<const char*, E> values[] = {
        {"mean", E::mean}, {"luminance", E::luminance}, {"max", E::max}};
};

template <>
struct enum_names<firefly::lambda_method> {
    using E = firefly::lambda_method;
    static constexpr std::pair<const char*, E> values[] = {
        {"exact", E::exact}, {"hill", E::hill}, {"normal", E::normal}};
};

template <>
struct enum_names<firefly::rebuild_source> {
    using E = firefly::rebuild_source;
    static constexpr std::pair<const char*, E> values[] = {{"other_half", E::other_half}, {"spatial", E::spatial}};
};

template <>
struct enum_names<firefly::frame_report::stage> {
    using E = firefly::frame_report::stage;
    static constexpr std::pair<const char*, E> values[] = {
        {"candidates", E::candidates}, {"esd", E::esd}, {"local", E::local}, {"highlights", E::highlights},
        {"other_half", E::other_half}, {"rebuild", E::rebuild}};
};
static_assert(std::size(enum_names<firefly::frame_report::stage>::values) == firefly::frame_report::stages,
              "every frame_report::stage needs a name");

template <>
struct enum_names<firefly::errc> {
    using E = firefly::errc;
    static constexpr std::pair<const char*, E> values[] = {
        {"ok", E::ok},
        {"null_data", E::null_data},
        {"empty_image", E::empty_image},
        {"bad_stride", E::bad_stride},
        {"size_overflow", E::size_overflow},
        {"size_mismatch", E::size_mismatch},
        {"channel_mismatch", E::channel_mismatch},
        {"invalid_argument", E::invalid_argument},
        {"no_valid_pixels", E::no_valid_pixels},
        {"aliased_views", E::aliased_views}};
};

// The name of an enum value; nullptr when the list above misses it.
template <class E>
const char* enum_name(E e) noexcept {
    for (const auto& nv : enum_names<E>::values)
        if (nv.second == e) return nv.first;
    return nullptr;
}

// Every detector_options member, by its flattened keyword (the member's own name; the
// highlight rule is `highlight_rule`, as `rule` alone says nothing, and the local test's
// options carry `local_`). f(name, get) where get(options) returns a reference to the member.
template <class F>
constexpr void for_each_option(F&& f) {
    using O = firefly::detector_options;
    f("alpha", [](O& o) -> auto& { return o.alpha; });
    f("bound_threshold", [](O& o) -> auto& { return o.bound_threshold; });
    f("reduction", [](O& o) -> auto& { return o.reduction; });
    f("lambdas", [](O& o) -> auto& { return o.lambdas; });
    f("highlight_rule", [](O& o) -> auto& { return o.highlight.rule; });
    f("max_ratio", [](O& o) -> auto& { return o.highlight.max_ratio; });
    f("max_relative_error", [](O& o) -> auto& { return o.highlight.max_relative_error; });
    f("min_excess_z", [](O& o) -> auto& { return o.highlight.min_excess_z; });
    f("cluster_relative_error", [](O& o) -> auto& { return o.highlight.cluster_relative_error; });
    f("kernel_width", [](O& o) -> auto& { return o.reconstruction.kernel_width; });
    f("sigma", [](O& o) -> auto& { return o.reconstruction.sigma; });
    f("tolerance", [](O& o) -> auto& { return o.reconstruction.tolerance; });
    f("max_iterations", [](O& o) -> auto& { return o.reconstruction.max_iterations; });
    f("rebuild", [](O& o) -> auto& { return o.rebuild; });
    f("blend_spatial", [](O& o) -> auto& { return o.blend_spatial; });
    f("reconstruct", [](O& o) -> auto& { return o.reconstruct; });
    f("find_dropped", [](O& o) -> auto& { return o.find_dropped; });
    f("find_implausible", [](O& o) -> auto& { return o.find_implausible; });
    f("return_energy", [](O& o) -> auto& { return o.return_energy; });
    f("energy_sigma", [](O& o) -> auto& { return o.energy_sigma; });
    f("energy_coarse_sigma", [](O& o) -> auto& { return o.energy_coarse_sigma; });
    f("energy_density_evidence", [](O& o) -> auto& { return o.energy_density_evidence; });
    f("local_test", [](O& o) -> auto& { return o.local_test; });
    f("local_false_alarm", [](O& o) -> auto& { return o.local.false_alarm; });
    f("local_radius", [](O& o) -> auto& { return o.local.radius; });
    f("local_min_neighbours", [](O& o) -> auto& { return o.local.min_neighbours; });
    f("local_variance_scale", [](O& o) -> auto& { return o.local.variance_scale; });
    f("local_spatial", [](O& o) -> auto& { return o.local.spatial; });
    f("local_homogeneity", [](O& o) -> auto& { return o.local.homogeneity; });
}

// Every half_report field: f(name, member pointer).
template <class F>
constexpr void for_each_half_field(F&& f) {
    using H = firefly::half_report;
    f("pixels", &H::pixels);
    f("valid", &H::valid);
    f("ignored", &H::ignored);
    f("nonfinite", &H::nonfinite);
    f("dropped", &H::dropped);
    f("implausible", &H::implausible);
    f("negative_variance", &H::negative_variance);
    f("median", &H::median);
    f("mad", &H::mad);
    f("bound", &H::bound);
    f("outliers", &H::outliers);
    f("local", &H::local);
    f("highlights", &H::highlights);
    f("consistent", &H::consistent);
    f("frame_kept", &H::frame_kept);
    f("fireflies", &H::fireflies);
    f("repaired", &H::repaired);
    f("from_other_half", &H::from_other_half);
    f("unreachable", &H::unreachable);
    f("phase1_rounds", &H::phase1_rounds);
    f("phase2_iterations", &H::phase2_iterations);
    f("final_change", &H::final_change);
    f("reconstruction", &H::reconstruction);
    f("energy_removed", &H::energy_removed);
    f("energy_returned", &H::energy_returned);
}

// Every frame_report field but `half` (the two half reports, listed above): f(name, member
// pointer).
template <class F>
constexpr void for_each_frame_field(F&& f) {
    using R = firefly::frame_report;
    f("error", &R::error);
    f("both_outliers", &R::both_outliers);
    f("variance_calibration", &R::variance_calibration);
    f("single_level", &R::single_level);
    f("single_log_level", &R::single_log_level);
    f("lambdas_computed", &R::lambdas_computed);
    f("scratch_bytes", &R::scratch_bytes);
    f("stage_ms", &R::stage_ms);  // a timing: differs from run to run
}

// Every cross_buffer_options member but `pair` (K = 2's detector_options, the keyword `pair`
// taking for_each_option's keywords): f(name, get).
template <class F>
constexpr void for_each_buffer_option(F&& f) {
    using O = firefly::cross_buffer_options;
    f("alpha", [](O& o) -> auto& { return o.alpha; });
    f("false_alarm", [](O& o) -> auto& { return o.false_alarm; });
    f("use_variance", [](O& o) -> auto& { return o.use_variance; });
    f("reconstruct", [](O& o) -> auto& { return o.reconstruct; });
    f("find_dropped", [](O& o) -> auto& { return o.find_dropped; });
    f("find_implausible", [](O& o) -> auto& { return o.find_implausible; });
    f("refine_noise", [](O& o) -> auto& { return o.refine_noise; });
    f("radius", [](O& o) -> auto& { return o.radius; });
    f("return_energy", [](O& o) -> auto& { return o.return_energy; });
    f("energy_sigma", [](O& o) -> auto& { return o.energy_sigma; });
    f("energy_coarse_sigma", [](O& o) -> auto& { return o.energy_coarse_sigma; });
    f("energy_density_evidence", [](O& o) -> auto& { return o.energy_density_evidence; });
}

// Every cross_buffer_report field but `pair` (K = 2's frame_report) and `per_buffer` (a list):
// f(name, member pointer).
template <class F>
constexpr void for_each_buffer_field(F&& f) {
    using R = firefly::cross_buffer_report;
    f("error", &R::error);
    f("buffers", &R::buffers);
    f("pixels", &R::pixels);
    f("tested", &R::tested);
    f("candidates", &R::candidates);
    f("level", &R::level);
    f("fireflies", &R::fireflies);
    f("nonfinite", &R::nonfinite);
    f("dropped", &R::dropped);
    f("implausible", &R::implausible);
    f("left", &R::left);
    f("energy_removed", &R::energy_removed);
    f("energy_returned", &R::energy_returned);
}

// ---------------------------------------------------------------------------------------
// The option and half-report lists are complete: their counts are checked against the number
// of members of the library's structs, so a member added there and not here stops the build.
namespace detail {

struct any_value {
    template <class T>
    constexpr operator T() const noexcept;  // never defined: used in unevaluated contexts only
};

template <class T, class Seq, class = void>
struct brace_initializable : std::false_type {};
template <class T, std::size_t... I>
struct brace_initializable<T, std::index_sequence<I...>, std::void_t<decltype(T{(void(I), any_value{})...})>>
    : std::true_type {};

// The number of initializers an aggregate takes: its number of members.
template <class T, std::size_t N = 0>
constexpr std::size_t aggregate_size() {
    if constexpr (brace_initializable<T, std::make_index_sequence<N + 1>>::value) {
        return aggregate_size<T, N + 1>();
    } else {
        return N;
    }
}

struct counter {
    std::size_t n = 0;
    template <class... X>
    constexpr void operator()(const char*, X&&...) noexcept { ++n; }
};

template <class List>
constexpr std::size_t count(List list) {
    counter c;
    list(c);
    return c.n;
}

}  // namespace detail

static_assert(detail::count([](auto& c) { for_each_option(c); }) ==
                  detail::aggregate_size<firefly::detector_options>() - 3 +  // highlight, reconstruction, local
                      detail::aggregate_size<firefly::highlight_options>() +
                      detail::aggregate_size<firefly::reconstruct_options>() +
                      detail::aggregate_size<firefly::local_test_options>(),
              "for_each_option must list every detector_options member");
static_assert(detail::count([](auto& c) { for_each_half_field(c); }) == detail::aggregate_size<firefly::half_report>(),
              "for_each_half_field must list every half_report member");
static_assert(detail::count([](auto& c) { for_each_buffer_option(c); }) ==
                  detail::aggregate_size<firefly::cross_buffer_options>() - 1,  // pair
              "for_each_buffer_option must list every cross_buffer_options member");
// (frame_report and cross_buffer_report, which holds one, are not counted: brace elision into
// its half[2] array makes the count meaningless. Their fields are few and listed above.)

}  // namespace firefly_py
