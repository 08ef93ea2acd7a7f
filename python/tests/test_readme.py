"""The README's Python example runs as written, on EXRs written here with OpenImageIO, and
gives the module's (and the command-line tool's) bits; `cmake --install` puts an importable
module under the prefix. Where ../shared/data is next to the repository: the count the README
quotes for its example on the example render, and docs/'s pictures, are the current output."""
import os
import re
import subprocess
import sys

import numpy as np
import pytest

import firefly
from conftest import make_frame, same_bits

NAMES = ["R", "G", "B", "Variance.R", "Variance.G", "Variance.B"]


def python_section():
    path = os.environ.get("FIREFLY_README")
    if not path:
        pytest.skip("FIREFLY_README is not set (run the tests through ctest)")
    text = open(path, encoding="utf-8").read()
    return text.split("\n## Python\n", 1)[1].split("\n## ", 1)[0]


def readme_examples():
    return re.findall(r"```python\n(.*?)```", python_section(), re.S)


def readme_example():
    return readme_examples()[0]


def write_half(oiio, path, color, variance):
    # The variance channels first and reversed: the example must pick channels by name.
    order = ["Variance.B", "Variance.G", "Variance.R", "R", "G", "B"]
    px = np.concatenate([color, variance], axis=-1)[..., [NAMES.index(n) for n in order]]
    spec = oiio.ImageSpec(px.shape[1], px.shape[0], 6, oiio.FLOAT)
    spec.channelnames = tuple(order)
    buf = oiio.ImageBuf(spec)
    buf.set_pixels(oiio.ROI(), np.ascontiguousarray(px))
    assert buf.write(str(path)), oiio.geterror()


def test_readme_example_runs_and_matches(tmp_path):
    oiio = pytest.importorskip("OpenImageIO")
    code = readme_example()
    assert len(code.strip().splitlines()) <= 12
    frame = make_frame(seed=4)
    write_half(oiio, tmp_path / "half_a.exr", frame["a_color"], frame["a_variance"])
    write_half(oiio, tmp_path / "half_b.exr", frame["b_color"], frame["b_variance"])
    env = dict(os.environ)
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr

    arrays = {k: frame[k].copy() for k in ("a_color", "a_variance", "b_color", "b_variance")}
    rep = firefly.Detector().process(**arrays)
    removed = rep.half[0].fireflies + rep.half[1].fireflies
    assert removed >= len(frame["fireflies"])
    assert done.stdout.strip() == "%d fireflies removed" % removed
    clean = oiio.ImageBuf(str(tmp_path / "clean.exr")).get_pixels(oiio.FLOAT)
    assert same_bits(clean, 0.5 * arrays["a_color"] + 0.5 * arrays["b_color"])

    cli = os.environ.get("FIREFLY_CLI")
    if cli:  # the command-line tool's combined colour, from the same files
        subprocess.run([cli, "half_a.exr", "half_b.exr", "-o", "cli.exr"], cwd=tmp_path, check=True,
                       capture_output=True)
        buf = oiio.ImageBuf(str(tmp_path / "cli.exr"))
        names = list(buf.spec().channelnames)
        px = buf.get_pixels(oiio.FLOAT)[..., [names.index(c) for c in ("R", "G", "B")]]
        assert same_bits(clean, np.ascontiguousarray(px))


def test_readme_buffers_example_runs_and_matches(tmp_path):
    oiio = pytest.importorskip("OpenImageIO")
    from test_buffers import make_buffers
    code = readme_examples()[1]
    assert len(code.strip().splitlines()) <= 8
    colors, _, _ = make_buffers(k=4, seed=12, variance_channels=0)
    for i, c in enumerate(colors):
        spec = oiio.ImageSpec(c.shape[1], c.shape[0], 4, oiio.FLOAT)  # RGBA, as Blender writes
        buf = oiio.ImageBuf(spec)
        buf.set_pixels(oiio.ROI(), np.ascontiguousarray(np.concatenate([c, np.ones_like(c[..., :1])], axis=-1)))
        assert buf.write(str(tmp_path / ("render_%d.exr" % i))), oiio.geterror()
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    cleaned = np.stack(colors)
    rep = firefly.BufferDetector().process(cleaned)
    assert rep.fireflies >= 4
    assert done.stdout.strip() == "%d fireflies removed from 4 renders" % rep.fireflies
    clean = oiio.ImageBuf(str(tmp_path / "clean.exr")).get_pixels(oiio.FLOAT)
    assert same_bits(clean, cleaned.mean(axis=0))


