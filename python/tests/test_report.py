"""The frame report as attributes and as plain Python types, the options as keywords and
back, the masks, and the module's constants."""
import json
import re

import numpy as np
import pytest

import firefly
from conftest import arrays_of, make_frame, same_bits

HALF_FIELDS = ["pixels", "valid", "ignored", "nonfinite", "dropped", "implausible", "negative_variance", "median", "mad", "bound",
               "outliers", "local", "highlights", "consistent", "frame_kept", "fireflies", "repaired", "from_other_half", "unreachable", "phase1_rounds",
               "phase2_iterations", "final_change", "reconstruction"]
FRAME_FIELDS = ["ok", "error", "both_outliers", "variance_calibration", "single_level", "single_log_level", "lambdas_computed", "scratch_bytes", "stage_ms", "half"]


def public(obj):
    return {n for n in dir(obj) if not n.startswith("_") and n != "as_dict"}


@pytest.fixture
def processed():
    frame = make_frame(alpha=True)
    h, w = frame["a_color"].shape[:2]
    masks = [np.full((h, w), 255, np.uint8) for _ in range(2)]
    rep = firefly.Detector().process(**arrays_of(frame), a_mask=masks[0], b_mask=masks[1])
    return frame, masks, rep


def test_report_fields(processed):
    frame, _, rep = processed
    h, w = frame["a_color"].shape[:2]
    assert set(HALF_FIELDS) <= public(rep.half[0])
    assert set(FRAME_FIELDS) <= public(rep)
    a, b = rep.half
    assert a.pixels == b.pixels == h * w
    assert a.ignored == 4 * h  # the transparent border
    assert a.valid + a.ignored + a.nonfinite == h * w
    assert b.nonfinite == b.repaired == len(frame["nan"])
    assert a.fireflies >= len(frame["fireflies"])
    assert a.highlights >= len(frame["highlights"]) - 1 and b.highlights >= 1
    assert rep.both_outliers >= a.highlights
    assert a.outliers == a.highlights + a.consistent + a.fireflies
    assert a.median > 0 and a.mad > 0 and a.bound >= a.outliers
    assert rep.lambdas_computed > 0 and rep.scratch_bytes > 0 and rep.variance_calibration > 0
    assert rep.ok and rep.error.ok and rep.error.code == "ok"
    assert a.unreachable == b.unreachable == 0 and a.from_other_half <= a.fireflies + a.repaired
    assert a.reconstruction.ok and a.reconstruction.message == "ok"


def test_as_dict_is_plain_python_and_matches_the_attributes(processed):
    _, _, rep = processed
    d = rep.as_dict()
    assert set(d) == public(rep) - {"ok"}  # every field, nothing else
    assert json.loads(json.dumps(d)) == d
    for half, hd in zip(rep.half, d["half"]):
        assert set(hd) == public(half)
        assert hd == half.as_dict()
        for name in HALF_FIELDS:
            value = getattr(half, name)
            assert hd[name] == (value.as_dict() if name == "reconstruction" else value)
    assert d["error"] == {"ok": True, "code": "ok", "message": "ok"}
    assert d["half"][0]["fireflies"] == rep.half[0].fireflies
    assert re.match(r"FrameReport\(\{'error'", repr(rep))


def test_masks(processed):
    frame, masks, rep = processed
    a, b = masks
    for p in frame["fireflies"]:
        assert a[p] & firefly.MASK_FIREFLY
    for p in frame["nan"]:
        assert b[p] & firefly.MASK_NONFINITE
    assert np.count_nonzero(a & firefly.MASK_FIREFLY) == rep.half[0].fireflies
    assert np.count_nonzero(b & firefly.MASK_HIGHLIGHT) == rep.half[1].highlights
    assert np.count_nonzero(a & firefly.MASK_CONSISTENT) == rep.half[0].consistent
    assert np.count_nonzero(a & firefly.MASK_OTHER_HALF) == rep.half[0].from_other_half
    assert np.all(a < 64) and np.all(b < 64)  # every pixel written (they started at 255), none left
    bits = [firefly.MASK_FIREFLY, firefly.MASK_HIGHLIGHT, firefly.MASK_NONFINITE, firefly.MASK_CONSISTENT,
            firefly.MASK_OTHER_HALF, firefly.MASK_ENERGY, firefly.MASK_LEFT]
    assert bits == [1, 2, 4, 8, 16, 32, 64]


