#!/usr/bin/python3
"""Autonomous runs grouped by their start key pose (docs/evaluate.md, "Why: an autonomous run
starts at a key pose").

An autonomous run (nao_rt --reference none --start-demo I) starts at the first sample of its
demonstration's feature-extracted trajectory, which is a key pose; the policy is deterministic,
so runs from one start are one rollout cut at different lengths. This pools the autonomous runs
of one or more `nao_toolchain evaluate` output directories (EVAL/detail.json and the run
directories it names) by their start (the first row's q_0..q_4 of ticks.csv, rounded to 0.01 rad)
and prints per movement and start: the runs, the median (min-max) DTW to the nearest
demonstration, and how many demonstrations of the data set start there (the label of the first
sample of DATA/<movement>_<index>/features.csv, matched to the start through DATA/centroids.json).

usage: toolchain/analysis/start_poses.py [--data DATA_DIR (out/train/data)] EVAL_DIR...
"""
import argparse
import csv
import glob
import json
import os
import sys

import numpy as np


def first_q(run_dir):
    with open(os.path.join(run_dir, "ticks.csv"), newline="", encoding="utf-8") as f:
        row = next(csv.DictReader(f))
    return np.array([float(row["q_%d" % j]) for j in range(5)])


def data_starts(data, movement, centroids):
    """Per key-pose label: the demonstrations of `movement` whose first sample has it."""
    counts = {}
    for path in sorted(glob.glob(os.path.join(data, movement + "_[0-9][0-9][0-9]", "features.csv"))):
        with open(path, newline="", encoding="utf-8") as f:
            label = int(next(csv.DictReader(f))["label"])
        counts[label] = counts.get(label, 0) + 1
    return counts


def main(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", default="out/train/data")
    p.add_argument("eval_dirs", nargs="+")
    a = p.parse_args(argv[1:])
    try:
        with open(os.path.join(a.data, "centroids.json"), encoding="utf-8") as f:
            centroids = json.load(f)["movements"]
        details = []
        for d in a.eval_dirs:
            with open(os.path.join(d, "detail.json"), encoding="utf-8") as f:
                details.append((d, json.load(f)))
    except (OSError, ValueError, KeyError) as e:
        print("start_poses: %s" % e, file=sys.stderr)
        return 1
    print("| movement | start key pose (q_0..q_4, rad) | demonstrations of the data set starting there | runs | "
          "DTW median (min-max), mm |")
    print("|---|---|---|---|---|")
    for movement in sorted(centroids):
        groups = {}
        for d, detail in details:
            for run in detail.get(movement, {}).get("autonomous", []):
                q = first_q(os.path.join(d, run["run_dir"]))
                key = tuple(np.round(q, 2))
                groups.setdefault(key, []).append(1e3 * run["dtw_nearest_m"])
        if not groups:
            continue
        c = np.array(centroids[movement]["centroids"])
        counts = data_starts(a.data, movement, c)
        for key in sorted(groups, key=lambda k: -len(groups[k])):
            v = np.array(groups[key])
            label = int(np.argmin(np.linalg.norm(c - np.array(key), axis=1)))
            near = np.linalg.norm(c[label] - np.array(key)) < 0.05  # the first measured q is within ~0.02 rad of its key pose
            n_data = counts.get(label, 0) if near else 0
            print("| %s | %s | %d | %d | %.1f (%.1f-%.1f) |" % (
                movement, " ".join("%.2f" % x for x in key), n_data, len(v), np.median(v), v.min(), v.max()))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
