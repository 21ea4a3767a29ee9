#!/usr/bin/python3
"""Which joints an autonomous policy moves too much or too little: per movement and joint, the
runs of an `nao_toolchain evaluate` output against its held-out demonstrations.

evaluate's speed ratio is one number for the hand; this splits it by joint. Over the middle 60 %
of each path's ticks (evaluate's middle stretch: indices floor(0.2 n) to ceil(0.8 n)):

- velocity: the RMS of the joint's tick-to-tick change / the tick period (rad/s);
- amplitude: the standard deviation of the joint's angle (rad): how far it strays from its own
  mean, whether by circling or by drifting.

Each is the median over the runs divided by the median over the demonstrations. Runs are
EVAL_DIR/<movement>/autonomous/<run>/ticks.csv (q_0..q_4), demonstrations
EVAL_DIR/<movement>/demos/<name>.csv (t_s, q_0..q_4): the files evaluate writes
(docs/evaluate.md). A ratio above 1 says the runs move that joint more than the demonstrations.

usage: toolchain/analysis/joint_motion.py [EVAL_DIR (out/eval)] [--json OUT]
"""
import argparse
import csv
import glob
import json
import math
import os
import sys

import numpy as np

JOINTS = ("RShoulderPitch", "RShoulderRoll", "RElbowYaw", "RElbowRoll", "RWristYaw")
PERIOD_S = 0.1  # evaluate's tick


class MotionError(Exception):
    pass


def read_q(path):
    """q (n, 5) of a ticks.csv or a demos/<name>.csv."""
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    try:
        q = np.array([[float(r["q_%d" % j]) for j in range(5)] for r in rows])
    except (KeyError, ValueError) as e:
        raise MotionError("%s: no usable q_0..q_4 columns (%s)" % (path, e))
    if len(q) < 2:
        raise MotionError("%s: fewer than 2 ticks" % path)
    return q


def middle(q):
    """evaluate's middle stretch of a path: ticks [floor(0.2 n), ceil(0.8 n))."""
    n = len(q)
    return q[int(math.floor(0.2 * n)):int(math.ceil(0.8 * n))]


def velocity(q, period_s=PERIOD_S):
    """(5,) RMS joint velocity over the middle stretch, rad/s."""
    m = middle(q)
    if len(m) < 2:
        return np.full(5, np.nan)
    v = np.diff(m, axis=0) / period_s
    return np.sqrt((v ** 2).mean(axis=0))


def amplitude(q):
    """(5,) standard deviation of each joint over the middle stretch, rad."""
    return middle(q).std(axis=0)


def movement_motion(runs, demos):
    """Per joint: run/demonstration ratios of the median velocity and amplitude, and the
    demonstrations' medians themselves."""
    if not runs or not demos:
        raise MotionError("need runs and demonstrations (%d runs, %d demonstrations)" % (len(runs), len(demos)))
    rv = np.median([velocity(q) for q in runs], axis=0)
    dv = np.median([velocity(q) for q in demos], axis=0)
    ra = np.median([amplitude(q) for q in runs], axis=0)
    da = np.median([amplitude(q) for q in demos], axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return {"velocity_ratio": (rv / dv).tolist(), "amplitude_ratio": (ra / da).tolist(),
                "demo_velocity_rad_s": dv.tolist(), "demo_amplitude_rad": da.tolist(),
                "runs": len(runs), "demos": len(demos)}


def eval_motion(eval_dir):
    """{movement: movement_motion} of every movement directory of an evaluate output."""
    out = {}
    for mdir in sorted(glob.glob(os.path.join(eval_dir, "*", "autonomous"))):
        movement = os.path.basename(os.path.dirname(mdir))
        runs = [read_q(p) for p in sorted(glob.glob(os.path.join(mdir, "*", "ticks.csv")))]
        demos = [read_q(p) for p in sorted(glob.glob(os.path.join(os.path.dirname(mdir), "demos", "*.csv")))]
        out[movement] = movement_motion(runs, demos)
    if not out:
        raise MotionError("%s: no <movement>/autonomous/ directories (an nao_toolchain evaluate output?)" % eval_dir)
    return out


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("eval_dir", nargs="?", default="out/eval", help="an nao_toolchain evaluate output (default out/eval)")
    ap.add_argument("--json", help="write the numbers here too")
    a = ap.parse_args(argv[1:])
    try:
        report = eval_motion(a.eval_dir)
    except (OSError, MotionError) as e:
        print("joint_motion: %s" % e, file=sys.stderr)
        return 1
    print("Runs / demonstrations over the middle 60 %% of the ticks (%s), per joint %s:\n" % (a.eval_dir, ", ".join(JOINTS)))
    print("| movement | velocity ratio | amplitude ratio | demonstrations' velocity, rad/s |")
    print("|---|---|---|---|")
    for m, r in report.items():
        print("| %s | %s | %s | %s |" % (m, " / ".join("%.2f" % v for v in r["velocity_ratio"]),
                                        " / ".join("%.2f" % v for v in r["amplitude_ratio"]),
                                        " / ".join("%.3f" % v for v in r["demo_velocity_rad_s"])))
    if a.json:
        with open(a.json, "w", encoding="utf-8") as fh:
            json.dump(report, fh, indent=2, sort_keys=True)
            fh.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
