// The C++ side of the Python module's round-trip test: cleans raw half buffers (or K buffers)
// with the library directly and prints the report, so the test can compare the module bit for
// bit.
//
//   firefly_py_reference DTYPE WIDTH HEIGHT COLOR_CHANNELS VARIANCE_CHANNELS DIR [name=value ...]
//   firefly_py_reference buffers K DTYPE WIDTH HEIGHT COLOR_CHANNELS VARIANCE_CHANNELS DIR [name=value ...]
//
// DTYPE is f4 or f8. DIR holds packed, C-order raw arrays a_color, a_variance, b_color,
// b_variance, and optionally a_alpha and b_alpha; the cleaned colour and variance are written
// back in place and the masks to a_mask and b_mask. Options are the module's keywords
// (firefly_tables.hpp) plus threads=N. The report goes to stdout, one "name value" per line
// ("a.fireflies 12"). Errors go to stderr with exit status 1.
//
// K buffers: DIR holds color_0 .. color_{K-1} and, unless VARIANCE_CHANNELS is 0, variance_0
// ..; masks go to mask_0 ..; options are BufferDetector's keywords, pair.NAME for Detector's
// (K = 2); the report prints as "fireflies 3", "per_buffer.0 1", "pair.a.fireflies 2".
#include <cerrno>
#include <cinttypes>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <type_traits>
#include <vector>

#include "firefly_tables.hpp"

