#!/usr/bin/env python3
"""The command-line tool against oiiotool on a 2K sequence.

Builds a sequence of two-half frames from a render with half buffers (default:
../shared/data/cycles-caustics, mirror-tiled to 2000x1080, each value's lowest mantissa bits
perturbed so that the tiles do not repeat byte for byte (--exact-tiles keeps them), ZIP
compression, the render's own channels), then times, in alternation:

  firefly --threads T A.####.exr B.####.exr --frames 1-N -o OUT.####.exr
  oiiotool --threads T A B --add --mulc 0.5 -o OUT          (once per frame)

and prints the per-frame wall time of each and their ratio (target: firefly <= 0.75x).
oiiotool's line reads the same two files, combines them and writes one image: the least an
I/O-bound tool that cleans the halves must do.

    bench/cli_speed.py build/bench/examples/firefly [--frames 8] [--threads 2] [--runs 3]
"""
import argparse
import os
import subprocess
import sys
import tempfile
import time

import numpy as np
import OpenImageIO as oiio


def mirror_tile(pixels, width, height):
    """pixels (h, w, c) repeated with mirrored copies until it covers width x height."""
    h, w = pixels.shape[:2]
    rows = [pixels if (j % 2 == 0) else pixels[::-1] for j in range(-(-height // h))]
    col = np.concatenate(rows, axis=0)[:height]
    tiles = [col if (i % 2 == 0) else col[:, ::-1] for i in range(-(-width // w))]
    return np.ascontiguousarray(np.concatenate(tiles, axis=1)[:, :width])


def decorrelate(pixels, seed):
    """Each value times 1 + u 2^-20 (u uniform in [-1, 1]): the low mantissa bits differ from
    tile to tile, as in a real frame, where the tiles would otherwise repeat byte for byte and
    ZIP finds the repeats (oiiotool's sum of mirror-tiled halves wrote 14.1 MB a frame where
    the cleaned frame, whose values depend on position, wrote 23.9 MB). Zeros stay zero."""
    u = np.random.default_rng(seed).uniform(-1.0, 1.0, pixels.shape)
    return (pixels * (1.0 + u * 2.0 ** -20)).astype(np.float32)


def make_sequence(src, out_dir, frames, width, height, exact_tiles=False):
    for k, half in enumerate(("a", "b")):
        buf = oiio.ImageBuf(os.path.join(src, f"half_{half}.exr"))
        if buf.has_error:
            sys.exit(f"cannot read {src}/half_{half}.exr: {buf.geterror()}")
        spec = buf.spec()
        tiled = mirror_tile(buf.get_pixels(oiio.FLOAT), width, height)
        if not exact_tiles:
            tiled = decorrelate(tiled, k)
        out_spec = oiio.ImageSpec(width, height, spec.nchannels, oiio.FLOAT)
        out_spec.channelnames = spec.channelnames
        out_spec.attribute("compression", "zip")
        out = oiio.ImageBuf(out_spec)
        out.set_pixels(oiio.ROI(0, width, 0, height, 0, 1, 0, spec.nchannels), tiled)
        for f in range(1, frames + 1):
            if not out.write(os.path.join(out_dir, f"half_{half}.{f:04d}.exr")):
                sys.exit(f"cannot write the sequence: {out.geterror()}")


def timed(cmds):
    t0 = time.perf_counter()
    for c in cmds:
        subprocess.run(c, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("firefly", help="the firefly tool (e.g. build/bench/examples/firefly)")
    ap.add_argument("--source", default=os.path.join(here, "..", "..", "shared", "data", "cycles-caustics"),
                    help="a folder with half_a.exr and half_b.exr")
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--size", default="2000x1080")
    ap.add_argument("--exact-tiles", action="store_true",
                    help="keep the mirrored tiles byte for byte (ZIP then finds their repeats)")
    a = ap.parse_args()
    width, height = (int(v) for v in a.size.split("x"))
    if not os.path.isfile(os.path.join(a.source, "half_a.exr")):
        print(f"skipped: no half buffers in {a.source}")
        return 0
    with tempfile.TemporaryDirectory() as d:
        make_sequence(a.source, d, a.frames, width, height, a.exact_tiles)
        seq = [os.path.join(d, f"half_{h}.####.exr") for h in "ab"]
        ours = [[a.firefly, "--threads", str(a.threads), *seq, "--frames", f"1-{a.frames}",
                 "-o", os.path.join(d, "clean.####.exr")]]
        theirs = [["oiiotool", "--threads", str(a.threads),
                   os.path.join(d, f"half_a.{f:04d}.exr"), os.path.join(d, f"half_b.{f:04d}.exr"),
                   "--add", "--mulc", "0.5", "-o", os.path.join(d, f"sum.{f:04d}.exr")]
                  for f in range(1, a.frames + 1)]
        timed(ours)  # warm the page cache and both tools' first runs
        timed(theirs)
        print(f"{a.frames} frames {width}x{height}, {a.threads} threads; per frame, seconds")
        print("run  firefly  oiiotool  ratio")
        ratios = []
        for r in range(a.runs):
            t_ours = timed(ours) / a.frames
            t_theirs = timed(theirs) / a.frames
            ratios.append(t_ours / t_theirs)
            print(f"{r + 1:3d}  {t_ours:7.3f}  {t_theirs:8.3f}  {ratios[-1]:5.2f}")
        print(f"median ratio {sorted(ratios)[len(ratios) // 2]:.2f} (target <= 0.75)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
