#!/usr/bin/python3
"""The README's failed-bucket pictures: the Cycles caustics render with a NaN square in half A
(a render bucket that failed), cleaned by firefly's default (rebuilt from half B) and by the
paper's spatial rule, next to the reference; then the same square written black (a bucket that
failed to zero), cleaned at the defaults (found dropped, rebuilt from half B) and with
find_dropped off. Needs the Python module on PYTHONPATH and python3-openimageio.

    PYTHONPATH=build/tests/python bench/bucket_images.py ../shared/data/cycles-caustics docs
"""
import sys

import numpy as np
import OpenImageIO as oiio

import firefly
from pfm_io import read_pfm


def write_png(path, rgb, crop, zoom=3):
    y0, y1, x0, x1 = crop
    img = np.nan_to_num(rgb[y0:y1, x0:x1], nan=0.0)
    img = np.where(np.isnan(rgb[y0:y1, x0:x1]), [1.0, 0.0, 1.0], img)  # NaN in magenta
    img = np.clip(img, 0.0, 1.0) ** (1 / 2.2)
    img = np.repeat(np.repeat(img, zoom, axis=0), zoom, axis=1)
    out = oiio.ImageBuf(np.ascontiguousarray((img * 255 + 0.5).astype(np.uint8)))
    if not out.write(path):
        sys.exit("cannot write " + path)


def relmse(img, ref):
    return float(np.mean((img - ref) ** 2 / (ref ** 2 + 0.01)))


def cleaned(halves, path, crop, **options):
    """The halves (colour, variance, colour, variance) cleaned on copies with the options, their
    mean written as a PNG crop; returns the report and the mean."""
    ca, cva, cb, cvb = (x.copy() for x in halves)
    rep = firefly.Detector(**options).process(ca, cva, cb, cvb)
    final = 0.5 * ca + 0.5 * cb
    write_png(path, final, crop)
    return rep, final


def main():
    src, out = sys.argv[1], sys.argv[2]
    a, va, b, vb, ref = (read_pfm(f"{src}/{n}.pfm") for n in ("a_color", "a_variance", "b_color", "b_variance", "reference"))
    y0, x0, size = 196, 200, 72  # the bucket: over the glass and the metal sphere
    a[y0:y0 + size, x0:x0 + size] = np.nan
    va[y0:y0 + size, x0:x0 + size] = np.nan
    crop = (y0 - 24, y0 + size + 24, x0 - 24, x0 + size + 24)
    box = (slice(y0, y0 + size), slice(x0, x0 + size))
    write_png(f"{out}/bucket_input.png", 0.5 * a + 0.5 * b, crop)
    write_png(f"{out}/bucket_reference.png", ref, crop)
    for name, rebuild in (("firefly", "other_half"), ("spatial", "spatial")):
        rep, final = cleaned((a, va, b, vb), f"{out}/bucket_{name}.png", crop, rebuild=rebuild)
        print(f"{name}: relMSE in the bucket {relmse(final[box], ref[box]):.4f}, frame {relmse(final, ref):.4f}, "
              f"status {'ok' if rep.ok else 'not ok'}")
    intact = firefly.Detector()
    ia, ib = read_pfm(f"{src}/a_color.pfm"), b.copy()
    intact.process(ia, read_pfm(f"{src}/a_variance.pfm"), ib, read_pfm(f"{src}/b_variance.pfm"))
    print(f"intact frame: relMSE in the same square {relmse((0.5 * ia + 0.5 * ib)[box], ref[box]):.4f}, "
          f"frame {relmse(0.5 * ia + 0.5 * ib, ref):.5f}")
    black(src, out, box, crop, ref)


def black(src, out, box, crop, ref):
    """The same square written black (colour and variance 0) in half A."""
    a, va, b, vb = (read_pfm(f"{src}/{n}.pfm") for n in ("a_color", "a_variance", "b_color", "b_variance"))
    a[box] = 0.0
    va[box] = 0.0
    write_png(f"{out}/bucket_black_input.png", 0.5 * a + 0.5 * b, crop)
    for name, find in (("firefly", True), ("kept", False)):
        rep, final = cleaned((a, va, b, vb), f"{out}/bucket_black_{name}.png", crop, find_dropped=find)
        print(f"black square, find_dropped={find}: relMSE in the square {relmse(final[box], ref[box]):.4f}, "
              f"frame {relmse(final, ref):.5f}, dropped {rep.half[0].dropped} + {rep.half[1].dropped}")


if __name__ == "__main__":
    main()
