"""Every refusal is a Python exception carrying the library's (or the binding's) message:
ValueError for sizes, channels and options; TypeError for a non-array, a wrong dtype or a
read-only array. Nothing is written when a frame is refused."""
import numpy as np
import pytest

import firefly
from conftest import arrays_of, make_frame, same_bits


def call(detector=None, **changes):
    """process() on a fresh frame with some arguments replaced; returns the untouched copy
    too, so a test can check that nothing was written."""
    args = {k: v.copy() for k, v in arrays_of(make_frame()).items()}
    args.update(changes)
    before = {k: np.array(v, copy=True) for k, v in args.items() if isinstance(v, np.ndarray)}
    try:
        (detector or firefly.Detector()).process(**args)
    finally:
        for k, v in before.items():
            assert same_bits(np.asarray(args[k]), v), k + " was written although the frame was refused"


def frame_shape():
    return make_frame()["a_color"].shape


@pytest.mark.parametrize("name", ["a_color", "a_variance", "b_color", "b_variance", "a_alpha", "b_mask"])
@pytest.mark.parametrize("value", [[[1.0, 2.0, 3.0]], "pixels", 3.0])
def test_non_array_is_a_type_error(name, value):
    with pytest.raises(TypeError, match=name + " must be a numpy array"):
        call(**{name: value})


@pytest.mark.parametrize("dtype", [np.float16, np.int32, np.uint8, np.complex64, ">f4"])
def test_colour_dtype_is_a_type_error(dtype):
    h, w, c = frame_shape()
    with pytest.raises(TypeError, match="a_color must be float32 or float64"):
        call(a_color=np.ones((h, w, c), dtype))


@pytest.mark.parametrize("name", ["a_variance", "b_color", "b_variance", "a_alpha"])
def test_mixed_float_dtypes_are_a_type_error(name):
    arr = make_frame(alpha=True)[name].astype(np.float64)
    with pytest.raises(TypeError, match=name + r" must be float32 \(like a_color\), not float64"):
        call(**{name: arr})


def test_mask_dtype_is_a_type_error():
    h, w, _ = frame_shape()
    with pytest.raises(TypeError, match="a_mask must be uint8, not bool"):
        call(a_mask=np.zeros((h, w), bool))


@pytest.mark.parametrize("name", ["a_color", "b_variance", "a_mask"])
def test_read_only_is_a_type_error(name):
    h, w, _ = frame_shape()
    arr = make_frame()[name] if name != "a_mask" else np.zeros((h, w), np.uint8)
    arr.flags.writeable = False
    with pytest.raises(TypeError, match=name + " is read-only"):
        call(**{name: arr})


def test_read_only_alpha_is_accepted():
    frame = make_frame(alpha=True)
    frame["a_alpha"].flags.writeable = False
    rep = firefly.Detector().process(**arrays_of(frame))
    assert rep.half[0].ignored > 0


def test_broadcast_array_is_refused():
    h, w, c = frame_shape()
    ro = np.broadcast_to(np.float32(1), (h, w, c))
    with pytest.raises(TypeError, match="read-only"):
        call(a_variance=ro)
    rw = np.lib.stride_tricks.as_strided(np.ones(3, np.float32), (h, w, c), (0, 0, 4), writeable=True)
    with pytest.raises(ValueError, match="a_variance: strides make pixels or channels overlap"):
        call(a_variance=rw)


def test_overlapping_strides_are_refused():
    h, w, c = frame_shape()
    base = np.ones(h * w * c, np.float32)
    overlapping = np.lib.stride_tricks.as_strided(base, (h, w, c), (w * 4, 4, 4), writeable=True)
    with pytest.raises(ValueError, match="b_color: strides make pixels or channels overlap"):
        call(b_color=overlapping)


def test_misaligned_data_is_refused():
    h, w, c = frame_shape()
    raw = bytearray(h * w * c * 4 + 1)
    misaligned = np.frombuffer(raw, np.float32, offset=1).reshape(h, w, c)
    with pytest.raises(ValueError, match="a_color: data is not aligned"):
        call(a_color=misaligned)


@pytest.mark.parametrize("shape,match", [
    ((72,), r"a_color must have shape \(H, W, C\) or \(H, W\)"),
    ((72, 96, 3, 1), r"a_color must have shape \(H, W, C\) or \(H, W\)"),
    ((72, 96, 5), "a_color must have 1, 2, 3 or 4 channels, not 5"),
    ((72, 96, 0), "a_color must have 1, 2, 3 or 4 channels, not 0"),
    ((0, 96, 3), "colour image is empty"),
    ((72, 95, 3), "variance and colour differ in size"),
])
def test_colour_shape_is_a_value_error(shape, match):
    with pytest.raises(ValueError, match=match):
        call(a_color=np.ones(shape, np.float32))


def test_variance_channels_are_a_value_error():
    h, w, _ = frame_shape()
    with pytest.raises(ValueError, match="variance needs 1 channel or as many channels as colour"):
        call(a_variance=np.ones((h, w, 2), np.float32))


def test_alpha_shape_is_a_value_error():
    h, w, _ = frame_shape()
    with pytest.raises(ValueError, match="a_alpha must have 1 channel, not 3"):
        call(a_alpha=np.ones((h, w, 3), np.float32))
    with pytest.raises(ValueError, match="alpha and colour differ in size"):
        call(b_alpha=np.ones((h + 1, w), np.float32))