def test_options_round_trip():
    defaults = firefly.Detector().options
    assert defaults["highlight_rule"] == "confident" and defaults["alpha"] == 0.05
    changed = {"alpha": 0.01, "bound_threshold": 3.0, "reduction": "max", "lambdas": "normal",
               "highlight_rule": "agree", "max_ratio": 3.0, "max_relative_error": 0.6, "min_excess_z": 0.0,
               "cluster_relative_error": 0.0, "kernel_width": 7, "sigma": 1.5, "tolerance": 1e-2,
               "max_iterations": 0, "rebuild": "spatial", "blend_spatial": False, "reconstruct": False,
               "find_dropped": False, "find_implausible": False, "return_energy": True, "energy_sigma": 4.0, "energy_coarse_sigma": 16.0,
               "energy_density_evidence": 4.0,
               "local_test": False, "local_false_alarm": 1e-3, "local_radius": 2, "local_min_neighbours": 4,
               "local_variance_scale": 2.0, "local_spatial": False, "local_homogeneity": 0.05}
    assert set(changed) == set(defaults)  # every option is covered here
    det = firefly.Detector(threads=2, **changed)
    assert det.options == changed and det.threads == 2
    assert firefly.Detector(**det.options).options == changed
    assert eval(repr(det), {"Detector": firefly.Detector}).options == changed
    for name in defaults:
        assert name + "=" in firefly.Detector.__doc__


def test_options_change_the_result():
    paper, default = arrays_of(make_frame()), arrays_of(make_frame())
    firefly.Detector(highlight_rule="same_pixel", min_excess_z=0.0, kernel_width=3).process(**paper)
    firefly.Detector().process(**default)
    assert not same_bits(paper["a_color"], default["a_color"])


def test_stage_timings():
    rep = firefly.Detector().process(**arrays_of(make_frame()))
    ms = rep.stage_ms
    assert list(ms) == ["candidates", "esd", "local", "highlights", "other_half", "rebuild"]
    assert all(v >= 0 for v in ms.values()) and sum(ms.values()) > 0
    assert rep.as_dict()["stage_ms"] == ms


def test_float64_frame():
    frame = make_frame(dtype=np.float64)
    arrays = arrays_of(frame)
    before = arrays["a_color"].copy()
    rep = firefly.Detector().process(**arrays)
    assert arrays["a_color"].dtype == np.float64
    assert rep.half[0].fireflies >= len(frame["fireflies"])
    changed = np.any(arrays["a_color"] != before, axis=-1)
    assert all(changed[p] for p in frame["fireflies"])
    # nothing else lowered: other changes are the light the energy return gives back
    lowered = np.any(arrays["a_color"] < before, axis=-1)
    assert np.count_nonzero(lowered) == rep.half[0].fireflies
    assert np.all(arrays["a_color"][changed & ~lowered] >= before[changed & ~lowered])


def test_version():
    assert re.fullmatch(r"\d+\.\d+\.\d+", firefly.__version__)


def test_detect_reads_only_and_marks_what_process_rebuilds():
    frame = make_frame(alpha=True)
    arrays = arrays_of(frame)
    for arr in arrays.values():
        arr.flags.writeable = False  # detect() must accept read-only arrays
    h, w = frame["a_color"].shape[:2]
    masks = [np.zeros((h, w), np.uint8) for _ in range(2)]
    found = firefly.Detector().detect(**arrays, a_mask=masks[0], b_mask=masks[1])
    assert all(same_bits(arrays[k], frame[k]) for k in arrays)
    copies = {k: v.copy() for k, v in arrays.items()}
    done_masks = [np.zeros((h, w), np.uint8) for _ in range(2)]
    done = firefly.Detector().process(**copies, a_mask=done_masks[0], b_mask=done_masks[1])
    assert found.half[0].fireflies == done.half[0].fireflies >= len(frame["fireflies"])
    assert found.half[1].highlights == done.half[1].highlights
    for m, d in zip(masks, done_masks):  # the same pixels, without the "rebuilt from" bit
        keep = firefly.MASK_FIREFLY | firefly.MASK_HIGHLIGHT | firefly.MASK_NONFINITE | firefly.MASK_CONSISTENT
        assert same_bits(m & keep, d & keep)


