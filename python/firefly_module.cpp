// firefly Python module: numpy half buffers (or K buffers) cleaned in place, with no copy.
//
// Arrays are wrapped in image_views with numpy's own byte strides (any layout numpy can
// describe, e.g. px[..., :3] and px[..., 3:6] of one (H, W, 6) array). The library returns
// errors as values; this file turns them into Python exceptions: ValueError for sizes,
// channels and options, TypeError for a wrong type, dtype or a read-only array. The GIL is
// released while a frame is processed.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <climits>
#include <cstdint>
#include <limits>
#include <mutex>
#include <string>
#include <type_traits>
#include <vector>

#include <firefly/version.hpp>

#include "firefly_tables.hpp"

namespace py = pybind11;
using firefly::cross_buffer_options;
using firefly::cross_buffer_report;
using firefly::detector_options;
using firefly::frame_report;
using firefly::half_report;
using firefly::image_view;
using firefly::status;

namespace {

#define FIREFLY_PY_STR2(x) #x
#define FIREFLY_PY_STR(x) FIREFLY_PY_STR2(x)
constexpr const char* version_string = FIREFLY_PY_STR(FIREFLY_VERSION_MAJOR) "." FIREFLY_PY_STR(
    FIREFLY_VERSION_MINOR) "." FIREFLY_PY_STR(FIREFLY_VERSION_PATCH);

// ---------------------------------------------------------------------------------------
// Options: Python values to option members and back.

template <class E>
std::string enum_choices() {
    std::string s;
    for (const auto& nv : firefly_py::enum_names<E>::values) s += (s.empty() ? "'" : ", '") + std::string(nv.first) + "'";
    return s;
}

// A Python bool or a numpy one (a flag read from an array is numpy.bool_, or a 0-d bool array).
bool is_boolean(py::handle v) {
    const py::module_ np = py::module_::import("numpy");
    if (PyBool_Check(v.ptr()) || py::isinstance(v, np.attr("bool_"))) return true;
    return py::isinstance(v, np.attr("ndarray")) && v.attr("dtype").attr("kind").cast<std::string>() == "b";
}

// An array of one or more dimensions is no option value (numpy would read [0.5] as 0.5).
bool is_sized_array(py::handle v) {
    return py::isinstance(v, py::module_::import("numpy").attr("ndarray")) && v.attr("ndim").cast<int>() != 0;
}

template <class T>
T option_from_python(const std::string& name, py::handle v) {
    const bool is_bool = is_boolean(v);
    if (is_sized_array(v)) throw py::type_error(name + " must be a single value, not an array");
    if constexpr (std::is_enum_v<T>) {
        if (!py::isinstance<py::str>(v)) throw py::type_error(name + " must be a string: one of " + enum_choices<T>());
        const std::string s = v.cast<std::string>();
        for (const auto& nv : firefly_py::enum_names<T>::values)
            if (s == nv.first) return nv.second;
        throw py::value_error(name + " must be one of " + enum_choices<T>() + ", not '" + s + "'");
    } else if constexpr (std::is_same_v<T, bool>) {
        if (!is_bool) throw py::type_error(name + " must be True or False");
        return PyObject_IsTrue(v.ptr()) == 1;
    } else if constexpr (std::is_integral_v<T>) {
        // PyNumber_Index, not int(): int() truncates 5.9 held in a 0-d float array to 5.
        const py::object index = is_bool ? py::object() : py::reinterpret_steal<py::object>(PyNumber_Index(v.ptr()));
        if (!index) {
            PyErr_Clear();
            throw py::type_error(name + " must be an integer");
        }
        int overflow = 0;
        const long long x = PyLong_AsLongLongAndOverflow(index.ptr(), &overflow);
        if (overflow != 0 || x < std::numeric_limits<T>::min() || x > std::numeric_limits<T>::max())
            throw py::value_error(name + " is out of range");
        return static_cast<T>(x);
    } else {
        if (is_bool || !PyNumber_Check(v.ptr()) || py::isinstance<py::str>(v))
            throw py::type_error(name + " must be a number");
        const double x = PyFloat_AsDouble(v.ptr());  // an int past DBL_MAX raises OverflowError
        if (x == -1.0 && PyErr_Occurred()) {
            if (!PyErr_ExceptionMatches(PyExc_OverflowError)) throw py::error_already_set();
            PyErr_Clear();
            throw py::value_error(name + " is out of range");
        }
        return static_cast<T>(x);
    }
}

template <class T>
py::object option_to_python(const T& v) {
    if constexpr (std::is_enum_v<T>) {
        const char* name = firefly_py::enum_name(v);  // null: a value missing from firefly_tables.hpp
        return name ? py::str(name) : py::str(std::to_string(static_cast<int>(v)));
    } else {
        return py::cast(v);
    }
}

// The keywords of kw that `list` names, into o; how many there were.
template <class O, class List>
std::size_t read_options(const py::kwargs& kw, O& o, List&& list) {
    std::size_t used = 0;
    list([&](const char* name, auto get) {
        if (!kw.contains(name)) return;
        auto& member = get(o);
        member = option_from_python<std::remove_reference_t<decltype(member)>>(name, kw[name]);
        ++used;
    });
    return used;
}

// TypeError for the first keyword of kw that `list` does not name (nor `extra`, if any).
template <class List>
void refuse_unknown(const py::kwargs& kw, List&& list, const char* cls, const char* extra = nullptr) {
    for (const auto& item : kw) {
        const std::string key = item.first.cast<std::string>();
        bool known = extra != nullptr && key == extra;
        list([&](const char* name, auto) { known |= key == name; });
        if (!known) throw py::type_error(std::string(cls) + " got an unexpected keyword argument '" + key + "'");
    }
}

constexpr auto detector_option_list = [](auto&& f) { firefly_py::for_each_option(f); };
constexpr auto buffer_option_list = [](auto&& f) { firefly_py::for_each_buffer_option(f); };

detector_options options_from_kwargs(const py::kwargs& kw, const char* cls = "Detector()") {
    detector_options o;
    if (read_options(kw, o, detector_option_list) != kw.size()) refuse_unknown(kw, detector_option_list, cls);
    if (const status st = firefly::check_options(o); !st.ok()) throw py::value_error(st.message());
    return o;
}

// BufferDetector's keywords; `pair` is a dict of Detector's (K = 2).
cross_buffer_options buffer_options_from_kwargs(const py::kwargs& kw) {
    cross_buffer_options o;
    std::size_t used = read_options(kw, o, buffer_option_list);
    if (kw.contains("pair")) {
        const py::object pair = kw["pair"];
        if (!py::isinstance<py::dict>(pair)) throw py::type_error("pair must be a dict of Detector() keywords");
        for (const auto& item : py::reinterpret_borrow<py::dict>(pair))  // (**kwargs keys are always str)
            if (!py::isinstance<py::str>(item.first))
                throw py::type_error("pair's keys must be strings (Detector() keywords), not " +
                                     py::str(py::type::handle_of(item.first).attr("__name__")).cast<std::string>());
        o.pair = options_from_kwargs(py::reinterpret_borrow<py::kwargs>(pair), "BufferDetector(pair=...)");
        ++used;
    }
    if (used != kw.size()) refuse_unknown(kw, buffer_option_list, "BufferDetector()", "pair");
    if (const status st = firefly::check_cross_buffer_options(o); !st.ok()) throw py::value_error(st.message());
    return o;
}

py::dict options_to_dict(detector_options o) {
    py::dict d;
    firefly_py::for_each_option([&](const char* name, auto get) { d[name] = option_to_python(get(o)); });
    return d;
}

// before + "name=repr(value)" + after for every keyword of an options dict (docs, repr).
std::string keywords_text(const py::dict& options, const char* before, const char* after = "") {
    std::string s;
    for (auto item : options)
        s += before + item.first.cast<std::string>() + "=" + py::repr(item.second).cast<std::string>() + after;
    return s;
}

py::dict buffer_options_to_dict(cross_buffer_options o) {
    py::dict d;
    firefly_py::for_each_buffer_option([&](const char* name, auto get) { d[name] = option_to_python(get(o)); });
    d["pair"] = options_to_dict(o.pair);
    return d;
}

// ---------------------------------------------------------------------------------------
// Reports: attributes and plain Python values, from the field lists.

py::str status_code(const status& s) {
    const char* code = firefly_py::enum_name(s.code());  // null: a code missing from the table
    return code ? py::str(code) : py::str(std::to_string(static_cast<int>(s.code())));
}

py::dict status_to_dict(const status& s) {
    py::dict d;
    d["ok"] = s.ok();
    d["code"] = status_code(s);
    d["message"] = s.message();
    return d;
}

// The stage timings, by stage name.
py::dict stages_to_dict(const double (&ms)[frame_report::stages]) {
    py::dict d;
    for (const auto& nv : firefly_py::enum_names<frame_report::stage>::values) d[nv.first] = ms[nv.second];
    return d;
}

// A field as plain Python (as_dict), or as an attribute (a Status object for a status).
template <bool attribute, class T>
py::object field_to_python(const T& v) {
    if constexpr (std::is_same_v<T, status>) {
        return attribute ? py::cast(v) : py::object(status_to_dict(v));
    } else if constexpr (std::is_same_v<T, double[frame_report::stages]>) {
        return stages_to_dict(v);
    } else {
        return py::cast(v);
    }
}

py::dict half_to_dict(const half_report& h) {
    py::dict d;
    firefly_py::for_each_half_field([&](const char* name, auto member) { d[name] = field_to_python<false>(h.*member); });
    return d;
}

py::dict frame_to_dict(const frame_report& r) {
    py::dict d;
    firefly_py::for_each_frame_field([&](const char* name, auto member) { d[name] = field_to_python<false>(r.*member); });
    py::list halves;
    halves.append(half_to_dict(r.half[0]));
    halves.append(half_to_dict(r.half[1]));
    d["half"] = halves;
    return d;
}

py::list per_buffer_list(const cross_buffer_report& r) {
    py::list l;
    for (const std::size_t n : r.per_buffer) l.append(n);
    return l;
}

// K buffers: the fields, per_buffer as a list, and (K = 2) the pair detector's report.
py::dict buffer_report_to_dict(const cross_buffer_report& r) {
    py::dict d;
    firefly_py::for_each_buffer_field([&](const char* name, auto member) { d[name] = field_to_python<false>(r.*member); });
    d["per_buffer"] = per_buffer_list(r);
    d["pair"] = r.buffers == 2 ? py::object(frame_to_dict(r.pair)) : py::none();
    return d;
}

std::string half_repr(const half_report& h) {
    return "HalfReport(" + py::repr(half_to_dict(h)).cast<std::string>() + ")";
}

void bind_reports(py::module_& m) {
    py::class_<status>(m, "Status", "A library status: ok, code (a name) and message.")
        .def_property_readonly("ok", &status::ok)
        .def_property_readonly("code", &status_code)
        .def_property_readonly("message", &status::message)
        .def("as_dict", &status_to_dict)
        .def("__repr__", [](const status& s) { return "Status(" + py::repr(status_to_dict(s)).cast<std::string>() + ")"; });

    py::class_<half_report> half(m, "HalfReport", "What the detector found and did in one half buffer.");
    firefly_py::for_each_half_field([&](const char* name, auto member) {
        half.def_property_readonly(name, [member](const half_report& h) { return field_to_python<true>(h.*member); });
    });
    half.def("as_dict", &half_to_dict, "The same fields as plain Python types.");
    half.def("__repr__", &half_repr);

    py::class_<frame_report> frame(m, "FrameReport", "The report of one frame: half[0], half[1] and the frame's fields.");
    firefly_py::for_each_frame_field([&](const char* name, auto member) {
        frame.def_property_readonly(name, [member](const frame_report& r) { return field_to_python<true>(r.*member); });
    });
    frame.def_property_readonly(
        "half", [](const frame_report& r) { return py::make_tuple(r.half[0], r.half[1]); },
        "The two half reports (A, B).");
    frame.def_property_readonly("ok", &frame_report::ok,
                                "True when the frame was checked and every pixel that needed it was rebuilt.");
    frame.def("as_dict", &frame_to_dict, "The same fields as plain Python types (for json.dump).");
    frame.def("__repr__", [](const frame_report& r) {
        return "FrameReport(" + py::repr(frame_to_dict(r)).cast<std::string>() + ")";
    });

    py::class_<cross_buffer_report> buffers(m, "BufferReport",
                                            "The report of one frame of K buffers (BufferDetector).");
    firefly_py::for_each_buffer_field([&](const char* name, auto member) {
        buffers.def_property_readonly(name, [member](const cross_buffer_report& r) { return field_to_python<true>(r.*member); });
    });
    buffers.def_property_readonly(
        "per_buffer", &per_buffer_list,
        "Fireflies and non-finite pixels rebuilt, per buffer (a list of K).");
    buffers.def_property_readonly(
        "pair", [](const cross_buffer_report& r) { return r.buffers == 2 ? py::cast(r.pair) : py::none(); },
        "K = 2: the two-half Detector's FrameReport (the paper's method); else None.");
    buffers.def_property_readonly("ok", &cross_buffer_report::ok,
                                  "True when the frame was checked and no pixel was left unrebuilt.");
    buffers.def("as_dict", &buffer_report_to_dict, "The same fields as plain Python types (for json.dump).");
    buffers.def("__repr__", [](const cross_buffer_report& r) {
        return "BufferReport(" + py::repr(buffer_report_to_dict(r)).cast<std::string>() + ")";
    });
}

// ---------------------------------------------------------------------------------------
// Arrays to views.

// The array behind an argument, or TypeError.
py::array as_array(const char* name, py::handle obj) {
    if (!py::isinstance<py::array>(obj))
        throw py::type_error(std::string(name) + " must be a numpy array, not " +
                             py::str(py::type::handle_of(obj).attr("__name__")).cast<std::string>());
    return py::reinterpret_borrow<py::array>(obj);
}

int checked_extent(const char* name, py::ssize_t n) {
    if (n > INT_MAX) throw py::value_error(std::string(name) + " is too large");
    return static_cast<int>(n);
}

// A view of an (H, W, C) or (H, W) array of T with numpy's strides. `channels` lists the
// accepted channel counts (a 2-D array has 1). A non-const T needs a writeable array.
template <class T>
image_view<T> view_of(const char* name, const py::array& a, std::initializer_list<int> channels, const char* dtype_text) {
    using V = std::remove_const_t<T>;
    if (!py::isinstance<py::array_t<V>>(a))
        throw py::type_error(std::string(name) + " must be " + dtype_text + ", not " + py::str(a.dtype()).cast<std::string>());
    if (!std::is_const_v<T> && !a.writeable())
        throw py::type_error(std::string(name) + " is read-only: firefly writes to it in place");
    if (a.ndim() != 2 && a.ndim() != 3)
        throw py::value_error(std::string(name) + " must have shape (H, W, C) or (H, W), not " +
                              py::str(a.attr("shape")).cast<std::string>());
    const int c = a.ndim() == 3 ? checked_extent(name, a.shape(2)) : 1;
    bool accepted = false;
    std::string list;  // "1 channel", "1 or 3 channels", "1, 2, 3 or 4 channels"
    const std::size_t count = channels.size();
    std::size_t i = 0;
    for (const int k : channels) {
        accepted |= c == k;
        list += (i == 0 ? "" : i + 1 == count ? " or " : ", ") + std::to_string(k);
        ++i;
    }
    list += count == 1 && *channels.begin() == 1 ? " channel" : " channels";
    if (!accepted) throw py::value_error(std::string(name) + " must have " + list + ", not " + std::to_string(c));
    // A zero stride means "packed" to create(); to numpy it means what it says (a broadcast
    // array, every pixel in one place), which a writeable view must not be.
    for (py::ssize_t k = 0; k < a.ndim(); ++k)
        if (a.strides(k) == 0 && a.shape(k) > 1 && a.size() > 0)  // numpy gives empty arrays 0 strides
            throw py::value_error(std::string(name) + ": strides make pixels or channels overlap");
    T* data = static_cast<T*>(const_cast<void*>(a.data()));
    // create() checks the strides' alignment; numpy can also offset the start (frombuffer).
    if (reinterpret_cast<std::uintptr_t>(data) % alignof(T) != 0)
        throw py::value_error(std::string(name) + ": data is not aligned for " + dtype_text);
    auto v = image_view<T>::create(data, checked_extent(name, a.shape(1)), checked_extent(name, a.shape(0)), c,
                                   a.strides(1), a.strides(0), a.ndim() == 3 ? a.strides(2) : firefly::auto_stride);
    if (!v.ok()) throw py::value_error(std::string(name) + ": " + v.error().message());
    return *v;
}

// ---------------------------------------------------------------------------------------
// The detector.

// A library detector (two halves or K buffers), its pool and its lock.
template <class D, class O>
struct py_detector_of {
    py_detector_of(const O& o, int threads)
        : det(o, firefly::executor::threads(static_cast<unsigned>(threads))), threads(threads) {}
    D det;
    int threads;
    std::mutex busy;  // one frame at a time per detector (it owns scratch memory)
};
using py_detector = py_detector_of<firefly::detector, detector_options>;
using py_buffer_detector = py_detector_of<firefly::cross_buffer_detector, cross_buffer_options>;

struct process_args {
    py::object a_color, a_variance, b_color, b_variance, a_alpha, b_alpha, a_mask, b_mask;
};

// C is the channel type of colour and variance: const for detect(), which writes nothing.
template <class C>
auto half_of(const char* const names[3], py::handle color, py::handle variance, py::handle alpha,
             const char* dtype_text) {
    using T = std::remove_const_t<C>;
    firefly::half_buffer<C, C, const T> h;
    h.color = view_of<C>(names[0], as_array(names[0], color), {1, 2, 3, 4}, dtype_text);
    h.variance = view_of<C>(names[1], as_array(names[1], variance), {1, 2, 3, 4}, dtype_text);
    if (!alpha.is_none()) h.alpha = view_of<const T>(names[2], as_array(names[2], alpha), {1}, dtype_text);
    return h;
}

image_view<std::uint8_t> mask_of(const char* name, py::handle mask) {
    if (mask.is_none()) return {};
    return view_of<std::uint8_t>(name, as_array(name, mask), {1}, "uint8");
}

// Refused inputs and options raise; a frame that was processed returns its report, also
// when some pixels had no usable source or were left (report.ok is then False, as in C++).
template <class Report>
Report checked(const Report& r) {
    if (!r.ok() && r.error.code() != firefly::errc::no_valid_pixels) throw py::value_error(r.error.message());
    return r;
}

template <class C>
frame_report run_typed(py_detector& d, const process_args& p, const char* dtype_text) {
    static const char* const names_a[3] = {"a_color", "a_variance", "a_alpha"};
    static const char* const names_b[3] = {"b_color", "b_variance", "b_alpha"};
    const auto a = half_of<C>(names_a, p.a_color, p.a_variance, p.a_alpha, dtype_text);
    const auto b = half_of<C>(names_b, p.b_color, p.b_variance, p.b_alpha, dtype_text);
    const auto ma = mask_of("a_mask", p.a_mask), mb = mask_of("b_mask", p.b_mask);
    frame_report r;
    {
        py::gil_scoped_release release;
        std::lock_guard<std::mutex> lock(d.busy);
        if constexpr (std::is_const_v<C>) {
            r = d.det.detect(a, b, ma, mb);
        } else {
            r = d.det.process(a, b, ma, mb);
        }
    }
    return checked(r);
}

template <class T>
struct type_tag {
    using type = T;
};

// f(type_tag<T>{}, dtype_text) with T the channel type of array `a` named `name` (float or
// double; const unless in_place), or TypeError.
template <bool in_place, class F>
auto by_dtype(const py::array& a, const std::string& name, F&& f) {
    if (py::isinstance<py::array_t<float>>(a))
        return f(type_tag<std::conditional_t<in_place, float, const float>>{}, ("float32 (like " + name + ")").c_str());
    if (py::isinstance<py::array_t<double>>(a))
        return f(type_tag<std::conditional_t<in_place, double, const double>>{}, ("float64 (like " + name + ")").c_str());
    throw py::type_error(name + " must be float32 or float64, not " + py::str(a.dtype()).cast<std::string>());
}

// process() (in place) or detect() (read only), on float32 or float64 arrays.
template <bool in_place>
frame_report run(py_detector& d, const process_args& p) {
    return by_dtype<in_place>(as_array("a_color", p.a_color), "a_color", [&](auto type, const char* dtype_text) {
        return run_typed<typename decltype(type)::type>(d, p, dtype_text);
    });
}

std::string detector_doc() {
    std::string s =
        "Detector(*, threads=1, **options)\n\n"
        "Finds and removes fireflies using the two half buffers of a frame. Keep one per stream of\n"
        "frames: it caches Student-t points and scratch memory across frames. threads: up to this\n"
        "many threads per frame, 1 to 256 (the two halves run in parallel). Options (keyword: default):\n";
    return s + keywords_text(options_to_dict(detector_options{}), "  ", "\n");
}

const char* process_doc =
    "process(a_color, a_variance, b_color, b_variance, a_alpha=None, b_alpha=None, a_mask=None, b_mask=None)\n\n"
    "Cleans both half buffers in place and returns a FrameReport. Arrays: float32 or float64 (all\n"
    "the same), shape (H, W, C), any strides; colour and variance writeable, variance with 1\n"
    "channel or as many as colour; alpha (H, W) or (H, W, 1); masks uint8 (H, W), writeable,\n"
    "receive MASK_* bits per pixel. ValueError for sizes, channels and options, TypeError for a\n"
    "non-array, a wrong dtype or a read-only array. The GIL is released while the frame is processed.\n"
    "A frame with pixels that no usable pixel could rebuild returns a report with ok False (they\n"
    "keep their values; report.error says why).";

const char* detect_doc =
    "detect(a_color, a_variance, b_color, b_variance, a_alpha=None, b_alpha=None, a_mask=None, b_mask=None)\n\n"
    "Like process(), but writes only the masks (what process() would rebuild is marked MASK_FIREFLY\n"
    "or MASK_NONFINITE) and the report; the half buffers are only read and may be read-only.";

// process() and detect(): the same arguments.
template <bool in_place>
void def_run(py::class_<py_detector>& c, const char* name, const char* doc) {
    c.def(
        name,
        [](py_detector& d, py::object ac, py::object av, py::object bc, py::object bv, py::object aa, py::object ba,
           py::object am, py::object bm) { return run<in_place>(d, process_args{ac, av, bc, bv, aa, ba, am, bm}); },
        doc, py::arg("a_color"), py::arg("a_variance"), py::arg("b_color"), py::arg("b_variance"),
        py::arg("a_alpha") = py::none(), py::arg("b_alpha") = py::none(), py::arg("a_mask") = py::none(),
        py::arg("b_mask") = py::none());
}

constexpr int max_threads = 256;

// A detector class: keyword constructor (threads and options), options, threads and repr.
template <class PyDet, class FromKwargs, class ToDict>
py::class_<PyDet> detector_class(py::module_& m, const char* name, const std::string& doc, FromKwargs from_kwargs,
                                 ToDict to_dict, const char* options_doc) {
    py::class_<PyDet> c(m, name, doc.c_str());
    c.def(py::init([from_kwargs](const py::object& threads_given, const py::kwargs& kw) {
              // As the tool's --threads: a count past the machine's threads only costs memory,
              // and thousands can abort the process (glibc, thread-local data).
              const long long threads = option_from_python<long long>("threads", threads_given);
              if (threads < 1 || threads > max_threads)
                  throw py::value_error("threads must lie in [1, " + std::to_string(max_threads) + "]");
              return new PyDet(from_kwargs(kw), static_cast<int>(threads));
          }),
          py::kw_only(), py::arg("threads") = 1)
        .def_property_readonly("options", [to_dict](const PyDet& d) { return to_dict(d.det.options()); }, options_doc)
        .def_property_readonly("threads", [](const PyDet& d) { return d.threads; })
        .def("__repr__", [name, to_dict](const PyDet& d) {
            return std::string(name) + "(threads=" + std::to_string(d.threads) +
                   keywords_text(to_dict(d.det.options()), ", ") + ")";
        });
    return c;
}

void bind_detector(py::module_& m) {
    auto c = detector_class<py_detector>(
        m, "Detector", detector_doc(), [](const py::kwargs& kw) { return options_from_kwargs(kw); }, &options_to_dict,
        "The options, as a dict of keyword: value.");
    def_run<true>(c, "process", process_doc);
    def_run<false>(c, "detect", detect_doc);
}

// ---------------------------------------------------------------------------------------
// K buffers: a sequence of K arrays per argument (a list, a tuple, or an array whose first
// axis is the buffers).

// The items of a sequence argument (kept alive while their views are used): TypeError for a
// non-sequence, ValueError for an array that is not (K, H, W, C) (masks: (K, H, W) too) or
// more than 64 items.
std::vector<py::object> items_of(const char* name, py::handle seq, bool masks = false) {
    if (py::isinstance<py::str>(seq) || !PySequence_Check(seq.ptr()))
        throw py::type_error(std::string(name) + " must be a sequence of numpy arrays, one per buffer, not " +
                             py::str(py::type::handle_of(seq).attr("__name__")).cast<std::string>());
    // One array must be (K, H, W, C): a single (H, W, C) image would pass as H buffers.
    const py::ssize_t ndim = py::isinstance<py::array>(seq) ? py::reinterpret_borrow<py::array>(seq).ndim() : 4;
    if (ndim != 4 && !(masks && ndim == 3))
        throw py::value_error(std::string(name) + " as one array must have shape " +
                              (masks ? "(K, H, W) or (K, H, W, 1)" : "(K, H, W, C)") + ", not " +
                              py::str(seq.attr("shape")).cast<std::string>());
    // Owned references: an array's items are new view objects, freed when no one holds them.
    const py::sequence s = py::reinterpret_borrow<py::sequence>(seq);
    if (s.size() > static_cast<std::size_t>(firefly::detail::max_buffers))
        throw py::value_error(std::string(name) + " holds " + std::to_string(s.size()) + " buffers: at most " +
                              std::to_string(firefly::detail::max_buffers));
    std::vector<py::object> out;
    for (std::size_t i = 0; i < s.size(); ++i) out.push_back(py::object(s[i]));
    return out;
}

// An optional sequence argument: none, or exactly k items.
std::vector<py::object> optional_items(const char* name, py::handle seq, std::size_t k, bool masks = false) {
    if (seq.is_none()) return {};
    std::vector<py::object> out = items_of(name, seq, masks);
    if (out.size() != k)
        throw py::value_error(std::string(name) + " must hold one array per buffer (" + std::to_string(k) +
                              " like colors), not " + std::to_string(out.size()));
    return out;
}

struct buffer_args {
    py::object colors, variances, masks;
};

template <class C>
cross_buffer_report run_buffers_typed(py_buffer_detector& d, const std::vector<py::object>& colors, const buffer_args& p,
                                      const char* dtype_text) {
    const std::vector<py::object> variances = optional_items("variances", p.variances, colors.size());
    const std::vector<py::object> masks = optional_items("masks", p.masks, colors.size(), true);
    std::vector<firefly::buffer_view<C>> views(colors.size());
    std::vector<image_view<std::uint8_t>> mask_views;
    for (std::size_t i = 0; i < colors.size(); ++i) {
        const std::string at = "[" + std::to_string(i) + "]";
        const std::string cn = "colors" + at, vn = "variances" + at, mn = "masks" + at;
        views[i].color = view_of<C>(cn.c_str(), as_array(cn.c_str(), colors[i]), {1, 2, 3, 4}, dtype_text);
        if (!variances.empty())
            views[i].variance = view_of<C>(vn.c_str(), as_array(vn.c_str(), variances[i]), {1, 2, 3, 4}, dtype_text);
        if (!masks.empty()) mask_views.push_back(view_of<std::uint8_t>(mn.c_str(), as_array(mn.c_str(), masks[i]), {1}, "uint8"));
    }
    cross_buffer_report r;
    {
        py::gil_scoped_release release;
        std::lock_guard<std::mutex> lock(d.busy);
        if constexpr (std::is_const_v<C>) {
            r = d.det.detect(views, mask_views);
        } else {
            r = d.det.process(views, mask_views);
        }
    }
    return checked(r);
}

// process() (in place) or detect() (read only), on float32 or float64 arrays.
template <bool in_place>
cross_buffer_report run_buffers(py_buffer_detector& d, const buffer_args& p) {
    const std::vector<py::object> colors = items_of("colors", p.colors);
    if (colors.empty()) throw py::value_error("colors must hold at least 2 buffers, not 0");
    return by_dtype<in_place>(as_array("colors[0]", colors[0]), "colors[0]", [&](auto type, const char* dtype_text) {
        return run_buffers_typed<typename decltype(type)::type>(d, colors, p, dtype_text);
    });
}

std::string buffer_detector_doc() {
    std::string s =
        "BufferDetector(*, threads=1, **options)\n\n"
        "Finds and removes fireflies across K >= 2 independent buffers of one frame (a renderer's\n"
        "sample-index-split buffers, or N renders with different seeds): a buffer is judged against\n"
        "the others at its own pixel and rebuilt from their mean. K = 2 is the two-half Detector\n"
        "(variance needed; its options: pair={...}). Keep one per stream of frames. Options\n"
        "(keyword: default):\n";
    return s + keywords_text(buffer_options_to_dict(cross_buffer_options{}), "  ", "\n");
}

const char* buffer_process_doc =
    "process(colors, variances=None, masks=None)\n\n"
    "Cleans the K buffers in place and returns a BufferReport. colors: K arrays (a list, a tuple, or\n"
    "one (K, H, W, C) array), float32 or float64 (all alike), (H, W, C) with C 1 to 4, writeable, any\n"
    "strides; variances: None or K arrays of the variance of each buffer's mean, 1 channel or as\n"
    "many as colour (needed for K = 2; optional from K = 3, where without them the spread of the\n"
    "buffers estimates the noise; K = 3 uses them when given, K >= 4 with use_variance);\n"
    "masks: None or K uint8 (H, W) arrays (or one (K, H, W)) receiving MASK_* bits. ValueError for\n"
    "sizes, channels, K and options, TypeError for a non-array, a wrong dtype or a read-only array.\n"
    "A frame with pixels left (more than K/2 buffers non-finite; K = 2: no usable value) returns a\n"
    "report with ok False (MASK_LEFT marks them).";

const char* buffer_detect_doc =
    "detect(colors, variances=None, masks=None)\n\n"
    "Like process(), but writes only the masks and the report; the buffers are only read and may be\n"
    "read-only.";

template <bool in_place>
void def_run_buffers(py::class_<py_buffer_detector>& c, const char* name, const char* doc) {
    c.def(
        name,
        [](py_buffer_detector& d, py::object colors, py::object variances, py::object masks) {
            return run_buffers<in_place>(d, buffer_args{colors, variances, masks});
        },
        doc, py::arg("colors"), py::arg("variances") = py::none(), py::arg("masks") = py::none());
}

void bind_buffer_detector(py::module_& m) {
    auto c = detector_class<py_buffer_detector>(m, "BufferDetector", buffer_detector_doc(), &buffer_options_from_kwargs,
                                                &buffer_options_to_dict,
                                                "The options, as a dict of keyword: value (pair: a dict of Detector's).");
    def_run_buffers<true>(c, "process", buffer_process_doc);
    def_run_buffers<false>(c, "detect", buffer_detect_doc);
}

}  // namespace

PYBIND11_MODULE(firefly, m) {
    m.doc() = "firefly: removes fireflies from Monte Carlo renders using two half buffers, or K buffers (numpy, in place).";
    m.attr("__version__") = version_string;
    m.attr("MASK_FIREFLY") = firefly::mask_bits::firefly;
    m.attr("MASK_HIGHLIGHT") = firefly::mask_bits::highlight;
    m.attr("MASK_NONFINITE") = firefly::mask_bits::nonfinite;
    m.attr("MASK_CONSISTENT") = firefly::mask_bits::consistent;
    m.attr("MASK_OTHER_HALF") = firefly::mask_bits::other_half;
    m.attr("MASK_ENERGY") = firefly::mask_bits::energy;
    m.attr("MASK_LEFT") = firefly::mask_bits::left;
    m.attr("MASK_DROPPED") = firefly::mask_bits::dropped;
    bind_reports(m);
    bind_detector(m);
    bind_buffer_detector(m);
}
