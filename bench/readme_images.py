#!/usr/bin/python3
"""The README's pictures of the real renders: for each render in ../shared/data given, the
combined input (A + B) / 2, firefly's output at the defaults and the high-sample reference, as
8-bit sRGB PNGs written the way the command-line tool's --preview writes them (clamped to [0, 1],
the sRGB curve, rounded), and for the caustics render 3x crops around the spheres. Needs the
Python module on PYTHONPATH and python3-openimageio.

    PYTHONPATH=build/tests/python bench/readme_images.py ../shared/data docs
"""
import os
import sys

import numpy as np
import OpenImageIO as oiio

import firefly
from downstream import relmse  # the accuracy tables' relMSE
from pfm_io import read_pfm

RENDERS = {"cycles-caustics": (180, 270, 120, 250), "cycles-interior": None}  # 3x crop: y0, y1, x0, x1


def srgb8(rgb):
    """As firefly_tools::write_png_preview, in float32."""
    v = np.where(np.isfinite(rgb), np.clip(rgb, 0.0, 1.0), 1.0).astype(np.float32)
    v = np.where(v <= np.float32(0.0031308), np.float32(12.92) * v,
                 np.float32(1.055) * np.power(v, np.float32(1 / 2.4)) - np.float32(0.055))
    return (v * np.float32(255) + np.float32(0.5)).astype(np.uint8)


def write_png(path, pixels):
    if not oiio.ImageBuf(np.ascontiguousarray(pixels)).write(path):
        sys.exit("cannot write " + path)


def main():
    src, out = sys.argv[1], sys.argv[2]
    for name, crop in RENDERS.items():
        d = os.path.join(src, name)
        if not os.path.isdir(d):
            print(f"{name}: {d} not found, skipped")
            continue
        a, va, b, vb, ref = (read_pfm(f"{d}/{n}.pfm") for n in ("a_color", "a_variance", "b_color", "b_variance", "reference"))
        before = 0.5 * a + 0.5 * b
        rep = firefly.Detector().process(a, va, b, vb)
        after = 0.5 * a + 0.5 * b
        images = {"before": srgb8(before), "after": srgb8(after), "reference": srgb8(ref)}
        for kind, px in images.items():
            write_png(f"{out}/{name}_{kind}.png", px)
            if crop:
                y0, y1, x0, x1 = crop
                write_png(f"{out}/crop_{kind}.png", np.repeat(np.repeat(px[y0:y1, x0:x1], 3, axis=0), 3, axis=1))
        print(f"{name}: relMSE {relmse(before, ref):.4f} -> {relmse(after, ref):.4f}, status {'ok' if rep.ok else 'not ok'}")


if __name__ == "__main__":
    main()
