"""K buffers (BufferDetector): the C++ library's bytes through the module, K = 2 as the two-half
Detector, pixels left where more than half of the buffers are NaN, and errors as exceptions."""
import subprocess

import numpy as np
import pytest

import firefly
from conftest import assert_gil_released, dtype_code, option_arg, reference_exe, report_as_text, same_bits


def make_buffers(k=4, seed=3, height=40, width=56, color_channels=3, variance_channels=3, dtype=np.float32):
    """K buffers of one noisy frame (each the mean of its own samples) with known defects:
    fireflies in single buffers, a NaN in one buffer, and a highlight every buffer agrees on.
    variance_channels 0: no variance. Returns (colors, variances or None, fireflies)."""
    rng = np.random.default_rng(seed)
    spp = 16
    y, x = np.mgrid[0:height, 0:width]
    radiance = (0.2 + 0.6 * x / width + 0.1 * np.cos(y / 5.0))[..., None] * np.array([1.0, 0.7, 0.5, 1.0])[:color_channels]
    radiance[10:13, 20:23] *= 30  # a highlight
    sigma = 0.5 * radiance
    colors, variances = [], []
    for _ in range(k):
        colors.append(radiance + rng.standard_normal(radiance.shape) * sigma / np.sqrt(spp))
        variances.append(np.broadcast_to((sigma ** 2 / spp) * rng.uniform(0.7, 1.3, radiance.shape), radiance.shape).copy())
    fireflies = [(b % k, p) for b, p in enumerate([(5, 7), (30, 40), (17, 50), (33, 9)])]
    for b, p in fireflies:
        colors[b][p][:3] += 3000.0 / spp
        variances[b][p] += (3000.0 / spp) ** 2 / spp
    colors[1][(25, 25)] = np.nan
    colors = [c.astype(dtype) for c in colors]
    if variance_channels == 0:
        return colors, None, fireflies
    if variance_channels == 1:
        variances = [v[..., :3].mean(axis=-1, keepdims=True) for v in variances]
    return colors, [v.astype(dtype) for v in variances], fireflies


def buffer_report_as_text(rep):
    """The BufferReport in the reference program's "name value" form."""
    d = rep.as_dict()
    out = {}
    for key, v in d.items():
        if key == "per_buffer":
            out.update({"per_buffer.%d" % i: str(n) for i, n in enumerate(v)})
        elif key == "pair":
            if v is not None:
                out.update({"pair." + k: t for k, t in report_as_text(rep.pair).items()})
        elif isinstance(v, dict):
            out[key] = v["code"]
        elif isinstance(v, float):
            out[key] = "%.17g" % v
        else:
            out[key] = str(v)
    return out


def run_reference_buffers(tmp_path, colors, variances, threads=1, **options):
    exe = reference_exe()
    h, w, nc = colors[0].shape
    nv = 0 if variances is None else variances[0].shape[2]
    for i, c in enumerate(colors):
        np.ascontiguousarray(c).tofile(tmp_path / ("color_%d" % i))
        if variances is not None:
            np.ascontiguousarray(variances[i]).tofile(tmp_path / ("variance_%d" % i))
    args = [exe, "buffers", str(len(colors)), dtype_code(colors[0].dtype), str(w), str(h), str(nc), str(nv),
            str(tmp_path), "threads=%d" % threads]
    for key, v in options.items():
        if key == "pair":
            args += [option_arg("pair." + k, x) for k, x in v.items()]
        else:
            args.append(option_arg(key, v))
    done = subprocess.run(args, capture_output=True, text=True, check=True)
    read = lambda name, like: np.fromfile(tmp_path / name, dtype=like.dtype).reshape(like.shape)
    out_c = [read("color_%d" % i, c) for i, c in enumerate(colors)]
    out_v = None if variances is None else [read("variance_%d" % i, v) for i, v in enumerate(variances)]
    masks = [np.fromfile(tmp_path / ("mask_%d" % i), dtype=np.uint8).reshape(h, w) for i in range(len(colors))]
    return out_c, out_v, masks, dict(line.split(" ", 1) for line in done.stdout.splitlines())


