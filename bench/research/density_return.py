#!/usr/bin/python3
"""A finer scale for the energy return, measured outside the library: the removed light given
back where it fell, as a Gaussian density of the removed excess itself. The prototype of
include/firefly/density.hpp (which pools the evidence over both halves, as --pooled rows do
here, and keeps only the part above the cleaned image's level).

    /usr/bin/python3 bench/research/density_return.py RENDER_DIR [--cli PATH] [--sigma 2]
        [--evidence 4 8] [--out DIR]

RENDER_DIR holds half_a.exr, half_b.exr and reference.exr (or reference.pfm), as
bench/renders/halves.py writes them or ../shared/data holds them. The firefly tool (`--cli`,
default build/tests/examples/firefly) cleans the halves twice, with the defaults but the
finest scale (--energy-density-evidence 0) and with --no-energy-return; the difference of the input and the second is each half's removed excess
e, per pixel and channel. Then, per half,
    M = G_sigma * e,  V = G_sigma^2 * |e|^2,  s = max(0, 1 - c V / |M|^2)
(the energy return's James-Stein factor, energy.hpp, with c the evidence asked: the return
needs more than c equal hits in the window), and the candidate output is the cleaned half plus
s M, plus the defaults' return scaled by 1 - s (the light the finer scale did not take; an
approximation of the library's split, not exact). Printed: relMSE against the reference over
the frame, over the reference's bright (> 1), middle (0.2 - 1) and dark (< 0.2) pixels, and
the light over the reference's. --out writes each candidate as DIR/<render>/density_c<c>.pfm
beside copies of nothing else: bench/downstream.py needs the render's other methods there
too (firefly_accuracy's FIREFLY_ACCURACY_IMAGES folder).
"""
import argparse
import os
import subprocess
import sys
import tempfile

import numpy as np
import OpenImageIO as oiio
from scipy.ndimage import convolve

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from pfm_io import read_pfm, write_pfm  # noqa: E402


def read_rgb(path):
    if path.endswith(".pfm"):
        return read_pfm(path).astype(np.float64)
    buf = oiio.ImageBuf(path)
    if buf.has_error:
        sys.exit(f"{path}: {buf.geterror()}")
    return buf.get_pixels(oiio.FLOAT)[..., :3].astype(np.float64)


def clean(cli, src, prefix, *flags):
    a, b = os.path.join(src, "half_a.exr"), os.path.join(src, "half_b.exr")
    subprocess.run([cli, a, b, "-o", prefix + ".exr", "--halves", prefix, "-q", *flags], check=True)
    return read_rgb(prefix + "_a.exr"), read_rgb(prefix + "_b.exr")


def gaussian(sigma):
    r = int(np.ceil(3 * sigma))
    y, x = np.mgrid[-r:r + 1, -r:r + 1]
    k = np.exp(-(x * x + y * y) / (2 * sigma * sigma))
    return k / k.sum()


def density(e, k, evidence):
    """s M and s for one half's removed excess e (h x w x 3)."""
    m = np.stack([convolve(e[..., c], k, mode="constant") for c in range(3)], -1)
    v = convolve((e * e).sum(-1), k * k, mode="constant")
    m2 = (m * m).sum(-1)
    s = np.where(m2 > 0, np.maximum(0.0, 1.0 - evidence * v / np.maximum(m2, 1e-300)), 0.0)
    return s[..., None] * m, s


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("render")
    ap.add_argument("--cli", default="build/tests/examples/firefly")
    ap.add_argument("--sigma", type=float, default=2.0)
    ap.add_argument("--evidence", type=float, nargs="+", default=[4.0, 8.0])
    ap.add_argument("--out")
    a = ap.parse_args()
    src = a.render
    ref_path = next((os.path.join(src, f) for f in ("reference.exr", "reference.pfm")
                     if os.path.exists(os.path.join(src, f))), None)
    if not ref_path:
        sys.exit(f"{src}: no reference.exr or reference.pfm")
    ref = read_rgb(ref_path)
    half = [read_rgb(os.path.join(src, f)) for f in ("half_a.exr", "half_b.exr")]
    with tempfile.TemporaryDirectory() as tmp:
        default = clean(a.cli, src, os.path.join(tmp, "default"), "--energy-density-evidence", "0")
        removed_only = clean(a.cli, src, os.path.join(tmp, "removed"), "--no-energy-return")
    lum = ref.mean(-1)
    regions = (lum > 1, (lum > 0.2) & (lum <= 1), lum <= 0.2)

    def report(name, x):
        err = (((x - ref) ** 2) / (ref ** 2 + 0.01)).sum(-1) / 3
        parts = " ".join("%.4f" % err[r].mean() if r.any() else "-" for r in regions)
        print("%-16s %.5f   %s   %.3f" % (name, err.mean(), parts, x.sum() / ref.sum()))

    print("%-16s relMSE    bright / middle / dark   light" % "method")
    report("input", (half[0] + half[1]) / 2)
    report("removed only", (removed_only[0] + removed_only[1]) / 2)
    report("wider scales", (default[0] + default[1]) / 2)
    k = gaussian(a.sigma)
    excess = [np.maximum(half[h] - removed_only[h], 0.0) for h in range(2)]
    for pooled in (False, True):
        for c in a.evidence:
            out = []
            if pooled:
                _, s = density(excess[0] + excess[1], k, c)
            for h in range(2):
                fine, own = density(excess[h], k, c)
                if pooled:
                    m = np.stack([convolve(excess[h][..., ch], k, mode="constant") for ch in range(3)], -1)
                    fine, own = s[..., None] * m, s
                out.append(removed_only[h] + fine + (default[h] - removed_only[h]) * (1.0 - own[..., None]))
            x = (out[0] + out[1]) / 2
            report("%s c=%g" % ("pooled" if pooled else "per half", c), x)
        if a.out:
            d = os.path.join(a.out, os.path.basename(os.path.normpath(src)))
            os.makedirs(d, exist_ok=True)
            write_pfm(os.path.join(d, "density_c%g.pfm" % c), x.astype(np.float32))


main()
