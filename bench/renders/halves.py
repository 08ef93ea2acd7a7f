#!/usr/bin/python3
"""N one-sample renders -> two half buffers with variance, laid out as ../shared/data's folders.

    /usr/bin/python3 bench/renders/halves.py SRC N DST [--reference SRC/reference.exr] [--renders K]

Renders SRC/seed_0.exr .. seed_<N-1>.exr: the first N/2 make half A, the rest half B. Each half
is the mean of its renders and the variance of that mean (sample variance / (N/2), unbiased),
written as DST/half_a.exr, half_b.exr (R, G, B, Variance.R/G/B, as a renderer writes them) and
the PFM copies the accuracy bench reads (a_color.pfm, a_variance.pfm, b_color.pfm,
b_variance.pfm); the reference as DST/reference.pfm. --renders K also writes the same N renders
as K seed renders of N/K samples each, DST/render_0.exr ... (R, G, B: what a Blender user has,
no variance), for the K-buffer detector. Needs Debian's python3-openimageio.
"""
import argparse
import os
import sys

import numpy as np
import OpenImageIO as oiio

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from pfm_io import write_pfm  # noqa: E402


def read_rgb(path):
    buf = oiio.ImageBuf(path)
    if buf.has_error:
        sys.exit(f"{path}: {buf.geterror()}")
    return buf.get_pixels(oiio.FLOAT)[..., :3]  # float32, as stored


def write_exr(path, pixels, names):
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], len(names), oiio.FLOAT)
    spec.channelnames = names
    spec.attribute("compression", "zip")
    out = oiio.ImageOutput.create(path)
    if not out or not out.open(path, spec) or not out.write_image(pixels.astype(np.float32)):
        sys.exit(f"{path}: {oiio.geterror()}")
    out.close()


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("src")
    ap.add_argument("n", type=int, help="renders, even, >= 4 (two or more per half)")
    ap.add_argument("dst")
    ap.add_argument("--reference", help="default: SRC/reference.exr")
    ap.add_argument("--renders", type=int, default=0, metavar="K", help="also K seed renders (K divides N)")
    a = ap.parse_args()
    if a.n < 4 or a.n % 2:
        sys.exit("N must be even and at least 4")
    if a.renders and (a.renders < 2 or a.n % a.renders):
        sys.exit("K must be at least 2 and divide N")
    os.makedirs(a.dst, exist_ok=True)
    # every render read once (float32 as stored; sums in float64 below)
    renders = np.stack([read_rgb(os.path.join(a.src, f"seed_{i}.exr")) for i in range(a.n)])
    per = a.n // 2
    for h, name in enumerate("ab"):
        half = renders[h * per:(h + 1) * per].astype(np.float64)
        color, variance = half.mean(0), half.var(0, ddof=1) / per
        write_exr(os.path.join(a.dst, f"half_{name}.exr"), np.concatenate([color, variance], 2),
                  ("R", "G", "B", "Variance.R", "Variance.G", "Variance.B"))
        write_pfm(os.path.join(a.dst, f"{name}_color.pfm"), color)
        write_pfm(os.path.join(a.dst, f"{name}_variance.pfm"), variance)
    per = a.n // max(a.renders, 1)
    for k in range(a.renders):
        mean = renders[k * per:(k + 1) * per].astype(np.float64).mean(0)
        write_exr(os.path.join(a.dst, f"render_{k}.exr"), mean, ("R", "G", "B"))
    write_pfm(os.path.join(a.dst, "reference.pfm"), read_rgb(a.reference or os.path.join(a.src, "reference.exr")))


main()