def process(colors, variances, threads=1, **options):
    colors = [c.copy() for c in colors]
    variances = None if variances is None else [v.copy() for v in variances]
    masks = [np.zeros(colors[0].shape[:2], np.uint8) for _ in colors]
    rep = firefly.BufferDetector(threads=threads, **options).process(colors, variances, masks)
    return colors, variances, masks, rep


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("k,variance_channels", [(3, 3), (4, 0), (4, 1), (8, 0), (8, 3)])
def test_bit_identical_to_the_library(tmp_path, dtype, k, variance_channels):
    colors, variances, fireflies = make_buffers(k=k, dtype=dtype, variance_channels=variance_channels)
    c, v, m, rep = process(colors, variances)
    rc, rv, rm, ref = run_reference_buffers(tmp_path, colors, variances)
    for x, y in zip(c + (v or []) + m, rc + (rv or []) + rm):
        assert same_bits(x, y)
    assert buffer_report_as_text(rep) == ref
    # a real cleaning, not two no-ops: every firefly found and rebuilt, the NaN repaired
    assert rep.ok and rep.buffers == k and rep.nonfinite == 1
    for b, p in fireflies:
        assert m[b][p] & firefly.MASK_FIREFLY and c[b][p][0] < 10
    assert not np.isnan(c[1][25, 25]).any() and m[1][25, 25] & firefly.MASK_NONFINITE
    assert all(not (mask[10:13, 20:23] & firefly.MASK_FIREFLY).any() for mask in m)  # the highlight stays


def test_bit_identical_with_threads_and_options(tmp_path):
    colors, variances, _ = make_buffers(k=6, seed=9)
    options = dict(use_variance=True, radius=2, false_alarm=1e-3, alpha=0.1, energy_sigma=4.0, refine_noise=False)
    c, v, m, rep = process(colors, variances, threads=2, **options)
    rc, rv, rm, ref = run_reference_buffers(tmp_path, colors, variances, threads=2, **options)
    assert all(same_bits(x, y) for x, y in zip(c + v + m, rc + rv + rm))
    assert buffer_report_as_text(rep) == ref
    one = process(colors, variances, threads=1, **options)
    assert all(same_bits(x, y) for x, y in zip(c + m, one[0] + one[2]))  # any thread count, the same bits


def test_two_buffers_are_the_two_half_detector(tmp_path):
    colors, variances, _ = make_buffers(k=2, seed=5)
    c, v, m, rep = process(colors, variances, pair={"alpha": 0.01, "highlight_rule": "agree"})
    a = {"a_color": colors[0].copy(), "a_variance": variances[0].copy(),
         "b_color": colors[1].copy(), "b_variance": variances[1].copy()}
    ma, mb = (np.zeros(colors[0].shape[:2], np.uint8) for _ in range(2))
    pair = firefly.Detector(alpha=0.01, highlight_rule="agree").process(**a, a_mask=ma, b_mask=mb)
    for x, y in zip(c + v + m, [a["a_color"], a["b_color"], a["a_variance"], a["b_variance"], ma, mb]):
        assert same_bits(x, y)
    assert rep.pair is not None and report_as_text(rep.pair) == report_as_text(pair)
    assert rep.fireflies == pair.half[0].fireflies + pair.half[1].fireflies
    rc, rv, rm, ref = run_reference_buffers(tmp_path, colors, variances, pair={"alpha": 0.01, "highlight_rule": "agree"})
    assert buffer_report_as_text(rep) == ref


def test_an_array_of_buffers_is_a_sequence():
    colors, _, _ = make_buffers(k=5)
    stacked = np.stack(colors)  # (K, H, W, C): its first axis is the buffers, cleaned in place
    masks = np.zeros((5,) + colors[0].shape[:2], np.uint8)
    rep = firefly.BufferDetector().process(stacked, masks=masks)
    c, _, m, listed = process(colors, None)
    assert same_bits(stacked, np.stack(c)) and same_bits(masks, np.stack(m))
    assert rep.as_dict() == listed.as_dict()