def test_install_puts_an_importable_module_under_the_prefix(tmp_path):
    build, site = os.environ.get("FIREFLY_BUILD_DIR"), os.environ.get("FIREFLY_PYTHON_INSTALL_DIR")
    if not build or not site:
        pytest.skip("FIREFLY_BUILD_DIR is not set (run the tests through ctest)")
    cmake = os.environ.get("CMAKE_COMMAND", "cmake")
    subprocess.run([cmake, "--install", build, "--component", "python", "--prefix", str(tmp_path)],
                   check=True, capture_output=True)
    installed = list((tmp_path / site).glob("firefly*.so"))
    assert len(installed) == 1
    env = dict(os.environ, PYTHONPATH=str(tmp_path / site))
    done = subprocess.run([sys.executable, "-c", "import firefly; print(firefly.__file__, firefly.__version__)"],
                          env=env, cwd=tmp_path, capture_output=True, text=True, check=True)
    assert done.stdout.split()[0] == str(installed[0])
    assert done.stdout.split()[1] == firefly.__version__


def test_readme_lists_every_option():
    section = python_section()
    listed = re.search(r"flattened \((.*?)\), enums", section, re.S).group(1)
    assert set(re.findall(r"`(\w+)`", listed)) == set(firefly.Detector().options)
    listed = re.search(r"member is a\s+keyword \((.*?)\), and `pair`", section, re.S).group(1)
    assert set(re.findall(r"`(\w+)`", listed)) | {"pair"} == set(firefly.BufferDetector().options)


def shared_render(name):
    """../shared/data/NAME next to the repository, or a skip where a clone has none."""
    path = os.environ.get("FIREFLY_README")
    if not path:
        pytest.skip("FIREFLY_README is not set (run the tests through ctest)")
    d = os.path.join(os.path.dirname(os.path.abspath(path)), "..", "shared", "data", name)
    if not os.path.isdir(d):
        pytest.skip("no ../shared/data/%s next to the repository" % name)
    return d


def test_readme_example_count_on_the_example_render(tmp_path):
    """The count the README says its example prints on the example render is what it prints."""
    pytest.importorskip("OpenImageIO")
    d = shared_render("cycles-caustics")
    said = re.search(r"On the example render this prints `(\d+) fireflies removed` \(the tool says "
                     r"`fireflies (\d+) \+\s+(\d+)`\)", python_section())
    assert said, "the README no longer states the example's count"
    for half in ("half_a.exr", "half_b.exr"):
        os.symlink(os.path.join(d, half), tmp_path / half)
    done = subprocess.run([sys.executable, "-c", readme_example()], cwd=tmp_path, env=dict(os.environ),
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "%s fireflies removed" % said.group(1)
    assert int(said.group(2)) + int(said.group(3)) == int(said.group(1))


def test_readme_pictures_are_the_current_output(tmp_path):
    """docs/'s pictures of the real renders are what bench/readme_images.py and
    bench/bucket_images.py make now (to one 8-bit step), so that no change of the library
    leaves them stale."""
    oiio = pytest.importorskip("OpenImageIO")
    shared_render("cycles-caustics")
    root = os.path.dirname(os.path.abspath(os.environ["FIREFLY_README"]))
    data = os.path.join(root, "..", "shared", "data")
    for script, source in (("readme_images.py", data), ("bucket_images.py", os.path.join(data, "cycles-caustics"))):
        done = subprocess.run([sys.executable, os.path.join(root, "bench", script), source, str(tmp_path)],
                              env=dict(os.environ), capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
    made = sorted(p for p in os.listdir(tmp_path) if p.endswith(".png"))
    assert "cycles-caustics_after.png" in made and "bucket_firefly.png" in made
    for name in made:
        now = oiio.ImageBuf(str(tmp_path / name)).get_pixels(oiio.UINT8).astype(int)
        kept = oiio.ImageBuf(os.path.join(root, "docs", name)).get_pixels(oiio.UINT8).astype(int)
        assert now.shape == kept.shape, name
        assert np.abs(now - kept).max() <= 1, "docs/%s is stale: rerun bench/readme_images.py and bucket_images.py" % name
