#!/usr/bin/python3
"""The downstream column of the accuracy report: a real denoiser after every prefilter.

firefly_accuracy, run with FIREFLY_ACCURACY_IMAGES=DIR, writes each downstream method's
combined output as DIR/<scene>/<method>.pfm and the reference as DIR/<scene>/reference.pfm
(simulated scenes as a centre crop, FIREFLY_ACCURACY_CROP, default 320x180). This script runs
scikit-image's non-local means on each (Debian python3-skimage, so /usr/bin/python3):

    y = log(1 + max(x, 0)),  sigma = estimate_sigma(y),
    y' = denoise_nl_means(y, h = f * sigma, sigma = sigma, fast_mode, patch 5, distance 6),
    output = exp(y') - 1,

at the strengths f in --strengths (default 0.5, 2, 8, 32: one grid for every method, wide
because a firefly survives NL-means unless h is far above the noise), and keeps the one with
the lowest relMSE against the reference (mean over pixels and channels of
(x - ref)^2 / (ref^2 + 0.01)), so every method is judged at its own best strength. Images are
denoised in --jobs processes (default 2). "input" is the denoiser alone: the input after
the shared non-finite repair (NL-means cannot take NaN), with no prefilter.

    /usr/bin/python3 bench/downstream.py DIR -o downstream.json
"""
import argparse
import json
import os
import sys
import time
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor

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


def denoise_best(img, ref, strengths):
    from skimage.restoration import denoise_nl_means, estimate_sigma
    bad = int((~np.isfinite(img)).sum())
    y = np.log1p(np.maximum(np.nan_to_num(img, nan=0.0, posinf=0.0, neginf=0.0), 0.0))
    sigma = float(estimate_sigma(y, channel_axis=-1, average_sigmas=True))
    t0 = time.time()
    errors = []
    for f in strengths:
        d = denoise_nl_means(y, h=f * sigma, sigma=sigma, fast_mode=True, patch_size=5, patch_distance=6,
                             channel_axis=-1)
        errors.append(relmse(np.expm1(d), ref))
    best = int(np.argmin(errors))
    return dict(relmse=errors[best], factor=strengths[best], sigma=sigma, nonfinite_in=bad,
                errors=errors, seconds=(time.time() - t0) / len(strengths), prefilter_relmse=relmse(img, ref))


def one(task):
    scene, path, ref_path, strengths = task
    img, ref = read_pfm(path), read_pfm(ref_path)
    if img.shape != ref.shape:
        return scene, path, None
    return scene, path, denoise_best(img, ref, strengths)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dir")
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--strengths", default="0.5,2,8,32", help="h / sigma values to try (comma-separated)")
    ap.add_argument("--jobs", type=int, default=2)
    a = ap.parse_args()
    strengths = [float(v) for v in a.strengths.split(",")]
    tasks = []
    for scene in sorted(os.listdir(a.dir)):
        ref_path = os.path.join(a.dir, scene, "reference.pfm")
        if os.path.isfile(ref_path):
            for name in sorted(os.listdir(os.path.join(a.dir, scene))):
                if name.endswith(".pfm") and name != "reference.pfm":
                    tasks.append((scene, os.path.join(a.dir, scene, name), ref_path, strengths))
    result = defaultdict(dict)
    with ProcessPoolExecutor(max_workers=max(a.jobs, 1)) as pool:
        for scene, path, r in pool.map(one, tasks):
            method = os.path.basename(path)[:-4]
            if r is None:
                print(f"note: {scene}/{method}: size differs from the reference, skipped", file=sys.stderr)
                continue
            result[scene][method] = r
            print(f"{scene:24s} {method:22s} prefilter {r['prefilter_relmse']:.4g}  after NL-means "
                  f"{r['relmse']:.4g} (h = {r['factor']:g} sigma)", file=sys.stderr)
    with open(a.out, "w") as f:
        json.dump(dict(strengths=strengths, scenes=result), f, indent=1)


if __name__ == "__main__":
    sys.exit(main())
