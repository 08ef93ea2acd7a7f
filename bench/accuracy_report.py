#!/usr/bin/python3
"""Turns firefly_accuracy's JSON (--benchmark_format=json) into Markdown tables and a plot of
accuracy against time (a Pareto front).

    ./firefly_accuracy --benchmark_format=json --benchmark_out=accuracy.json
    python3 bench/accuracy_report.py accuracy.json --plot docs/accuracy_vs_time.png > table.md

Targets (per scene, defaults): recall >= 0.99, false positives <= 0.1%, highlights kept >= 0.99.
The summary ranks methods by the geometric mean of relMSE over the simulated scenes.
"""
import argparse
import json
import math
import sys
from collections import defaultdict


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
        scene, method = parts[1], parts[2]
        ms = b["real_time"] if b.get("time_unit") == "ms" else b["real_time"] / 1e6
        rows.append(dict(scene=scene, method=method, ms=ms, **{k: b.get(k) for k in
                    ("recall", "precision", "false_positive", "highlight_kept", "relmse", "changed")}))
    return rows


def meets(r):
    return r["recall"] >= 0.99 and r["false_positive"] <= 0.001 and r["highlight_kept"] >= 0.99


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("json")
    ap.add_argument("--plot", help="write the accuracy-versus-time plot here (PNG)")
    a = ap.parse_args()
    rows = load(a.json)
    sim = [r for r in rows if r["scene"] != "cycles-caustics"]
    real = [r for r in rows if r["scene"] == "cycles-caustics"]
    methods = sorted({r["method"] for r in sim}, key=lambda m: (not m.startswith("firefly"), m))
    scenes = sorted({r["scene"] for r in sim})

    # Summary over the simulated scenes.
    by = defaultdict(list)
    for r in sim:
        by[r["method"]].append(r)
    summary = []
    for m in methods:
        rs = by[m]
        geo = math.exp(sum(math.log(max(r["relmse"], 1e-12)) for r in rs) / len(rs))
        summary.append(dict(method=m, ms=sum(r["ms"] for r in rs) / len(rs), relmse=geo,
                            recall=min(r["recall"] for r in rs), fp=max(r["false_positive"] for r in rs),
                            hl=min(r["highlight_kept"] for r in rs), ok=sum(meets(r) for r in rs), n=len(rs)))
    summary.sort(key=lambda s: s["relmse"])
    print("| method | mean ms / 2K frame | relMSE (geo. mean) | min recall | max false pos. | min highlights kept | scenes meeting all targets |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for s in summary:
        print(f"| {s['method']} | {s['ms']:.1f} | {s['relmse']:.4g} | {s['recall']:.4f} | {100 * s['fp']:.3f}% | "
              f"{s['hl']:.4f} | {s['ok']}/{s['n']} |")
    print()

    # Per scene: firefly's default against the peers.
    show = [m for m in methods if m in ("firefly", "firefly_paper") or not m.startswith("firefly")]
    for sc in scenes:
        print(f"**{sc}**\n")
        print("| method | ms | recall | precision | false pos. | highlights kept | relMSE | meets targets |")
        print("|---|---:|---:|---:|---:|---:|---:|:---:|")
        for m in show:
            for r in sim:
                if r["scene"] == sc and r["method"] == m:
                    print(f"| {m} | {r['ms']:.1f} | {r['recall']:.4f} | {r['precision']:.4f} | "
                          f"{100 * r['false_positive']:.3f}% | {r['highlight_kept']:.4f} | {r['relmse']:.4g} | "
                          f"{'yes' if meets(r) else 'no'} |")
        print()
    if real:
        print("**cycles-caustics (real render, relMSE against the high-sample reference)**\n")
        print("| method | ms | pixels changed | relMSE |")
        print("|---|---:|---:|---:|")
        for r in sorted(real, key=lambda r: r["relmse"]):
            print(f"| {r['method']} | {r['ms']:.2f} | {100 * r['changed']:.2f}% | {r['relmse']:.4g} |")
        print()

    if a.plot:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, (ax, az) = plt.subplots(1, 2, figsize=(13, 5.5), dpi=100)
        pts = sorted(((s["ms"], s["relmse"], s["method"], s["ok"] == s["n"]) for s in summary))
        for ms, e, m, ok in pts:
            mine = m.startswith("firefly")
            ax.scatter(ms, e, s=36, c=("tab:green" if mine else "tab:red"), marker=("o" if ok else "x"))
            if not mine or m == "firefly":
                ax.annotate(m, (ms, e), fontsize=8, xytext=(4, 3), textcoords="offset points")
        front, best = [], float("inf")
        for ms, e, m, ok in pts:
            if e < best:
                front.append((ms, e))
                best = e
        ax.plot([p[0] for p in front], [p[1] for p in front], "k--", lw=0.8, label="Pareto front")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("time per 2K frame, both halves (ms, log)")
        ax.set_ylabel("relMSE, geometric mean over the simulated scenes (log)")
        ax.set_title("all methods: firefly (green), peers (red)\no: meets every target on every scene, x: misses one",
                     fontsize=10)
        ax.legend(loc="upper right", fontsize=8)
        ax.grid(True, which="both", lw=0.3)
        ff = [p for p in pts if p[2].startswith("firefly")]
        for k, (ms, e, m, ok) in enumerate(sorted(ff, key=lambda p: p[1])):
            az.scatter(ms, e, s=36, c="tab:green", marker=("o" if ok else "x"))
            az.annotate(m.replace("firefly_", ""), (ms, e), fontsize=8, xytext=(6, -12 + 9 * (k % 4)),
                        textcoords="offset points")
        az.set_xlabel("time per 2K frame, both halves (ms)")
        az.set_ylabel("relMSE, geometric mean")
        az.set_title("firefly's configurations (zoom)", fontsize=10)
        az.grid(True, lw=0.3)
        fig.tight_layout()
        fig.savefig(a.plot)


if __name__ == "__main__":
    sys.exit(main())