def test_a_frame_with_nothing_to_rebuild_from_returns_a_report():
    frame = make_frame(height=16, width=16)
    arrays = arrays_of(frame)
    for k in ("a_color", "b_color"):
        arrays[k][:] = np.nan
    masks = [np.zeros((16, 16), np.uint8) for _ in range(2)]
    rep = firefly.Detector().process(**arrays, a_mask=masks[0], b_mask=masks[1])
    assert not rep.ok
    assert rep.error.code == "no_valid_pixels" and rep.error.message
    assert rep.half[0].nonfinite == 16 * 16
    for m in masks:  # found and left as it was: the masks say where NaN remains
        assert np.all(m == firefly.MASK_NONFINITE | firefly.MASK_LEFT)
    assert np.all(np.isnan(arrays["a_color"]))
    assert rep.as_dict()["error"]["ok"] is False
    # no valid pixel, no median: NaN (it read 0.0), in the attribute and in as_dict()
    assert np.isnan(rep.half[0].median) and np.isnan(rep.half[1].mad)
    assert np.isnan(rep.as_dict()["half"][0]["median"])


def test_a_bucket_written_black_is_found_and_rebuilt():
    """A 16x16 square black in half A (colour and variance 0) over half B's content: dropped,
    MASK_DROPPED (not MASK_NONFINITE), rebuilt from half B; off with find_dropped=False."""
    frame = make_frame(seed=3)
    frame["a_color"][30:46, 40:56] = 0
    frame["a_variance"][30:46, 40:56] = 0
    h, w = frame["a_color"].shape[:2]
    masks = [np.zeros((h, w), np.uint8) for _ in range(2)]
    kept = {k: v.copy() for k, v in arrays_of(frame).items()}
    rep = firefly.Detector().process(**arrays_of(frame), a_mask=masks[0], b_mask=masks[1])
    assert rep.ok and rep.half[0].dropped == 256 and rep.half[1].dropped == 0
    assert rep.as_dict()["half"][0]["dropped"] == 256
    square = masks[0][30:46, 40:56]
    assert (square & firefly.MASK_DROPPED).all() and not (square & firefly.MASK_NONFINITE).any()
    assert firefly.MASK_DROPPED == 128
    assert (frame["a_color"][30:46, 40:56] > 0).all()
    off = firefly.Detector(find_dropped=False).process(**kept)
    assert off.half[0].dropped == 0 and off.half[0].ignored == 256
    assert (kept["a_color"][30:46, 40:56] == 0).all()


def test_a_bucket_of_garbage_is_found_implausible_and_rebuilt():
    """A 16x16 square of 1e30 in half A's colour, its variance kept: implausible, MASK_NONFINITE,
    rebuilt from half B as a NaN square is, bit for bit; off with find_implausible=False."""
    frames = [make_frame(seed=3) for _ in range(3)]
    frames[0]["a_color"][30:46, 40:56] = 1e30
    frames[1]["a_color"][30:46, 40:56] = np.nan
    frames[2]["a_color"][30:46, 40:56] = 1e30
    h, w = frames[0]["a_color"].shape[:2]
    masks = [[np.zeros((h, w), np.uint8) for _ in range(2)] for _ in range(2)]
    rep = firefly.Detector().process(**arrays_of(frames[0]), a_mask=masks[0][0], b_mask=masks[0][1])
    nan = firefly.Detector().process(**arrays_of(frames[1]), a_mask=masks[1][0], b_mask=masks[1][1])
    assert rep.ok and rep.half[0].implausible == 256 and rep.half[1].implausible == 0
    assert rep.as_dict()["half"][0]["implausible"] == 256 and nan.half[0].nonfinite == 256
    assert (masks[0][0][30:46, 40:56] & firefly.MASK_NONFINITE).all()
    for key in ("a_color", "b_color", "a_variance", "b_variance"):
        assert same_bits(frames[0][key], frames[1][key])
    assert all((a == b).all() for a, b in zip(masks[0], masks[1]))
    assert frames[0]["a_color"].max() < 1e3
    # Off: nothing implausible, nothing rebuilt as non-finite; the square is judged as fireflies
    # are (against half B, its energy given back), so the garbage stays in the frame.
    off_mask = np.zeros((h, w), np.uint8)
    off = firefly.Detector(find_implausible=False).process(**arrays_of(frames[2]), a_mask=off_mask)
    assert off.half[0].implausible == 0 and off.half[0].nonfinite == 0
    assert not (off_mask & firefly.MASK_NONFINITE).any()
    assert frames[2]["a_color"][30:46, 40:56].mean() > 1e28
