"""Shared helpers of the firefly module's tests: a deterministic frame made in numpy and the
C++ reference program (firefly_py_reference, built next to the module) that cleans the same
frame with the library directly."""
import os
import subprocess

import numpy as np
import pytest

import firefly


def make_frame(seed=7, height=72, width=96, color_channels=3, variance_channels=3,
               dtype=np.float32, alpha=False):
    """Two half buffers of a smooth scene with Monte Carlo noise and known defects.

    Returns a dict: a_color, a_variance, b_color, b_variance (and a_alpha, b_alpha), plus
    'fireflies' (pixels with a firefly in half A), 'highlights' (bright in both halves)
    and 'nan' (a NaN pixel in half B)."""
    rng = np.random.default_rng(seed)
    spp = 32
    y, x = np.mgrid[0:height, 0:width]
    base = 0.25 + 0.5 * (x / width) + 0.2 * np.sin(y / 7.0)
    tint = np.array([1.0, 0.8, 0.6, 1.0])[:color_channels]
    radiance = base[..., None] * tint
    sigma = 0.6 * radiance  # per-sample standard deviation
    out = {}
    inside = lambda points: [(y, x) for y, x in points if y < height and x < width]
    highlights = inside([(20, 30), (20, 31), (21, 30), (21, 31)])
    fireflies = inside([(5, 7), (40, 60), (60, 12), (33, 90)])
    for h in "ab":
        color = radiance + rng.standard_normal(radiance.shape) * sigma / np.sqrt(spp)
        samples = np.sqrt(spp) * np.abs(rng.standard_normal(radiance.shape))
        var = (sigma * samples / np.sqrt(spp)) ** 2 / spp
        for p in highlights:  # many samples that agree: bright, low relative error
            color[p] *= 40
            var[p] *= 40 ** 2
        if variance_channels == 1:
            var = var[..., :3].mean(axis=-1, keepdims=True)
        out[h + "_color"] = color.astype(dtype)
        out[h + "_variance"] = var.astype(dtype)
        if alpha:
            a = np.ones((height, width), dtype)
            a[:, :4] = 0  # a transparent border: ignored
            out[h + "_alpha"] = a
    for p in fireflies:  # one sample of 2000 in half A
        out["a_color"][p][:3] += 2000 / spp
        out["a_variance"][p] += (2000 / spp) ** 2 / spp
    nan = inside([(50, 50)])
    for p in nan:
        out["b_color"][p] = np.nan
    out["fireflies"], out["highlights"], out["nan"] = fireflies, highlights, nan
    return out


ARRAYS = ["a_color", "a_variance", "b_color", "b_variance", "a_alpha", "b_alpha"]


def arrays_of(frame):
    return {k: frame[k] for k in ARRAYS if k in frame}


def reference_exe():
    """The reference program (firefly_py_reference), or a skip outside ctest."""
    exe = os.environ.get("FIREFLY_PY_REFERENCE")
    if not exe:
        pytest.skip("FIREFLY_PY_REFERENCE is not set (run the tests through ctest)")
    return exe


def dtype_code(dtype):
    """The reference program's name for a dtype."""
    return {np.dtype(np.float32): "f4", np.dtype(np.float64): "f8"}[np.dtype(dtype)]


def option_arg(name, value):
    """An option as the reference program reads it: name=value (repr() but for strings)."""
    return "%s=%s" % (name, value if isinstance(value, str) else repr(value))


def run_reference(tmp_path, frame, threads=1, **options):
    """Cleans the frame with the C++ library; returns (arrays, masks, report as text dict)."""
    exe = reference_exe()
    arrays = arrays_of(frame)
    for name, arr in arrays.items():
        np.ascontiguousarray(arr).tofile(tmp_path / name)
    color = arrays["a_color"]
    h, w, nc = color.shape
    nv = arrays["a_variance"].shape[2] if arrays["a_variance"].ndim == 3 else 1
    args = [exe, dtype_code(color.dtype), str(w), str(h), str(nc), str(nv), str(tmp_path), "threads=%d" % threads]
    args += [option_arg(k, v) for k, v in options.items()]
    done = subprocess.run(args, capture_output=True, text=True, check=True)
    out = {name: np.fromfile(tmp_path / name, dtype=color.dtype).reshape(arr.shape)
           for name, arr in arrays.items()}
    masks = [np.fromfile(tmp_path / m, dtype=np.uint8).reshape(h, w) for m in ("a_mask", "b_mask")]
    report = dict(line.split(" ", 1) for line in done.stdout.splitlines())
    return out, masks, report


def report_as_text(rep):
    """The module's report in the reference program's "name value" form."""
    def text(v):
        if isinstance(v, dict):  # a status
            return v["code"]
        if isinstance(v, float):
            return "%.17g" % v
        return str(v)
    d = rep.as_dict()
    out = {k: text(v) for k, v in d.items() if k not in ("half", "stage_ms")}  # stage_ms: timings
    for h, half in zip("ab", d["half"]):
        out.update({"%s.%s" % (h, k): text(v) for k, v in half.items()})
    return out


def assert_gil_released(call, repeat=3):
    """Asserts that call() (a long library call) releases the GIL: under a switch interval so
    long that a thread holding the GIL is never interrupted, this thread runs again while the
    worker is still inside its calls. No timing."""
    import sys
    import threading
    entered, state = threading.Event(), {"done": False}

    def worker():
        entered.set()
        for _ in range(repeat):  # a long window for this thread to be scheduled in
            call()  # the GIL is released only inside
        state["done"] = True

    old = sys.getswitchinterval()
    sys.setswitchinterval(1000.0)  # a thread holding the GIL keeps it until it blocks
    try:
        t = threading.Thread(target=worker)
        t.start()
        entered.wait()
        # This thread runs again only once the worker gives up the GIL. Had the call kept it,
        # that would be after the calls returned and `done` was set.
        done_when_we_ran = state["done"]
    finally:
        sys.setswitchinterval(old)
        t.join()
    assert not done_when_we_ran
    assert state["done"]


def same_bits(x, y):
    return x.dtype == y.dtype and x.shape == y.shape and np.ascontiguousarray(x).tobytes() == np.ascontiguousarray(y).tobytes()


@pytest.fixture
def frame():
    return make_frame()


@pytest.fixture
def detector():
    return firefly.Detector()