def test_halves_of_different_size_or_channels_are_a_value_error():
    small = make_frame(height=40)
    with pytest.raises(ValueError, match="the two halves differ in size"):
        call(b_color=small["b_color"], b_variance=small["b_variance"])
    one = make_frame(variance_channels=1)
    with pytest.raises(ValueError, match="the two halves differ in channels"):
        call(b_variance=one["b_variance"])


def test_mask_size_is_a_value_error():
    h, w, _ = frame_shape()
    with pytest.raises(ValueError, match="a mask must be 1 channel, frame-sized"):
        call(a_mask=np.zeros((h, w + 1), np.uint8))
    with pytest.raises(ValueError, match="b_mask must have 1 channel, not 2"):
        call(b_mask=np.zeros((h, w, 2), np.uint8))


@pytest.mark.parametrize("options,match", [
    ({"alpha": 1.5}, "alpha must lie in"),
    ({"alpha": float("nan")}, "alpha must lie in"),
    ({"bound_threshold": -1.0}, "bound threshold must be finite"),
    ({"max_ratio": 0.5}, "highlight: max_ratio >= 1"),
    ({"kernel_width": 4}, "kernel"),
    ({"highlight_rule": "brightest"}, "highlight_rule must be one of 'same_pixel', 'agree', 'confident', 'confident_and_agree', not 'brightest'"),
    ({"lambdas": "fast"}, "lambdas must be one of"),
    ({"reduction": "median"}, "reduction must be one of"),
    ({"kernel_width": 2 ** 40}, "kernel_width is out of range"),
    ({"max_iterations": 2 ** 80}, "max_iterations is out of range"),
    ({"alpha": 10 ** 400}, "alpha is out of range"),
    ({"threads": 0}, r"threads must lie in \[1, 256\]"),
    ({"threads": 257}, r"threads must lie in \[1, 256\]"),  # 400 aborted the interpreter
    ({"threads": 2 ** 31}, r"threads must lie in \[1, 256\]"),  # a TypeError of pybind11 before
    ({"threads": 2 ** 70}, "threads is out of range"),
])
def test_bad_option_value_is_a_value_error(options, match):
    with pytest.raises(ValueError, match=match):
        firefly.Detector(**options)


@pytest.mark.parametrize("options,match", [
    ({"alpha": "0.05"}, "alpha must be a number"),
    ({"alpha": True}, "alpha must be a number"),
    ({"kernel_width": 5.0}, "kernel_width must be an integer"),
    ({"reconstruct": 1}, "reconstruct must be True or False"),
    ({"kernel_width": np.bool_(True)}, "kernel_width must be an integer"),
    ({"alpha": np.bool_(True)}, "alpha must be a number"),
    # 0-d arrays are read as their value, but not truncated or taken as a number when bool
    ({"kernel_width": np.array(5.9)}, "kernel_width must be an integer"),  # read as 5
    ({"max_iterations": np.array(7.8)}, "max_iterations must be an integer"),
    ({"local_radius": np.array(True)}, "local_radius must be an integer"),  # read as 1
    ({"sigma": np.array(True)}, "sigma must be a number"),  # read as 1.0
    ({"sigma": np.array([0.5])}, "sigma must be a single value, not an array"),
    ({"kernel_width": np.array([5])}, "kernel_width must be a single value"),
    ({"threads": 2.0}, "threads must be an integer"),
    ({"highlight_rule": 2}, "highlight_rule must be a string"),
    ({"kernelwidth": 5}, "unexpected keyword argument 'kernelwidth'"),
    ({"": 5}, "unexpected keyword argument ''"),
])
def test_bad_option_type_or_name_is_a_type_error(options, match):
    with pytest.raises(TypeError, match=match):
        firefly.Detector(**options)


def test_numpy_scalars_are_accepted_as_options():
    det = firefly.Detector(alpha=np.float32(0.25), kernel_width=np.int64(3))
    assert det.options["alpha"] == 0.25 and det.options["kernel_width"] == 3
    det = firefly.Detector(sigma=np.array(1.5), kernel_width=np.array(7), threads=np.int32(2))
    assert det.options["sigma"] == 1.5 and det.options["kernel_width"] == 7 and det.threads == 2
    for flag in (np.bool_(False), np.bool_(True)):
        assert firefly.Detector(reconstruct=flag).options["reconstruct"] == bool(flag)


def test_a_refused_frame_leaves_the_detector_usable():
    det = firefly.Detector()
    with pytest.raises(ValueError):
        call(det, a_color=np.ones((5, 5, 3), np.float32))
    frame = make_frame()
    rep = det.process(**arrays_of(frame))
    assert rep.half[0].fireflies >= len(frame["fireflies"])


def test_views_sharing_memory_are_a_value_error():
    frame = make_frame()
    with pytest.raises(ValueError, match="must not share memory"):
        call(b_color=frame["a_color"], a_color=frame["a_color"])
    h, w, _ = frame_shape()
    px = np.zeros((h, w, 6), np.float32)  # variance overlapping colour by one channel
    with pytest.raises(ValueError, match="must not share memory"):
        call(a_color=px[..., :3], a_variance=px[..., 2:5])
    mask = np.zeros((h, w), np.uint8)
    with pytest.raises(ValueError, match="the two masks share memory"):
        call(a_mask=mask, b_mask=mask)