def test_buffers_interleaved_innermost_are_not_an_overlap():
    colors, _, _ = make_buffers(k=4, seed=21)
    inner = np.stack(colors, -1).transpose(3, 0, 1, 2)  # memory (H, W, C, K): disjoint, interleaved
    rep = firefly.BufferDetector().process(inner)
    c, _, _, apart = process(colors, None)
    assert rep.as_dict() == apart.as_dict() and rep.fireflies >= 4
    assert same_bits(np.ascontiguousarray(inner), np.stack(c))


def test_two_buffers_report_what_the_pair_detector_left():
    colors, variances, _ = make_buffers(k=2)
    for c in colors:
        c[:] = np.nan
    c, v, m, rep = process(colors, variances)
    assert not rep.ok and rep.left == rep.pair.half[0].unreachable == colors[0].shape[0] * colors[0].shape[1]
    assert all((x == firefly.MASK_NONFINITE | firefly.MASK_LEFT).all() for x in m)


def test_pixels_left_where_most_buffers_are_nan():
    colors, _, _ = make_buffers(k=5)
    for b in range(3):
        colors[b][(3, 3)] = np.nan
    c, _, m, rep = process(colors, None)
    assert not rep.ok and rep.error.code == "no_valid_pixels" and rep.left == 1
    for b in range(5):
        want = firefly.MASK_NONFINITE | firefly.MASK_LEFT if b < 3 else 0
        assert m[b][3, 3] == want
        assert same_bits(c[b][3, 3], colors[b][3, 3])  # left as it was, NaN included
    assert sum(int((x & firefly.MASK_LEFT).any()) for x in m) == 3
    assert firefly.MASK_LEFT == 64


def test_detect_reads_only_and_decides_as_process():
    colors, variances, _ = make_buffers(k=4)
    frozen = [c.copy() for c in colors]
    for c in frozen:
        c.setflags(write=False)
    masks = [np.zeros(colors[0].shape[:2], np.uint8) for _ in colors]
    found = firefly.BufferDetector().detect(frozen, masks=masks)
    assert all(same_bits(x, y) for x, y in zip(frozen, colors))
    _, _, done_masks, done = process(colors, None)
    assert found.fireflies == done.fireflies and found.nonfinite == done.nonfinite
    decided = firefly.MASK_FIREFLY | firefly.MASK_NONFINITE
    assert all(same_bits(x & decided, y & decided) for x, y in zip(masks, done_masks))
    with pytest.raises(TypeError, match="read-only"):
        firefly.BufferDetector().process(frozen)


def test_options_round_trip():
    defaults = firefly.BufferDetector().options
    assert defaults["false_alarm"] == 1e-4 and defaults["pair"] == firefly.Detector().options
    changed = {"alpha": 0.1, "false_alarm": 1e-3, "use_variance": True, "reconstruct": False, "find_dropped": False, "find_implausible": False, "refine_noise": False,
               "radius": 3, "return_energy": False, "energy_sigma": 4.0, "energy_coarse_sigma": 0.0, "energy_density_evidence": 0.0,
               "pair": dict(firefly.Detector().options, alpha=0.01, rebuild="spatial")}
    assert set(changed) == set(defaults)  # every option is covered here
    det = firefly.BufferDetector(threads=2, **changed)
    assert det.options == changed and det.threads == 2
    assert eval(repr(det), {"BufferDetector": firefly.BufferDetector}).options == changed


