#!/usr/bin/python3
"""How much the autonomous rollouts move, beside their demonstrations and the demonstrations' mean.

For every autonomous run of an `nao_toolchain evaluate` output (EVAL/<movement>/autonomous/<demo>/
ticks.csv) and its start demonstration's feature trajectory f (DATA/<demo>/features.csv, the data
set of `toolchain/nao train data`), per movement and joint: the RMS of the per-tick joint change
(rad per tick) of the rollouts' q, of the held-out demonstrations' f, and of the tick-by-tick mean
of those demonstrations (over the ticks all of them have). A policy trained by mean squared error
on demonstrations whose loops run at different phases learns something near that mean, which has
lost the loops: the third column shows how much motion is left in it (docs/evaluate.md).

usage: toolchain/analysis/rollout_motion.py [EVAL_DIR (out/eval)] [DATA_DIR (out/train/data)]
                                           [--figure PNG [--movement M (elbow)]]
--figure also draws movement M's joints over the ticks: the demonstrations (grey), their mean
(black) and the rollouts (colour).
"""
import argparse
import csv
import json
import os
import sys

import numpy as np

MOVEMENTS = ("whole_arm", "elbow", "wrist")


def columns(path, prefix):
    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise ValueError(f"{path}: no rows")
    return np.array([[float(r[f"{prefix}{j}"]) for j in range(5)] for r in rows])


def step_rms(paths):
    """Per joint: the RMS over every tick of every path of |x(t+1) - x(t)|, rad."""
    d = np.concatenate([np.diff(p, axis=0) for p in paths])
    return np.sqrt((d**2).mean(axis=0))


def main(argv):
    ap = argparse.ArgumentParser(description="autonomous rollouts' motion against their demonstrations")
    ap.add_argument("eval_dir", nargs="?", default="out/eval")
    ap.add_argument("data_dir", nargs="?", default="out/train/data")
    ap.add_argument("--figure", help="PNG of one movement's joints over the ticks")
    ap.add_argument("--movement", default="elbow", choices=MOVEMENTS)
    a = ap.parse_args(argv[1:])
    ev, data = a.eval_dir, a.data_dir
    try:
        with open(os.path.join(ev, "detail.json"), encoding="utf-8") as f:
            detail = json.load(f)
    except (OSError, ValueError) as e:
        print(f"rollout_motion: {e}", file=sys.stderr)
        return 1
    drawn = None
    print("| movement | runs | rollouts: RMS change per tick, joints 0-4 (mrad) | demonstrations | "
          "demonstrations' tick-by-tick mean | rollouts / demonstrations (all joints) | mean / demonstrations |")
    print("|---|---|---|---|---|---|---|")
    for m in MOVEMENTS:
        if m not in detail:
            continue
        runs = detail[m]["autonomous"]
        try:
            q = [columns(os.path.join(ev, r["run_dir"], "ticks.csv"), "q_") for r in runs]
            f = [columns(os.path.join(data, r["start_demo"], "features.csv"), "f_") for r in runs]
        except (OSError, KeyError, ValueError) as e:
            print(f"rollout_motion: {m}: {e}", file=sys.stderr)
            return 1
        n = min(len(x) for x in f)
        mean = np.mean([x[:n] for x in f], axis=0)
        rq, rf, rm = step_rms(q), step_rms(f), step_rms([mean])
        total = lambda v: float(np.sqrt((v**2).sum()))
        fmt = lambda v: " ".join(f"{1e3 * x:.0f}" for x in v)
        print(f"| {m} | {len(runs)} | {fmt(rq)} | {fmt(rf)} | {fmt(rm)} | "
              f"{total(rq) / total(rf):.2f} | {total(rm) / total(rf):.2f} |")
        if m == a.movement:
            drawn = (q, f, mean)
    if a.figure:
        if drawn is None:
            print(f"rollout_motion: no autonomous runs of {a.movement} in {ev}", file=sys.stderr)
            return 1
        figure(a.figure, a.movement, *drawn)
    return 0


def figure(path, movement, q, f, mean):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = ("RShoulderPitch", "RShoulderRoll", "RElbowYaw", "RElbowRoll", "RWristYaw")
    fig, ax = plt.subplots(5, 1, figsize=(8, 11), sharex=True)
    for j in range(5):
        for x in f:
            ax[j].plot(x[:, j], color="0.7", lw=0.7)
        for x in q:
            ax[j].plot(x[:, j], lw=0.9)
        ax[j].plot(mean[:, j], color="k", lw=1.6, ls="--")
        ax[j].set_ylabel(f"{names[j]} (rad)")
    ax[0].set_title(f"{movement}: autonomous rollouts (colour), their start demonstrations (grey), "
                    "the demonstrations' mean (black)", fontsize=9)
    ax[-1].set_xlabel("tick (0.1 s)")
    fig.tight_layout()
    fig.savefig(path, dpi=70, metadata={"Software": None})
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main(sys.argv))
