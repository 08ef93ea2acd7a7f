#!/usr/bin/python3
"""Turns firefly_accuracy's JSON (--benchmark_format=json) and bench/downstream.py's NL-means
results into docs/accuracy.md: per-scene tables, a plot of accuracy against time (a Pareto
front), and which of the project's accuracy targets are met.

    /usr/bin/python3 bench/accuracy_report.py accuracy.json --downstream downstream.json \\
        --merged docs/accuracy.json --plot docs/accuracy_vs_time.png > docs/accuracy.md

--merged writes the benchmark JSON with the downstream results under "downstream", so
`accuracy_report.py docs/accuracy.json` alone regenerates the same report.
"""
import argparse
import json
import math
import sys
from collections import defaultdict

# The real renders (not simulated: no ground truth but a reference). The benchmark's context
# names them ("renders"), with FIREFLY_ACCURACY_RENDERS' folders too; these are the default
# for a file whose context does not.
DEFAULT_REAL = ("cycles-caustics", "cycles-interior", "cycles-caustics-seeds")
PEERS = ("median3x3", "cycles_prefilter", "bcd_spikes", "nrd_clamp", "clamp4", "clamp16")
COUNTERS = ("recall", "precision", "false_positive", "highlight_kept", "relmse", "changed", "worse",
            "worse_of_changed", "energy", "energy_dark", "energy_bright", "error", "highlight_not_lowered")


def load(path):
    with open(path) as f:
        data = json.load(f)
    rows = []
    for b in data["benchmarks"]:
        if b.get("run_type") == "aggregate":
            continue
        parts = b["name"].split("/")
        if len(parts) < 3 or parts[0] != "accuracy":
            continue
        ms = b["real_time"] if b.get("time_unit") == "ms" else b["real_time"] / 1e6
        rows.append(dict(scene=parts[1], method=parts[2], ms=ms, **{k: b.get(k) for k in COUNTERS}))
    real = set(DEFAULT_REAL) | set(n for n in data.get("context", {}).get("renders", "").split(",") if n)
    for r in rows:
        r["real"] = r["scene"] in real
    return data, rows


# The denoisers of bench/downstream.py, in the order the report shows them.
DENOISER_NAMES = {"nl_means": "NL-means", "wavelet": "wavelet shrinkage", "tv": "total variation"}


def denoisers_of(ds):
    """name -> {"strengths", "scenes"} (a file of NL-means alone, the earlier format, too)."""
    if not ds:
        return {}
    if "denoisers" in ds:
        return ds["denoisers"]
    return {"nl_means": ds}


def attach_downstream(rows, ds):
    """r["ds"], r["ds_h"]: NL-means' relMSE and strength; r["dsx"]: every denoiser's relMSE."""
    dn = denoisers_of(ds)
    for r in rows:
        r["dsx"] = {}
        for name, d in dn.items():
            v = d.get("scenes", {}).get(r["scene"], {}).get(r["method"])
            if v:
                r["dsx"][name] = v["relmse"]
        d = dn.get("nl_means", {}).get("scenes", {}).get(r["scene"], {}).get(r["method"])
        r["ds"] = d["relmse"] if d else None
        r["ds_h"] = d["factor"] if d else None


def is_sim(r):
    return not r["real"]


def scene_order(rows):
    """Sort key: the simulated scenes first, then the renders, each by name."""
    real = {r["scene"] for r in rows if r["real"]}
    return lambda s: (s in real, s)


GMON = ("gmon_k", "agmon_k")  # G-MoN's binary and adaptive variants: the best of them is compared


def is_kbuf(m):
    return m.startswith(("mean_k", "mon_k", "gmon_k", "agmon_k", "firefly_k"))


def meets(r):
    return r["recall"] >= 0.99 and r["false_positive"] <= 0.001 and r["highlight_kept"] >= 0.99


def fmt(v, spec=".4g", none="-"):
    return none if v is None else format(v, spec)


def pct(v):
    return "-" if v is None else f"{100 * v:.3f}%"