namespace {

using firefly::detector_options;

bool read_file(const std::string& path, std::vector<unsigned char>& out, std::size_t bytes) {
    std::FILE* f = std::fopen(path.c_str(), "rb");
    if (!f) return false;
    out.resize(bytes);
    const bool ok = std::fread(out.data(), 1, bytes, f) == bytes && std::fgetc(f) == EOF;
    std::fclose(f);
    return ok;
}

bool write_file(const std::string& path, const void* data, std::size_t bytes) {
    std::FILE* f = std::fopen(path.c_str(), "wb");
    if (!f) return false;
    const bool ok = std::fwrite(data, 1, bytes, f) == bytes;
    return std::fclose(f) == 0 && ok;
}

template <class T>
bool parse_value(const char* s, T& out) {
    char* end = nullptr;
    errno = 0;
    if constexpr (std::is_enum_v<T>) {
        for (const auto& nv : firefly_py::enum_names<T>::values)
            if (std::strcmp(s, nv.first) == 0) {
                out = nv.second;
                return true;
            }
        return false;
    } else if constexpr (std::is_same_v<T, bool>) {
        out = std::strcmp(s, "True") == 0 || std::strcmp(s, "true") == 0 || std::strcmp(s, "1") == 0;
        return out || std::strcmp(s, "False") == 0 || std::strcmp(s, "false") == 0 || std::strcmp(s, "0") == 0;
    } else if constexpr (std::is_integral_v<T>) {
        const long long v = std::strtoll(s, &end, 10);
        out = static_cast<T>(v);
        return *s && !*end && errno == 0 && static_cast<long long>(out) == v;
    } else {
        out = static_cast<T>(std::strtod(s, &end));  // strtod reads Python's repr() exactly
        return *s && !*end;
    }
}

// name = value into the options through the option list; false when either is unknown.
template <class O, class List>
bool set_listed(O& o, const std::string& name, const char* value, List&& list) {
    bool found = false, ok = false;
    list([&](const char* n, auto get) {
        if (name != n) return;
        found = true;
        ok = parse_value(value, get(o));
    });
    return found && ok;
}

constexpr auto detector_option_list = [](auto&& f) { firefly_py::for_each_option(f); };
constexpr auto buffer_option_list = [](auto&& f) { firefly_py::for_each_buffer_option(f); };

// An option into the options; false when its name or value is unknown.
bool set_option(detector_options& o, const std::string& name, const char* value) {
    return set_listed(o, name, value, detector_option_list);
}

// The same for K buffers: "pair.NAME" is Detector's option NAME (K = 2).
bool set_buffer_option(firefly::cross_buffer_options& o, const std::string& name, const char* value) {
    if (name.rfind("pair.", 0) == 0) return set_listed(o.pair, name.substr(5), value, detector_option_list);
    return set_listed(o, name, value, buffer_option_list);
}

void print_value(const char* name, const firefly::status& s) { std::printf("%s %s\n", name, firefly_py::enum_name(s.code())); }
void print_value(const char* name, double v) { std::printf("%s %.17g\n", name, v); }
void print_value(const char* name, int v) { std::printf("%s %d\n", name, v); }
void print_value(const char* name, std::size_t v) { std::printf("%s %zu\n", name, v); }
void print_value(const char*, const double (&)[firefly::frame_report::stages]) {}  // timings differ per run

void print_report(const firefly::frame_report& r, const std::string& prefix = "") {
    firefly_py::for_each_frame_field([&](const char* name, auto member) { print_value((prefix + name).c_str(), r.*member); });
    for (int h = 0; h < 2; ++h)
        firefly_py::for_each_half_field([&](const char* name, auto member) {
            print_value((prefix + (h ? "b." : "a.") + name).c_str(), r.half[h].*member);
        });
}

void print_report(const firefly::cross_buffer_report& r) {
    firefly_py::for_each_buffer_field([&](const char* name, auto member) { print_value(name, r.*member); });
    for (std::size_t i = 0; i < r.per_buffer.size(); ++i) std::printf("per_buffer.%zu %zu\n", i, r.per_buffer[i]);
    if (r.buffers == 2) print_report(r.pair, "pair.");
}

struct frame_spec {
    int width = 0, height = 0, nc = 0, nv = 0;
    std::string dir;
};

template <class T>
int run(const frame_spec& s, const detector_options& o, int threads) {
    const std::size_t n = static_cast<std::size_t>(s.width) * static_cast<std::size_t>(s.height);
    const char* names[6] = {"a_color", "a_variance", "b_color", "b_variance", "a_alpha", "b_alpha"};
    const std::size_t counts[6] = {n * s.nc, n * s.nv, n * s.nc, n * s.nv, n, n};
    std::vector<unsigned char> data[6];
    bool present[6] = {};
    for (int i = 0; i < 6; ++i) {
        present[i] = read_file(s.dir + "/" + names[i], data[i], counts[i] * sizeof(T));
        if (!present[i] && i < 4) return std::fprintf(stderr, "cannot read %s/%s\n", s.dir.c_str(), names[i]), 1;
    }
    auto view = [&](int i, int channels) {
        return *firefly::make_image_view(reinterpret_cast<T*>(data[i].data()), s.width, s.height, channels);
    };
    firefly::half_buffer<T> a{view(0, s.nc), view(1, s.nv), {}}, b{view(2, s.nc), view(3, s.nv), {}};
    if (present[4]) a.alpha = view(4, 1);
    if (present[5]) b.alpha = view(5, 1);
    std::vector<std::uint8_t> mask[2] = {std::vector<std::uint8_t>(n), std::vector<std::uint8_t>(n)};
    firefly::detector d(o, firefly::executor::threads(static_cast<unsigned>(threads)));
    const firefly::frame_report r = d.process(a, b, *firefly::make_image_view(mask[0].data(), s.width, s.height),
                                              *firefly::make_image_view(mask[1].data(), s.width, s.height));
    // Like the module: a processed frame with unreachable pixels still has a report.
    if (!r.ok() && r.error.code() != firefly::errc::no_valid_pixels)
        return std::fprintf(stderr, "%s\n", r.error.message()), 1;
    for (int i = 0; i < 4; ++i)
        if (!write_file(s.dir + "/" + names[i], data[i].data(), data[i].size())) return 1;
    if (!write_file(s.dir + "/a_mask", mask[0].data(), n) || !write_file(s.dir + "/b_mask", mask[1].data(), n)) return 1;
    print_report(r);
    return 0;
}

// The "name=value" options from argv[first ..] (threads=N, or set(o, name, value)), then
// run(T{}, o, threads) with T float or double as dtype says.
template <class O, class Set, class Run>
int run_with(int argc, char** argv, int first, const std::string& dtype, O o, Set&& set, Run&& run) {
    int threads = 1;
    for (int i = first; i < argc; ++i) {
        const std::string arg = argv[i];
        const std::size_t eq = arg.find('=');
        const std::string name = arg.substr(0, eq);
        const char* value = argv[i] + (eq == std::string::npos ? arg.size() : eq + 1);
        const bool ok = eq != std::string::npos && (name == "threads" ? parse_value(value, threads) : set(o, name, value));
        if (!ok) return std::fprintf(stderr, "bad option: %s\n", argv[i]), 2;
    }
    if (dtype == "f4") return run(float{}, o, threads);
    if (dtype == "f8") return run(double{}, o, threads);
    std::fprintf(stderr, "dtype must be f4 or f8\n");
    return 2;
}

struct buffers_spec {
    int k = 0;
    frame_spec frame;
};

// K buffers from DIR, cleaned by a cross_buffer_detector, written back; the report printed.
template <class T>
int run_buffers(const buffers_spec& s, const firefly::cross_buffer_options& o, int threads) {
    const frame_spec& f = s.frame;
    const std::size_t n = static_cast<std::size_t>(f.width) * static_cast<std::size_t>(f.height);
    std::vector<std::vector<unsigned char>> color(static_cast<std::size_t>(s.k)), variance(color.size());
    std::vector<std::vector<std::uint8_t>> mask(color.size(), std::vector<std::uint8_t>(n));
    std::vector<firefly::buffer_view<T>> views(color.size());
    std::vector<firefly::image_view<std::uint8_t>> masks;
    auto path = [&](const char* what, std::size_t i) { return f.dir + "/" + what + "_" + std::to_string(i); };
    for (std::size_t i = 0; i < color.size(); ++i) {
        if (!read_file(path("color", i), color[i], n * f.nc * sizeof(T)) ||
            (f.nv > 0 && !read_file(path("variance", i), variance[i], n * f.nv * sizeof(T))))
            return std::fprintf(stderr, "cannot read buffer %zu in %s\n", i, f.dir.c_str()), 1;
        views[i].color = *firefly::make_image_view(reinterpret_cast<T*>(color[i].data()), f.width, f.height, f.nc);
        if (f.nv > 0)
            views[i].variance = *firefly::make_image_view(reinterpret_cast<T*>(variance[i].data()), f.width, f.height, f.nv);
        masks.push_back(*firefly::make_image_view(mask[i].data(), f.width, f.height));
    }
    firefly::cross_buffer_detector d(o, firefly::executor::threads(static_cast<unsigned>(threads)));
    const firefly::cross_buffer_report r = d.process(views, masks);
    if (!r.ok() && r.error.code() != firefly::errc::no_valid_pixels)  // like the module
        return std::fprintf(stderr, "%s\n", r.error.message()), 1;
    for (std::size_t i = 0; i < color.size(); ++i)
        if (!write_file(path("color", i), color[i].data(), color[i].size()) ||
            (f.nv > 0 && !write_file(path("variance", i), variance[i].data(), variance[i].size())) ||
            !write_file(path("mask", i), mask[i].data(), n))
            return 1;
    print_report(r);
    return 0;
}

int buffers_main(int argc, char** argv) {
    if (argc < 9) {
        std::fprintf(stderr, "usage: %s buffers K f4|f8 WIDTH HEIGHT COLOR_CHANNELS VARIANCE_CHANNELS DIR [name=value ...]\n",
                     argv[0]);
        return 2;
    }
    const buffers_spec s{std::atoi(argv[2]),
                         {std::atoi(argv[4]), std::atoi(argv[5]), std::atoi(argv[6]), std::atoi(argv[7]), argv[8]}};
    if (s.k < 1 || s.k > 64) return std::fprintf(stderr, "K must lie in [1, 64]\n"), 2;
    return run_with(argc, argv, 9, argv[3], firefly::cross_buffer_options{}, set_buffer_option,
                    [&](auto type, const auto& o, int threads) { return run_buffers<decltype(type)>(s, o, threads); });
}

}  // namespace

int main(int argc, char** argv) {
    if (argc > 1 && std::string(argv[1]) == "buffers") return buffers_main(argc, argv);
    if (argc < 7) {
        std::fprintf(stderr, "usage: %s f4|f8 WIDTH HEIGHT COLOR_CHANNELS VARIANCE_CHANNELS DIR [name=value ...]\n", argv[0]);
        return 2;
    }
    const frame_spec s{std::atoi(argv[2]), std::atoi(argv[3]), std::atoi(argv[4]), std::atoi(argv[5]), argv[6]};
    return run_with(argc, argv, 7, argv[1], detector_options{}, set_option,
                    [&](auto type, const auto& o, int threads) { return run<decltype(type)>(s, o, threads); });
}
