#!/usr/bin/python3
"""The downstream columns of the accuracy report: real denoisers after every prefilter.

firefly_accuracy, run with FIREFLY_ACCURACY_IMAGES=DIR, writes each downstream method's
combined output as DIR/<scene>/<method>.pfm and the reference as DIR/<scene>/reference.pfm
(simulated scenes as a centre crop, FIREFLY_ACCURACY_CROP, default 320x180). This script runs
three of scikit-image's denoisers (Debian python3-skimage, so /usr/bin/python3), each of a
different kind, on each image in the log domain:

    y = log(1 + max(x, 0)),  sigma = estimate_sigma(y),  output = exp(d(y)) - 1,

    nl_means  non-local means (patches): denoise_nl_means(y, h = f * sigma, sigma = sigma,
              fast_mode, patch 5, distance 6), f in 0.5, 2, 8, 32
    wavelet   wavelet shrinkage (transform): denoise_wavelet(y, sigma = f * sigma,
              BayesShrink, soft, rescale_sigma), f in 0.25 ... 64
    tv        total variation (variational): denoise_tv_chambolle(y, weight = f * sigma),
              f in 0.25 ... 64

and keeps, per denoiser, the strength with the lowest relMSE against the reference (mean over
pixels and channels of (x - ref)^2 / (ref^2 + 0.01)), so every method is judged at its own
best strength. The grids are wide because a firefly survives a denoiser unless its strength is
far above the noise. Images are denoised in --jobs processes (default 2). "input" is the
denoiser alone: the input after the shared non-finite repair (no denoiser takes NaN), with no
prefilter.

    /usr/bin/python3 bench/downstream.py DIR -o downstream.json [--denoisers nl_means,wavelet,tv]

The JSON: {"denoisers": {name: {"strengths": [...], "scenes": {scene: {method: result}}}}}.
"""
import argparse
import json
import os
import sys
import time
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from pfm_io import read_pfm


def relmse(x, ref):
    e = (x - ref) ** 2 / (ref ** 2 + 0.01)
    e[~np.isfinite(e)] = 1e6
    return float(e.mean())


WIDE = [0.25, 0.5, 1, 2, 4, 8, 16, 32, 64]


def nl_means(y, sigma, f):
    from skimage.restoration import denoise_nl_means
    return denoise_nl_means(y, h=f * sigma, sigma=sigma, fast_mode=True, patch_size=5, patch_distance=6,
                            channel_axis=-1)


def wavelet(y, sigma, f):
    from skimage.restoration import denoise_wavelet
    return denoise_wavelet(y, sigma=f * sigma, method="BayesShrink", mode="soft", rescale_sigma=True,
                           channel_axis=-1)


def tv(y, sigma, f):
    from skimage.restoration import denoise_tv_chambolle
    return denoise_tv_chambolle(y, weight=f * sigma, channel_axis=-1)


# name: (denoise(y, sigma, strength), the strengths tried)
DENOISERS = {"nl_means": (nl_means, [0.5, 2, 8, 32]), "wavelet": (wavelet, WIDE), "tv": (tv, WIDE)}


def denoise_best(img, ref, denoise, strengths):
    from skimage.restoration import estimate_sigma
    bad = int((~np.isfinite(img)).sum())
    y = np.log1p(np.maximum(np.nan_to_num(img, nan=0.0, posinf=0.0, neginf=0.0), 0.0))
    sigma = float(estimate_sigma(y, channel_axis=-1, average_sigmas=True))
    t0 = time.time()
    errors = [relmse(np.expm1(denoise(y, sigma, f)), ref) for f in strengths]
    best = int(np.argmin(errors))
    return dict(relmse=errors[best], factor=strengths[best], sigma=sigma, nonfinite_in=bad,
                errors=errors, seconds=(time.time() - t0) / len(strengths), prefilter_relmse=relmse(img, ref))


def one(task):
    scene, path, ref_path, grids = task
    img, ref = read_pfm(path, np.float64), read_pfm(ref_path, np.float64)
    if img.shape != ref.shape:
        return scene, path, None
    return scene, path, {name: denoise_best(img, ref, DENOISERS[name][0], grid) for name, grid in grids.items()}


def parse_grids(names, overrides):
    """The denoisers to run and their strengths: --denoisers picks, --strengths NAME=a,b,c (or a
    bare list, for nl_means) replaces a grid."""
    grids = {}
    for name in names.split(","):
        if name not in DENOISERS:
            sys.exit(f"downstream.py: unknown denoiser '{name}' (known: {', '.join(DENOISERS)})")
        grids[name] = list(DENOISERS[name][1])
    for o in overrides:
        name, _, values = o.rpartition("=")
        name = name or "nl_means"
        if name not in grids:
            sys.exit(f"downstream.py: --strengths for '{name}', which is not run")
        try:
            grids[name] = [float(v) for v in values.split(",")]
        except ValueError:
            sys.exit(f"downstream.py: --strengths {o}: not a list of numbers")
    return grids


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dir")
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--denoisers", default=",".join(DENOISERS), help="which to run (comma-separated)")
    ap.add_argument("--strengths", action="append", default=[],
                    help="NAME=a,b,c: the strengths (x sigma) tried for one denoiser; repeatable")
    ap.add_argument("--jobs", type=int, default=2)
    a = ap.parse_args()
    grids = parse_grids(a.denoisers, a.strengths)
    tasks = []
    for scene in sorted(os.listdir(a.dir)):
        ref_path = os.path.join(a.dir, scene, "reference.pfm")
        if os.path.isfile(ref_path):
            for name in sorted(os.listdir(os.path.join(a.dir, scene))):
                if name.endswith(".pfm") and name != "reference.pfm":
                    tasks.append((scene, os.path.join(a.dir, scene, name), ref_path, grids))
    result = {name: defaultdict(dict) for name in grids}
    with ProcessPoolExecutor(max_workers=max(a.jobs, 1)) as pool:
        for scene, path, rs in pool.map(one, tasks):
            method = os.path.basename(path)[:-4]
            if rs is None:
                print(f"note: {scene}/{method}: size differs from the reference, skipped", file=sys.stderr)
                continue
            line = f"{scene:24s} {method:22s} prefilter {next(iter(rs.values()))['prefilter_relmse']:.4g}"
            for name, r in rs.items():
                result[name][scene][method] = r
                line += f"  {name} {r['relmse']:.4g} ({r['factor']:g})"
            print(line, file=sys.stderr)
    with open(a.out, "w") as f:
        json.dump(dict(denoisers={n: dict(strengths=grids[n], scenes=result[n]) for n in grids}), f, indent=1)


if __name__ == "__main__":
    sys.exit(main())