def shown(scene_rows):
    """Per-scene rows: firefly, the paper, the input, the peers, and the K-buffer estimators
    when the scene has more than two buffers (on the halves they equal the input)."""
    k2 = any(r["method"].startswith("mean_k2") for r in scene_rows)
    keep = [r for r in scene_rows if r["method"] in ("firefly", "firefly_no_energy", "firefly_fine_energy", "firefly_no_density", "firefly_paper", "input") + PEERS
            or (is_kbuf(r["method"]) and not k2)]
    return sorted(keep, key=lambda r: r["relmse"])


def scene_table(sc, rs):
    sim = is_sim(rs[0])
    print(f"**{sc}**" + ("" if sim else " (real render; relMSE against the high-sample reference)") + "\n")
    head = "| method | relMSE | "
    head += "recall | false pos. | highlights kept | " if sim else ""
    head += "changed | made worse (of changed) | energy all / dark / bright | after NL-means (h/sigma) | ms |"
    print(head)
    print("|---" + "|---:" * (head.count("|") - 2) + "|")
    for r in shown(rs):
        line = f"| {r['method']}{' (status not ok)' if r.get('error') else ''} | {fmt(r['relmse'])} | "
        if sim:
            line += f"{fmt(r['recall'], '.4f')} | {pct(r['false_positive'])} | {fmt(r['highlight_kept'], '.4f')} | "
        line += (f"{pct(r['changed'])} | {pct(r['worse'])} ({fmt(r['worse_of_changed'], '.2f')}) | "
                 f"{r['energy']:.3f} / {r['energy_dark']:.3f} / {r['energy_bright']:.3f} | "
                 f"{fmt(r['ds'])}{'' if r['ds_h'] is None else ' (%g)' % r['ds_h']} | {r['ms']:.2f} |")
        print(line)
    print()


DOWNSTREAM_COLUMNS = ["input", "firefly", "firefly_paper", "cycles_prefilter", "bcd_spikes", "median3x3", "nrd_clamp",
                      "clamp4"]


def downstream_table(rows, name="nl_means"):
    """Scenes down, methods across: relMSE after one denoiser (the prefilter's own relMSE is in
    the per-scene tables)."""
    cols = DOWNSTREAM_COLUMNS
    at = {(r["scene"], r["method"]): r for r in rows}
    scenes = sorted({r["scene"] for r in rows if name in r["dsx"]}, key=scene_order(rows))
    if not scenes:
        return
    print(f"relMSE after {DENOISER_NAMES.get(name, name)} at each method's best strength (`input`: the denoiser "
          "alone); the lowest of each row in bold.\n")
    print("| scene | " + " | ".join("denoiser alone" if c == "input" else c for c in cols) + " |")
    print("|---" + "|---:" * len(cols) + "|")
    for sc in scenes:
        vals = [at.get((sc, c), {}).get("dsx", {}).get(name) for c in cols]
        low = min(v for v in vals if v is not None)
        cells = ["-" if v is None else (f"**{v:.4g}**" if v == low else f"{v:.4g}") for v in vals]
        print(f"| {sc} | " + " | ".join(cells) + " |")
    print()


def geo(values):
    return math.exp(sum(math.log(max(v, 1e-12)) for v in values) / len(values)) if values else None