@pytest.mark.parametrize("call,error,message", [
    (lambda c, v: firefly.BufferDetector().process(c[:1]), ValueError, "at least 2 buffers"),
    (lambda c, v: firefly.BufferDetector().process([]), ValueError, "at least 2 buffers"),
    (lambda c, v: firefly.BufferDetector().process(c[:2]), ValueError, "2 buffers need variance"),
    (lambda c, v: firefly.BufferDetector().process([c[0], c[1][:-1], c[2]]), ValueError, "differ in size"),
    (lambda c, v: firefly.BufferDetector().process([c[0], c[0], c[1]]), ValueError, "overlap|alias|share"),
    (lambda c, v: firefly.BufferDetector().process(c, v[:2]), ValueError, "one array per buffer"),
    (lambda c, v: firefly.BufferDetector().process(c, masks=[np.zeros((2, 2), np.uint8)]), ValueError, "one array per buffer"),
    (lambda c, v: firefly.BufferDetector().process([c[0], c[1].astype(np.float64)]), TypeError, "float32"),
    (lambda c, v: firefly.BufferDetector().process([np.zeros(x.shape, np.int32) for x in c]), TypeError, "float32 or float64"),
    (lambda c, v: firefly.BufferDetector().process(5), TypeError, "sequence of numpy arrays"),
    (lambda c, v: firefly.BufferDetector().process("abc"), TypeError, "sequence of numpy arrays"),
    (lambda c, v: firefly.BufferDetector().process([c[0], [1.0]]), TypeError, "numpy array"),
    (lambda c, v: firefly.BufferDetector(radius=9), ValueError, "radius must lie in"),
    (lambda c, v: firefly.BufferDetector(radius=0), ValueError, r"radius must lie in \[1, 8\]"),
    (lambda c, v: firefly.BufferDetector(false_alarm=0.7), ValueError, "false_alarm must lie in"),
    (lambda c, v: firefly.BufferDetector(bogus=1), TypeError, "unexpected keyword argument 'bogus'"),
    (lambda c, v: firefly.BufferDetector(pair={"bogus": 1}), TypeError, "unexpected keyword argument 'bogus'"),
    (lambda c, v: firefly.BufferDetector(pair={"": 1}), TypeError, "unexpected keyword argument ''"),
    (lambda c, v: firefly.BufferDetector(pair=3), TypeError, "pair must be a dict"),
    (lambda c, v: firefly.BufferDetector(pair={"alpha": 2.0}), ValueError, "alpha"),
    (lambda c, v: firefly.BufferDetector(threads=0), ValueError, r"threads must lie in \[1, 256\]"),
    (lambda c, v: firefly.BufferDetector(radius=np.array(2.7)), TypeError, "radius must be an integer"),  # read as 2
    (lambda c, v: firefly.BufferDetector(pair={b"alpha": 0.3}), TypeError, "keys must be strings"),
    (lambda c, v: firefly.BufferDetector(pair={1: 2}), TypeError, "keys must be strings"),
    (lambda c, v: firefly.BufferDetector().process(np.array(1.0)), ValueError, r"shape \(K, H, W, C\)"),
    (lambda c, v: firefly.BufferDetector().process(c[0]), ValueError, r"shape \(K, H, W, C\)"),  # not H buffers
    (lambda c, v: firefly.BufferDetector().process(range(10 ** 7)), ValueError, "at most 64"),
])
def test_errors_raise_with_the_library_message(call, error, message):
    colors, variances, _ = make_buffers(k=4)
    before = [c.copy() for c in colors]
    with pytest.raises(error, match=message):
        call(colors, variances)
    assert all(same_bits(x, y) for x, y in zip(colors, before))  # refused: nothing written


def test_gil_is_released_and_a_shared_detector_is_serialized():
    import threading
    big, _, _ = make_buffers(k=8, seed=4, height=512, width=512)
    det = firefly.BufferDetector()
    assert_gil_released(lambda: det.detect(big), repeat=2)

    det = firefly.BufferDetector()
    frames = [make_buffers(k=4, seed=s)[0] for s in range(40, 44)]
    reference = [process(f, None)[0] for f in frames]
    copies = [[c.copy() for c in f] for f in frames]
    threads = [threading.Thread(target=det.process, args=(copies[i],)) for i in range(len(frames))]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    for got, ref in zip(copies, reference):
        assert all(same_bits(x, y) for x, y in zip(got, ref))
