#!/usr/bin/python3
"""How much of the autonomous rollouts' DTW goes with the run's length.

An autonomous run (paper 4.1) starts from a held-out demonstration's s_0 and lasts that
demonstration's number of ticks; nothing in autonomous mode tells the policy that length, i.e.
how fast the demonstrator moved. This prints, per movement of an `nao_toolchain evaluate`
detail.json, the correlation between a run's length and its DTW to the nearest held-out
demonstration, and the median DTW of the shorter and the longer half of the runs, beside the
same for the held-out demonstrations' own nearest-neighbour DTW (docs/evaluate.md).

usage: toolchain/analysis/duration_effect.py [out/eval/detail.json]
"""
import json
import math
import statistics
import sys


def pearson(xs, ys):
    mx, my = statistics.fmean(xs), statistics.fmean(ys)
    sxy = sum((x - mx) * (y - my) for x, y in zip(xs, ys))
    sxx = sum((x - mx) ** 2 for x in xs)
    syy = sum((y - my) ** 2 for y in ys)
    return sxy / math.sqrt(sxx * syy) if sxx > 0 and syy > 0 else float("nan")


def halves(pairs):
    """Median DTW (mm) of the runs at or below the median length and of those above it."""
    cut = statistics.median(t for t, _ in pairs)
    short = [v for t, v in pairs if t <= cut]
    long_ = [v for t, v in pairs if t > cut]
    return cut, statistics.median(short), statistics.median(long_) if long_ else float("nan")


def main(argv):
    path = argv[1] if len(argv) > 1 else "out/eval/detail.json"
    try:
        with open(path, encoding="utf-8") as f:
            detail = json.load(f)
    except (OSError, ValueError) as e:
        sys.exit(f"duration_effect: cannot read {path}: {e}")
    print("| movement | runs | r(length, DTW) | median length (ticks) | DTW, shorter half (mm) | DTW, longer half (mm) |"
          " demo NN r(length, DTW) |")
    print("|---|---|---|---|---|---|---|")
    for movement, m in detail.items():
        runs = [(r["ticks"], 1e3 * r["dtw_nearest_m"]) for r in m.get("autonomous", [])]
        if len(runs) < 4:
            continue
        length = {r["start_demo"]: r["ticks"] for r in m["autonomous"]}
        nn = [(length[d["demo"]], 1e3 * d["dtw_nearest_m"]) for d in m.get("demo_nn", []) if d["demo"] in length]
        cut, short, long_ = halves(runs)
        r_nn = pearson(*zip(*nn)) if len(nn) >= 4 else float("nan")
        print(f"| {movement} | {len(runs)} | {pearson(*zip(*runs)):+.2f} | {cut:g} | {short:.1f} | {long_:.1f} | {r_nn:+.2f} |")


if __name__ == "__main__":
    main(sys.argv)