def across_denoisers(rows, targets):
    """Per denoiser, over the scenes it ran on: where firefly is the lowest of the
    highlight-keeping prefilters (a tie counts, as in the targets) and where it is no worse than
    the denoiser alone; geometric means of firefly, the best such peer per scene and the denoiser
    alone."""
    names = [n for n in DENOISER_NAMES if any(n in r["dsx"] for r in rows)]
    if len(names) < 2:
        return
    print("Across the denoisers: on how many scenes firefly is the lowest of the highlight-keeping "
          "prefilters after each (a tie counts), and no worse than the denoiser alone; the geometric "
          "means over those scenes of firefly, the best highlight-keeping peer of each scene, and "
          "the denoiser alone.\n")
    print("| denoiser | firefly lowest of the keeping peers | firefly no worse than the denoiser alone | "
          "firefly (geo. mean) | best keeping peer (geo. mean) | denoiser alone (geo. mean) | not lowest on |")
    print("|---|---:|---:|---:|---:|---:|---|")
    for name in names:
        lowest, no_worse, ff, peer, alone, missed = 0, 0, [], [], [], []
        scenes = sorted({r["scene"] for r in rows if name in r["dsx"]}, key=scene_order(rows))
        for sc in scenes:
            r, inp = targets.get(sc, "firefly"), targets.get(sc, "input")
            peers = [p["dsx"][name] for p in targets.keeping_peers(sc) if name in p["dsx"]]
            if not r or name not in r["dsx"] or not peers or not inp or name not in inp["dsx"]:
                continue
            v = r["dsx"][name]
            lowest += v <= min(peers)
            no_worse += v <= inp["dsx"][name]
            ff.append(v), peer.append(min(peers)), alone.append(inp["dsx"][name])
            if v > min(peers):
                missed.append(sc)
        print(f"| {DENOISER_NAMES[name]} | {lowest} of {len(ff)} | {no_worse} of {len(ff)} | {fmt(geo(ff))} | "
              f"{fmt(geo(peer))} | {fmt(geo(alone))} | {', '.join(missed) or '-'} |")
    print()


def buffers_table(rows):
    """Per K-buffer scene: the mean, the best median of means, the best G-MoN, and the
    half-buffer methods on the same samples."""
    at = defaultdict(dict)
    for r in rows:
        at[r["scene"]][r["method"]] = r
    scenes = [sc for sc, ms in at.items() if any(m.startswith(GMON) and "_k2_" not in m for m in ms)]
    if not scenes:
        return
    print("| scene | mean of the K | best median of means | best G-MoN | firefly (K buffers) | firefly (two halves) | "
          "firefly_paper | cycles_prefilter |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")

    def best(ms, prefix):
        c = [r for m, r in ms.items() if m.startswith(prefix)]
        if not c:
            return "-"
        r = min(c, key=lambda r: r["relmse"])
        hl = "" if r["highlight_kept"] is None else f", hl {r['highlight_kept']:.2f}"
        # with several families the full name tells which one won
        label = r["method"] if isinstance(prefix, tuple) else r["method"].split("_", 1)[1]
        return f"{r['relmse']:.4g} ({label}{hl})"

    def one(ms, m):
        r = ms.get(m)
        if not r:
            return "-"
        return f"{r['relmse']:.4g}" + ("" if r["highlight_kept"] is None else f" (hl {r['highlight_kept']:.2f})")

    for sc in sorted(scenes, key=scene_order(rows)):
        ms = at[sc]
        mean = [r for m, r in ms.items() if m.startswith("mean_k")]
        kf = next((m for m in ms if m.startswith("firefly_k")), None)
        print(f"| {sc} | {mean[0]['relmse']:.4g} | {best(ms, 'mon_k')} | {best(ms, GMON)} | "
              f"{one(ms, kf) if kf else '-'} | {one(ms, 'firefly')} | {one(ms, 'firefly_paper')} | {one(ms, 'cycles_prefilter')} |")
    print()


def summarize(sim):
    by = defaultdict(list)
    for r in sim:
        by[r["method"]].append(r)
    out = []
    for m, rs in by.items():
        if is_kbuf(m):
            continue
        dss = [r["ds"] for r in rs if r["ds"] is not None]
        out.append(dict(method=m, ms=sum(r["ms"] for r in rs) / len(rs), relmse=geo([r["relmse"] for r in rs]),
                        ds=geo(dss) if len(dss) == len(rs) else None,
                        recall=min(r["recall"] for r in rs), fp=max(r["false_positive"] for r in rs),
                        hl=min(r["highlight_kept"] for r in rs), worse=max(r["worse_of_changed"] for r in rs),
                        ok=sum(meets(r) for r in rs), n=len(rs)))
    out.sort(key=lambda s: s["relmse"])
    return out


