#!/usr/bin/python3
"""The downstream column of the accuracy report: a real denoiser after every prefilter.

firefly_accuracy, run with FIREFLY_ACCURACY_IMAGES=DIR, writes each downstream method's
combined output as DIR/<scene>/<method>.pfm and the reference as DIR/<scene>/reference.pfm
(simulated scenes as a centre crop, FIREFLY_ACCURACY_CROP, default 320x180). This script runs
scikit-image's non-local means on each (Debian python3-skimage, so /usr/bin/python3):

    y = log(1 + max(x, 0)),  sigma = estimate_sigma(y),
    y' = denoise_nl_means(y, h = f * sigma, sigma = sigma, fast_mode, patch 5, distance 6),
    output = exp(y') - 1,

at strengths f = 2^j (j = -2 .. 4), searched from f = 1 upwards and downwards while the
relMSE against the reference (mean over pixels and channels of (x - ref)^2 / (ref^2 + 0.01))
keeps falling, and keeps the best, so every method is judged at its own best strength. "input" is the denoiser alone: the input after
the shared non-finite repair (NL-means cannot take NaN), with no prefilter.

    /usr/bin/python3 bench/downstream.py DIR -o downstream.json
"""
import argparse
import json
import os
import sys
import time

import numpy as np


def read_pfm(path):
    with open(path, "rb") as f:
        magic = f.readline().strip()
        w, h = (int(v) for v in f.readline().split())
        scale = float(f.readline())
        c = 3 if magic == b"PF" else 1
        data = np.fromfile(f, dtype="<f4" if scale < 0 else ">f4", count=w * h * c)
    return data.reshape(h, w, c)[::-1].astype(np.float64)  # PFM rows are bottom-up


def relmse(x, ref):
    e = (x - ref) ** 2 / (ref ** 2 + 0.01)
    e[~np.isfinite(e)] = 1e6
    return float(e.mean())


def denoise_best(img, ref, lo, hi):
    from skimage.restoration import denoise_nl_means, estimate_sigma
    bad = int((~np.isfinite(img)).sum())
    y = np.log1p(np.maximum(np.nan_to_num(img, nan=0.0, posinf=0.0, neginf=0.0), 0.0))
    sigma = float(estimate_sigma(y, channel_axis=-1, average_sigmas=True))
    tried = {}

    def at(j):
        if j not in tried:
            d = denoise_nl_means(y, h=2.0 ** j * sigma, sigma=sigma, fast_mode=True, patch_size=5,
                                 patch_distance=6, channel_axis=-1)
            tried[j] = relmse(np.expm1(d), ref)
        return tried[j]

    t0 = time.time()
    best = 0
    for step in (1, -1):  # walk up, then down, while the error falls
        j = best
        while lo <= j + step <= hi and at(j + step) < at(best):
            j += step
            best = j
    return dict(relmse=at(best), factor=2.0 ** best, sigma=sigma, nonfinite_in=bad, tried=len(tried),
                seconds=(time.time() - t0) / len(tried), prefilter_relmse=relmse(img, ref))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dir")
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--range", default="-2,4", help="lowest and highest j in h = 2^j sigma")
    a = ap.parse_args()
    lo, hi = (int(v) for v in a.range.split(","))
    result = {}
    for scene in sorted(os.listdir(a.dir)):
        sdir = os.path.join(a.dir, scene)
        ref_path = os.path.join(sdir, "reference.pfm")
        if not os.path.isfile(ref_path):
            continue
        ref = read_pfm(ref_path)
        result[scene] = {}
        for name in sorted(os.listdir(sdir)):
            if not name.endswith(".pfm") or name == "reference.pfm":
                continue
            img = read_pfm(os.path.join(sdir, name))
            if img.shape != ref.shape:
                print(f"note: {scene}/{name}: size differs from the reference, skipped", file=sys.stderr)
                continue
            r = denoise_best(img, ref, lo, hi)
            result[scene][name[:-4]] = r
            print(f"{scene:24s} {name[:-4]:22s} prefilter {r['prefilter_relmse']:.4g}  after NL-means "
                  f"{r['relmse']:.4g} (h = {r['factor']} sigma)", file=sys.stderr)
    with open(a.out, "w") as f:
        json.dump(dict(strengths=[2.0 ** j for j in range(lo, hi + 1)], scenes=result), f, indent=1)


if __name__ == "__main__":
    sys.exit(main())
