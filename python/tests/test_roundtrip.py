"""The module gives the C++ library's bytes: same cleaned arrays, masks and report as the
reference program, for every dtype, layout and option set; and it cleans strided views in
place without a copy."""
import os
import subprocess

import numpy as np
import pytest

import firefly
from conftest import arrays_of, make_frame, report_as_text, run_reference, same_bits


def process(frame, threads=1, layout=lambda a: a, **options):
    """Cleans copies of the frame through `layout` (a function giving the view to pass)."""
    arrays = {k: layout(v.copy()) for k, v in arrays_of(frame).items()}
    h, w = frame["a_color"].shape[:2]
    masks = [np.zeros((h, w), np.uint8) for _ in range(2)]
    rep = firefly.Detector(threads=threads, **options).process(**arrays, a_mask=masks[0], b_mask=masks[1])
    return arrays, masks, rep


def assert_matches_reference(tmp_path, frame, threads=1, **options):
    arrays, masks, rep = process(frame, threads, **options)
    ref, ref_masks, ref_rep = run_reference(tmp_path, frame, threads, **options)
    for name in arrays:
        assert same_bits(arrays[name], ref[name]), name
    for m, r in zip(masks, ref_masks):
        assert same_bits(m, r)
    assert report_as_text(rep) == ref_rep
    return rep


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("channels", [(3, 3), (3, 1), (4, 4), (4, 1)])
def test_bit_identical_to_the_library(tmp_path, dtype, channels):
    frame = make_frame(dtype=dtype, color_channels=channels[0], variance_channels=channels[1])
    rep = assert_matches_reference(tmp_path, frame)
    # The frame's defects were found: this compares a real cleaning, not two no-ops.
    assert rep.half[0].fireflies >= len(frame["fireflies"])
    assert rep.half[0].highlights >= 1 and rep.half[1].highlights >= 1
    assert rep.half[1].repaired == 1


def test_bit_identical_with_alpha_threads_and_options(tmp_path):
    frame = make_frame(alpha=True, seed=11)
    rep = assert_matches_reference(tmp_path, frame, threads=2, alpha=0.01, highlight_rule="same_pixel",
                                   kernel_width=3, sigma=0.8, reduction="luminance", lambdas="hill",
                                   max_iterations=5, min_excess_z=2.5)
    assert rep.half[0].ignored == 4 * frame["a_color"].shape[0]


def test_detect_only_changes_nothing(tmp_path, frame):
    before = {k: v.copy() for k, v in arrays_of(frame).items()}
    arrays, masks, rep = process(frame, reconstruct=False)
    for k in before:
        assert same_bits(arrays[k], before[k]), k
    assert rep.half[0].fireflies >= len(frame["fireflies"])
    assert_matches_reference(tmp_path, frame, reconstruct=False)


def oiio_layout(arr):
    """The array as a view into a wider interleaved buffer, like px[..., :3] of an EXR with
    colour and variance channels."""
    h, w, c = arr.shape
    wide = np.full((h, w, c + 3), -1, arr.dtype)
    wide[..., 1:1 + c] = arr
    return wide[..., 1:1 + c]


LAYOUTS = {
    "interleaved_in_wider": oiio_layout,
    "fortran_order": np.asfortranarray,
    "planar": lambda a: np.moveaxis(np.ascontiguousarray(np.moveaxis(a, -1, 0)), 0, -1),
    "bottom_up": lambda a: np.ascontiguousarray(a[::-1])[::-1],
    "mirrored_channels": lambda a: np.ascontiguousarray(a[..., ::-1])[..., ::-1],
    "padded_rows": lambda a: np.pad(a, ((0, 0), (0, 5), (0, 0)))[:, :a.shape[1]],
}


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_any_strides_same_bits(layout, dtype):
    frame = make_frame(dtype=dtype)
    packed, packed_masks, packed_rep = process(frame)
    arrays, masks, rep = process(frame, layout=LAYOUTS[layout])
    assert not arrays["a_color"].flags.c_contiguous
    for k in packed:
        assert same_bits(arrays[k], packed[k]), k
    assert report_as_text(rep) == report_as_text(packed_rep)
    assert all(same_bits(m, p) for m, p in zip(masks, packed_masks))


def test_colour_and_variance_of_one_array_cleaned_in_place():
    frame = make_frame()
    reference, _, _ = process(frame)
    h, w, _ = frame["a_color"].shape
    px = {}
    for half in "ab":
        px[half] = np.empty((h, w, 7), np.float32)  # R G B VR VG VB A, as one EXR holds them
        px[half][..., :3] = frame[half + "_color"]
        px[half][..., 3:6] = frame[half + "_variance"]
        px[half][..., 6] = 1
    a_color, a_var = px["a"][..., :3], px["a"][..., 3:6]
    firefly.Detector().process(a_color, a_var, px["b"][..., :3], px["b"][..., 3:6],
                               a_alpha=px["a"][..., 6], b_alpha=px["b"][..., 6:7])
    assert np.shares_memory(a_color, px["a"])  # the views we passed, not copies
    assert same_bits(np.ascontiguousarray(px["a"][..., :3]), reference["a_color"])
    assert same_bits(np.ascontiguousarray(px["b"][..., 3:6]), reference["b_variance"])
    assert np.all(px["a"][..., 6] == 1)  # alpha untouched


def test_second_frame_reuses_the_lambda_cache():
    det = firefly.Detector()
    first = det.process(**{k: v.copy() for k, v in arrays_of(make_frame()).items()})
    second = det.process(**{k: v.copy() for k, v in arrays_of(make_frame()).items()})
    assert first.lambdas_computed > 0
    assert second.lambdas_computed == 0


def write_pfm(path, img):
    """PFM: bottom-up rows of little-endian float32."""
    h, w, c = img.shape
    with open(path, "wb") as f:
        f.write(b"PF\n" if c == 3 else b"Pf\n")
        f.write(b"%d %d\n-1.0\n" % (w, h))
        f.write(np.ascontiguousarray(img[::-1], dtype="<f4").tobytes())


def test_bit_identical_to_the_command_line_tool(tmp_path):
    cli = os.environ.get("FIREFLY_CLI")
    if not cli:
        pytest.skip("the command-line tool is not built (it needs OpenEXR)")
    oiio = pytest.importorskip("OpenImageIO")
    frame = make_frame()
    for k in ("a_color", "a_variance", "b_color", "b_variance"):
        write_pfm(tmp_path / (k + ".pfm"), frame[k])
    subprocess.run([cli, str(tmp_path / "a_color.pfm"), str(tmp_path / "b_color.pfm"),
                    "--variance-a", str(tmp_path / "a_variance.pfm"), "--variance-b", str(tmp_path / "b_variance.pfm"),
                    "-o", str(tmp_path / "clean.exr"), "--halves", str(tmp_path / "half")],
                   check=True, capture_output=True)
    arrays, _, rep = process(frame)
    assert rep.half[0].fireflies >= len(frame["fireflies"])
    for half in "ab":
        buf = oiio.ImageBuf(str(tmp_path / ("half_%s.exr" % half)))
        px = buf.get_pixels(oiio.FLOAT)
        names = list(buf.spec().channelnames)
        pick = lambda channels: np.ascontiguousarray(px[..., [names.index(c) for c in channels]])
        assert same_bits(pick(["R", "G", "B"]), arrays[half + "_color"])
        assert same_bits(pick(["Variance.R", "Variance.G", "Variance.B"]), arrays[half + "_variance"])