def summary_table(summary):
    print("| method | mean ms / frame | relMSE (geo. mean) | after NL-means (geo. mean) | min recall | "
          "max false pos. | min highlights kept | max made worse / changed | scenes meeting all targets |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for s in summary:
        print(f"| {s['method']} | {s['ms']:.1f} | {s['relmse']:.4g} | {fmt(s['ds'])} | {s['recall']:.4f} | "
              f"{pct(s['fp'])} | {s['hl']:.4f} | {s['worse']:.2f} | {s['ok']}/{s['n']} |")
    print()


# ---------------------------------------------------------------------------------------
# The accuracy targets, by group, checked on whatever scenes the run has.

class Targets:
    def __init__(self, rows):
        self.at = {(r["scene"], r["method"]): r for r in rows}
        self.scenes = sorted({r["scene"] for r in rows})
        self.lines = []
        self.keepers = None

    def get(self, sc, m):
        return self.at.get((sc, m))

    def add(self, group, target, scene, measured, met):
        self.lines.append((group, target, scene, measured, met))

    def keeping_peers(self, sc):
        """The peers that keep highlights, a property of the method: their median share of
        highlight pixels kept over the simulated scenes that have highlights (where some peer
        changes one) is >= 0.9. The same set on every scene, real renders included."""
        if self.keepers is None:
            rows = [r for r in self.at.values() if is_sim(r) and "@k" not in r["scene"]]
            lit = {r["scene"] for r in rows if r["highlight_kept"] is not None and r["highlight_kept"] < 1.0}
            self.keepers = []
            for p in PEERS:
                v = sorted(r["highlight_kept"] for r in rows if r["method"] == p and r["scene"] in lit)
                if v and v[len(v) // 2] >= 0.9:
                    self.keepers.append(p)
        return [r for r in (self.get(sc, p) for p in self.keepers) if r]

    def base(self):
        for sc in self.scenes:
            r = self.get(sc, "firefly")
            if r and r["recall"] is not None:
                self.add("detection", "recall >= 0.99, false pos. <= 0.1%, highlights kept >= 0.99", sc,
                         f"{r['recall']:.4f}, {pct(r['false_positive'])}, {r['highlight_kept']:.4f}", meets(r))

    def downstream(self):
        for sc in self.scenes:
            r = self.get(sc, "firefly")
            peers = [p for p in self.keeping_peers(sc) if p["ds"] is not None]
            if not r or r["ds"] is None or not peers:
                continue
            best = min(peers, key=lambda p: p["ds"])
            base = r["recall"] is None or meets(r)  # and the detection targets still met (simulated)
            self.add("downstream", "after NL-means: firefly lowest of the highlight-keeping prefilters"
                     + ("" if r["recall"] is None else ", detection targets met"), sc,
                     # a tie is the lowest too: a frame without fireflies that firefly and the
                     # best peer both leave exactly as it was gives both the denoiser's own result
                     f"{r['ds']:.4g} vs {best['method']} {best['ds']:.4g}", r["ds"] <= best["ds"] and base)

    def interiors(self):
        for sc in ("cycles-interior", "interior"):
            r, cy, inp = self.get(sc, "firefly"), self.get(sc, "cycles_prefilter"), self.get(sc, "input")
            if not (r and cy and inp):
                continue
            self.add("interiors", "relMSE below the Cycles prefilter's", sc, f"{r['relmse']:.4g} vs {cy['relmse']:.4g}",
                     r["relmse"] < cy["relmse"])
            if r["ds"] is not None and inp["ds"] is not None:
                self.add("interiors", "after NL-means no worse than the denoiser alone", sc,
                         f"{r['ds']:.4g} vs {inp['ds']:.4g}", r["ds"] <= inp["ds"])

    def brightness(self):
        r, cy = self.get("decades", "firefly"), self.get("decades", "cycles_prefilter")
        if r and cy:
            self.add("brightness", "three decades: recall >= 0.99, false pos. <= 0.1%, relMSE below Cycles'", "decades",
                     f"{r['recall']:.4f}, {pct(r['false_positive'])}, {r['relmse']:.4g} vs {cy['relmse']:.4g}",
                     r["recall"] >= 0.99 and r["false_positive"] <= 0.001 and r["relmse"] < cy["relmse"])
        for sc in [s for s in self.scenes if s == "fog" or s.startswith("null_")]:
            r, inp = self.get(sc, "firefly"), self.get(sc, "input")
            if r and inp:
                self.add("calibration", "no fireflies: pixels changed <= 0.1%, relMSE no worse than the input's", sc,
                         f"{pct(r['changed'])}, {r['relmse']:.4g} vs {inp['relmse']:.4g}",
                         r["changed"] <= 0.001 and r["relmse"] <= inp["relmse"])
        worse = [self.get(sc, "firefly") for sc in self.scenes]
        worse = [r for r in worse if r and r["changed"]]
        for r in [r for r in worse if not is_sim(r)]:
            self.add("made worse", "changed pixels made worse than the input (reported)", r["scene"],
                     f"{pct(r['worse'])} of pixels, {r['worse_of_changed']:.2f} of changed", None)
        sims = [r for r in worse if is_sim(r)]
        if sims:
            top = max(sims, key=lambda r: r["worse"])
            self.add("made worse", "changed pixels made worse than the input (reported; every scene in its table)",
                     f"simulated, worst: {top['scene']}",
                     f"{pct(top['worse'])} of pixels, {top['worse_of_changed']:.2f} of changed", None)

    def dense(self):
        for sc in ("dense10", "dense30"):
            r = self.get(sc, "firefly")
            if r:
                self.add("dense", "dense: recall >= 0.99, highlights kept >= 0.99", sc,
                         f"{r['recall']:.4f}, {r['highlight_kept']:.4f}",
                         r["recall"] >= 0.99 and r["highlight_kept"] >= 0.99)

    def buffers(self):
        for sc in self.scenes:
            g = [r for (s, m), r in self.at.items() if s == sc and m.startswith(GMON) and "_k2_" not in m]
            # the K-buffer detector where it ran on the K buffers, else firefly on two halves
            kf = [x for (s, m), x in self.at.items() if s == sc and m.startswith("firefly_k")]
            r = kf[0] if kf else self.get(sc, "firefly")
            if not g or not r:
                continue
            best = min(g, key=lambda x: x["relmse"])
            if not sc.startswith("null_"):  # no fireflies: the target there is the mean's
                hl = r.get("highlight_not_lowered")  # energy return adds light to highlights,
                strict = r.get("highlight_kept")      # takes none: kept, but not unchanged
                self.add("K buffers", "relMSE below G-MoN's (its best variant, threshold and grouping), highlights kept "
                         "(not lowered) >= 0.99", sc,
                         f"{r['method']} {r['relmse']:.4g} vs {best['method']} {best['relmse']:.4g}"
                         + ("" if hl is None else f", highlights not lowered {hl:.3f} (unchanged {strict:.3f})"),
                         r["relmse"] < best["relmse"] and (hl is None or hl >= 0.99))
            mean = [x for (s, m), x in self.at.items() if s == sc and m.startswith("mean_k")]
            if sc.startswith("null_") and mean:
                self.add("K buffers", "no fireflies: relMSE no worse than the mean of the buffers", sc,
                         f"{r['method']} {r['relmse']:.4g} vs {mean[0]['relmse']:.4g}", r["relmse"] <= mean[0]["relmse"])

    def print(self):
        print("| group | target | scene | measured (firefly at defaults) | met |")
        print("|---|---|---|---|:---:|")
        for group, target, sc, measured, met in self.lines:
            print(f"| {group} | {target} | {sc} | {measured} | {'-' if met is None else ('yes' if met else '**no**')} |")
        print()
        checked = [m for *_, m in self.lines if m is not None]
        print(f"{sum(checked)} of {len(checked)} checked targets met. Highlight-keeping peers in this run: "
              f"{', '.join(self.keepers or []) or 'none'}.\n")


# ---------------------------------------------------------------------------------------
# The plot: accuracy against time, every method (left), firefly's configurations (middle),
# and after NL-means (right).

def pareto(ax, pts):
    front, best = [], float("inf")
    for ms, e, *_ in sorted(pts):
        if e < best:
            front.append((ms, e))
            best = e
    ax.plot([p[0] for p in front], [p[1] for p in front], "k--", lw=0.8, label="Pareto front")


def panel(ax, pts, title, ylabel, label_all, baseline=None):
    base = [p for p in pts if p[2] == "input"]
    pts = [p for p in pts if p[2] != "input"]
    if base and baseline:  # no filter: a level to beat, not a point on the time axis
        ax.axhline(base[0][1], color="tab:gray", lw=0.8, ls=":", label=baseline)
    for k, (ms, e, m, ok) in enumerate(sorted(pts, key=lambda p: p[1])):
        mine = m.startswith("firefly")
        ax.scatter(ms, e, s=36, c=("tab:green" if mine else "tab:red"), marker=("o" if ok else "x"))
        if label_all or not mine or m in ("firefly", "firefly_paper"):
            ax.annotate(m.replace("firefly_", "") if label_all else m, (ms, e), fontsize=7,
                        xytext=(5, -10 + 8 * (k % 4)), textcoords="offset points")
    if pts and not label_all:
        pareto(ax, pts)
    if not label_all and ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper right", fontsize=8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("time per frame (ms, log)")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=9)
    ax.grid(True, which="both", lw=0.3)


def real_downstream(rows):
    """(ms, geometric mean of the after-NL-means relMSE, method, True) over the real renders, for
    the methods that have the column on every one of them."""
    by = defaultdict(list)
    for r in rows:
        if not is_sim(r) and r["ds"] is not None:
            by[r["method"]].append(r)
    n = max((len(v) for v in by.values()), default=0)
    return [(sum(r["ms"] for r in rs) / n, geo([r["ds"] for r in rs]), m, True)
            for m, rs in by.items() if len(rs) == n and not is_kbuf(m)]


def plot(summary, path, size, rows):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 3, figsize=(18, 5.8), dpi=90)
    pts = [(s["ms"], s["relmse"], s["method"], s["ok"] == s["n"]) for s in summary]
    panel(axes[0], pts, f"all methods ({size}): firefly green, peers red\no: meets every target on every "
          "simulated scene, x: misses one", "relMSE, geometric mean over the simulated scenes", False,
          "input (no filter)")
    panel(axes[1], [p for p in pts if p[2].startswith("firefly")], "firefly's configurations (zoom)",
          "relMSE, geometric mean", True)
    panel(axes[2], real_downstream(rows), "real renders, after NL-means (best strength per method)",
          "relMSE after NL-means, geometric mean over the real renders", False, "the denoiser alone")
    fig.tight_layout()
    fig.savefig(path)


def frame_size(data):
    return data.get("context", {}).get("simulated_frame", "2048x1080")


HEADER = """# Accuracy

Generated by `bench/accuracy_report.py` from a run of `firefly_accuracy` and `bench/downstream.py`;
do not edit by hand.

## How to regenerate

```sh
cmake -S . -B build/acc -DCMAKE_BUILD_TYPE=Release -DFIREFLY_BUILD_TESTS=OFF -DFIREFLY_BUILD_EXAMPLES=OFF
cmake --build build/acc -j2 --target firefly_accuracy
rm -rf /tmp/ff-images
FIREFLY_ACCURACY_SIZE={size} FIREFLY_ACCURACY_IMAGES=/tmp/ff-images \\
  build/acc/bench/firefly_accuracy --benchmark_format=json --benchmark_out=/tmp/accuracy.json
/usr/bin/python3 bench/downstream.py /tmp/ff-images -o /tmp/downstream.json
/usr/bin/python3 bench/accuracy_report.py /tmp/accuracy.json --downstream /tmp/downstream.json \\
  --merged docs/accuracy.json --plot docs/accuracy_vs_time.png > docs/accuracy.md
```

Without `FIREFLY_ACCURACY_SIZE` the simulated scenes are 2048x1080. NL-means runs on a 320x180
centre crop of each simulated scene at any size (`FIREFLY_ACCURACY_CROP`) and not on the `@k`
variants, to keep its cost affordable on two cores; the real renders are always whole. Real
renders missing from `../shared/data` are skipped with a note. `/usr/bin/python3` is Debian's
(python3-skimage, python3-matplotlib). `accuracy_report.py docs/accuracy.json` alone rebuilds
this page from the merged file. `FIREFLY_ACCURACY_RENDERS=DIR[:DIR...]` adds renders of one's
own laid out as those folders (`bench/renders/README.md`: held-out Blender scenes, measured).

This run: simulated frames {size}, {date}, {cpus} CPUs ({load}).

## What is measured

- **Scenes.** Every named simulated scene (`firefly/sim/scenes.hpp`, ground truth known), the
  hard low-sample variants `@16spp`, K-buffer variants `@k4`/`@k8` (the simulator's K buffers,
  at most 1024x540; the half-buffer methods get their two halves, K/2 buffers each, the same
  samples), and the
  real renders `cycles-caustics`, `cycles-interior` (half buffers with variance) and
  `cycles-caustics-seeds` (8 renders of 16 samples with different seeds, no variance: the
  halves are 4 + 4 renders with the variance of their mean from their spread; reference that of
  `cycles-caustics`).
- **relMSE**: mean over pixels and channels of (x - ref)^2 / (ref^2 + 0.01) of the combined
  image ((A + B) / 2, or the estimator's output) against the expected radiance (simulated) or
  the high-sample reference (real); a non-finite value counts 1e6.
- **recall, false pos., highlights kept** (simulated only; `firefly/sim/metrics.hpp`): visible
  firefly hits lowered; clean non-highlight pixels lowered; highlight pixels lowered in neither
  half. Lowered: changed, with some channel now below the input (or a non-finite input).
  Removing a firefly lowers its pixel; giving removed energy back (`energy.hpp`, on by default)
  only adds light, a change of the estimate that relMSE, made worse and energy measure, not a
  detection.
- **changed**: pixels whose combined output differs from the input's (beyond float round-off).
- **made worse**: pixels changed *and* further from the reference than the input was (per-pixel
  error: the relMSE term summed over the channels; a non-finite input is infinitely far), as a
  share of all pixels, and in parentheses as a share of the changed pixels.
- **energy**: mean brightness of the output / the reference's, over all pixels, the dark ones
  (reference below the median of the lit pixels) and the bright ones (at or above their 95th
  percentile). 1 = no energy lost; an unbiased input reads ~1, a prefilter that cuts real
  light reads below. The reference holds the fireflies' expected energy (the simulator's
  expected radiance includes it, as a converged render does), so removing fireflies always
  costs some energy; what matters is how much, and where.
- **after NL-means**: scikit-image's non-local means on log(1 + x) (patch 5, distance 6,
  fast mode, sigma from `estimate_sigma`), at the strength h in {0.5, 2, 8, 32} x sigma that
  gives that method its lowest relMSE (one grid for all; fireflies survive NL-means unless h is
  far above the noise); `input` there is the denoiser alone (after the shared
  non-finite repair, which NL-means needs). The same after two denoisers of other kinds, so
  that no conclusion rests on one: wavelet shrinkage (BayesShrink, soft) and total variation
  (Chambolle), each at its best of {0.25, 0.5, ..., 64} x sigma. See `bench/downstream.py`.
- **ms**: time per frame (both halves, or all K buffers), Release build, on a machine shared
  with other work: compare within one run.

**Fair peers.** Every peer (median3x3, cycles_prefilter, bcd_spikes, nrd_clamp, clamps; see
`bench/peers.hpp`) first gets the same non-finite repair: a pixel whose colour or variance is
NaN/Inf in one half takes the other half's values when those are finite, else the mean of its
finite 3x3 neighbours, else 0. The tables measure firefly handling, not NaN handling; firefly
handles non-finite pixels itself.

**K-buffer estimators** (per pixel, over K buffers grouped into M means): `mean_kK`,
`mon_kK_mM` (median of the M means), and G-MoN (Buisine, Delepoulle and Renaud, EGSR 2021)
in its two variants, both driven by the Gini coefficient G of the M means, averaged over the
channels: `agmon_kK_mM`, the paper's adaptive G-MoN (Section 4.3, Eq. 6), the mean of the
sorted means once floor(G M / 2) are dropped at each end; and `gmon_kK_mM_tT`, its binary
variant, the mean below T (the paper's 0.25) and the median of means at or above it, run at
T = 0.1, 0.25 and 0.4. "Best G-MoN" is the best of all of these, and the targets compare
against it. On two halves (K = 2) all of them are the mean of the halves, so their rows are
left out of the per-scene tables there.

**Highlight-keeping peers** (the downstream target): a property of the method, read off the simulated
scenes that have highlight pixels: the peers whose median share of highlight pixels kept over
those scenes is >= 0.9. The same set is used on every scene, real renders included (where
highlights are not known); the targets table names it.
"""


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("json", help="firefly_accuracy --benchmark_format=json output (or a merged file)")
    ap.add_argument("--downstream", help="bench/downstream.py output")
    ap.add_argument("--merged", help="write the benchmark JSON with the downstream results here")
    ap.add_argument("--plot", help="write the accuracy-versus-time plot here (PNG)")
    a = ap.parse_args()
    data, rows = load(a.json)
    ds = data.get("downstream")
    if a.downstream:
        with open(a.downstream) as f:
            ds = json.load(f)
    attach_downstream(rows, ds)
    if a.merged:
        data["downstream"] = ds
        with open(a.merged, "w") as f:
            json.dump(data, f, indent=1)
    sim = [r for r in rows if is_sim(r) and "@k" not in r["scene"]]
    summary = summarize(sim)
    size = frame_size(data)

    ctx = data.get("context", {})
    print(HEADER.replace("{size}", size).replace("{date}", ctx.get("date", "?")).replace(
        "{cpus}", str(ctx.get("num_cpus", "?"))).replace(
        "{load}", "load average " + ", ".join(f"{v:.1f}" for v in ctx.get("load_avg", [])) or "?"))
    print("## Targets\n")
    t = Targets(rows)
    for check in (t.base, t.dense, t.downstream, t.interiors, t.brightness, t.buffers):
        check()
    t.print()
    print(f"## Accuracy against time\n\n![accuracy against time]({a.plot.split('/')[-1] if a.plot else 'accuracy_vs_time.png'})\n")
    print("Over the simulated half-buffer scenes (the `@k` scenes, which only firefly, the paper and the peers "
          "run, and the K-buffer estimators, which on two halves are the mean, are left out):\n")
    summary_table(summary)
    print("## After a real denoiser\n")
    downstream_table(rows)
    if any(len(r["dsx"]) > 1 for r in rows):
        print("### After denoisers of two other kinds\n")
        for name in DENOISER_NAMES:
            if name != "nl_means":
                downstream_table(rows, name)
        across_denoisers(rows, t)
    print("## K buffers\n")
    print("relMSE on the scenes with K > 2 buffers (hl: highlights kept, simulated scenes); the "
          "half-buffer methods run on two halves of the same samples.\n")
    buffers_table(rows)
    print("## Per scene\n")
    for sc in sorted({r["scene"] for r in rows}, key=scene_order(rows)):
        scene_table(sc, [r for r in rows if r["scene"] == sc])
    if a.plot:
        plot(summary, a.plot, size, rows)


if __name__ == "__main__":
    sys.exit(main())
