#!/usr/bin/python3
"""What a deterministic autonomous policy could score at best: fixed trajectories from the data.

The autonomous bar compares a rollout's hand-path DTW to its nearest held-out
demonstration with the held-out demonstrations' own median nearest-neighbour DTW. A policy in
autonomous mode sees only s_0, the movement and the tick, so from one start it plays one fixed
trajectory. This script scores fixed trajectories built from the *training* demonstrations the
same way as `nao_toolchain evaluate` scores a rollout (one run per held-out demonstration d, from
d's start key pose, for d's number of samples, DTW to the nearest held-out demonstration), with
no policy and no simulated arm in between:

- mean: the tick-by-tick mean of the training demonstrations from d's start key pose (each held
  at its last pose past its end): what a regression on unaligned demonstrations tends to;
- warped mean: the same after each of them is time-warped by DTW (joint space) onto the group's
  medoid, the medoid's length kept: what a regression on demonstrations aligned to one template
  tends to (the idea of `--canonical-pace`);
- warped mean, shortest: the same onto the movement's shortest training demonstration, one
  template for all its starts (the template `--canonical-pace dtw` uses);
- medoid: the training demonstration from that start with the least summed DTW to the others of
  its group: a policy that commits to one typical demonstration;
- replay: every training demonstration from that start, one at a time (the median over them);
- best replay: per start, the one training demonstration whose runs score best against the
  held-out set. Chosen on the data it is scored on, so optimistic: no fixed trajectory taken from
  the training demonstrations does better.

The hand path is the forward kinematics of the feature-extracted trajectory f (features.csv),
as nao_rt builds the demonstrations' paths; DTW is rt::dtwMeanDistance's (mean distance per
matched pair, ties to the longer alignment). The held-out demonstrations are those of the
evaluation's detail.json (the model's validation split), read from DATA as they are; nao_rt
regenerates them with the runtime's retargeting, so the demonstrations' own median differs from
summary.json's `demo_nn_dtw_m` by a little.

usage: toolchain/analysis/autonomous_ceiling.py [EVAL_DIR (out/eval)] [DATA_DIR (out/train/data)]
                                               [--splits N [--seed S]] [--json OUT]
"""
import argparse
import csv
import glob
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from nao_analysis import AnalysisError  # noqa: E402
from nao_analysis.kinematics import hand_position, load_arm_model  # noqa: E402
from nao_analysis.units import dtw_mean_distances as dtw_batch  # noqa: E402

MOVEMENTS = ("whole_arm", "elbow", "wrist")


def read_features(path):
    """(labels (n,), f (n, 5)) of a features.csv."""
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    if not rows:
        raise AnalysisError("%s: no rows" % path)
    labels = np.array([int(r["label"]) for r in rows])
    f = np.array([[float(r["f_%d" % j]) for j in range(5)] for r in rows])
    return labels, f


def dtw_path(a, b):
    """The matched pairs (i, j) of a plain DTW of a against b (sum of distances, same tie order)."""
    n, m = len(a), len(b)
    d = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2)
    cost = np.full((n + 1, m + 1), np.inf)
    cost[0, 0] = 0.0
    for i in range(1, n + 1):
        for j in range(1, m + 1):
            cost[i, j] = d[i - 1, j - 1] + min(cost[i - 1, j - 1], cost[i - 1, j], cost[i, j - 1])
    i, j, path = n, m, []
    while i > 0 and j > 0:
        path.append((i - 1, j - 1))
        steps = ((cost[i - 1, j - 1], i - 1, j - 1), (cost[i - 1, j], i - 1, j), (cost[i, j - 1], i, j - 1))
        _, i, j = min(steps, key=lambda s: s[0])
    return path[::-1]


def warp_onto(f, template):
    """f time-warped onto template's samples: each template sample gets the mean of the samples
    of f matched to it."""
    acc = np.zeros_like(template)
    cnt = np.zeros(len(template))
    for i, j in dtw_path(f, template):
        acc[j] += f[i]
        cnt[j] += 1
    return acc / cnt[:, None]


def held(f, n):
    """f cut to n samples, or held at its last sample up to n."""
    if len(f) >= n:
        return f[:n]
    return np.vstack([f, np.repeat(f[-1:], n - len(f), axis=0)])


# The fixed trajectories scored per run, and their keys in the report.
KEYS = {"mean": "mean_m", "warped mean": "warped_mean_m", "warped mean, shortest": "warped_mean_shortest_m",
        "medoid": "medoid_m"}


def movement_ceiling(arm, demos, movement, heldout, replays=True):
    """The scores of one movement's fixed trajectories (module docstring) for the held-out
    demonstrations `heldout` (names in demos); every other demonstration of the movement is a
    training one. Metres; the replay columns only with `replays` (they cost most)."""
    train = [d for d in demos if d.startswith(movement + "_") and d not in heldout]
    hand = {d: hand_position(arm, demos[d][1]) for d in heldout + train}
    start = {d: demos[d][0][0] for d in heldout + train}

    # The held-out demonstrations' nearest neighbour among the others.
    pairs = [(hand[x], hand[y]) for x in heldout for y in heldout if x != y]
    nn = dtw_batch(pairs).reshape(len(heldout), len(heldout) - 1).min(axis=1)

    # Fixed trajectories per start key pose, from the training demonstrations.
    groups = {}
    for d in train:
        groups.setdefault(start[d], []).append(d)
    shortest = min(train, key=lambda d: (len(demos[d][1]), d))
    fixed = {}
    for s, g in groups.items():
        within = dtw_batch([(hand[x], hand[y]) for x in g for y in g]).reshape(len(g), len(g))
        medoid = g[int(np.argmin(within.sum(axis=1)))]
        longest = max(len(demos[d][1]) for d in g)
        fixed[s] = {
            "mean": np.mean([held(demos[d][1], longest) for d in g], axis=0),
            "warped mean": np.mean([warp_onto(demos[d][1], demos[medoid][1]) for d in g], axis=0),
            "warped mean, shortest": np.mean([warp_onto(demos[d][1], demos[shortest][1]) for d in g], axis=0),
            "medoid": demos[medoid][1],
            "group": g,
        }

    def score(trajs):
        """Per held-out run: DTW of each candidate (joint trajectory, cut to the run or held at
        its end) to the nearest held-out demonstration; and the run of each value."""
        pairs, shape = [], []
        for d in heldout:
            n = len(demos[d][1])
            for t in trajs(d):
                path = hand_position(arm, held(t, n))
                pairs += [(path, hand[y]) for y in heldout]
                shape.append(d)
        return dtw_batch(pairs).reshape(len(shape), len(heldout)).min(axis=1), shape

    row = {"demo_nn_m": float(np.median(nn)), "heldout": len(heldout), "shortest_template": shortest,
           "starts": {str(s): {"training_demos": len(g["group"]),
                               "heldout_demos": sum(1 for d in heldout if start[d] == s)}
                      for s, g in fixed.items()}}
    # A run from a start no training demonstration has gets no fixed trajectory (none so far).
    for kind in ("mean", "warped mean", "warped mean, shortest", "medoid"):
        v, _ = score(lambda d, kind=kind: [fixed[start[d]][kind]] if start[d] in fixed else [])
        row[KEYS[kind]] = float(np.median(v))
    if not replays:
        return row
    v, shape = score(lambda d: [demos[e][1] for e in fixed[start[d]]["group"]] if start[d] in fixed else [])
    shape = np.array(shape)
    row["replay_m"] = float(np.median([np.median(v[shape == d]) for d in heldout if (shape == d).any()]))
    # Best replay: per start, the training demonstration with the least median over that start's
    # runs (v holds each run's candidates in group order); the median over every run.
    best_runs = []
    for s in fixed:
        runs = [d for d in heldout if start[d] == s]
        if runs:
            per = np.array([v[shape == d] for d in runs])  # (runs, group)
            best_runs += list(per[:, int(np.argmin(np.median(per, axis=0)))])
    row["best_replay_m"] = float(np.median(best_runs))
    return row


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("eval_dir", nargs="?", default="out/eval",
                    help="an nao_toolchain evaluate output: its detail.json names the held-out demonstrations "
                         "and the policy's runs (default out/eval)")
    ap.add_argument("data_dir", nargs="?", default="out/train/data",
                    help="the data set of toolchain/nao train data (default out/train/data)")
    ap.add_argument("--json", help="write the numbers here too")
    ap.add_argument("--splits", type=int, default=0,
                    help="also draw this many random held-out sets of the evaluation's size per movement "
                         "(no replay columns) and report how often each trajectory meets the bar")
    ap.add_argument("--seed", type=int, default=1, help="seed of the random held-out sets (default 1)")
    a = ap.parse_args(argv[1:])
    try:
        with open(os.path.join(a.eval_dir, "detail.json"), encoding="utf-8") as fh:
            detail = json.load(fh)
        arm = load_arm_model()
        demos = {}
        for path in sorted(glob.glob(os.path.join(a.data_dir, "*_[0-9][0-9][0-9]", "features.csv"))):
            demos[os.path.basename(os.path.dirname(path))] = read_features(path)
        heldouts = {m: [r["start"] for r in detail[m]["runs"]] for m in MOVEMENTS}
    except (OSError, ValueError, KeyError, AnalysisError) as e:
        print("autonomous_ceiling: %s" % e, file=sys.stderr)
        return 1
    for m, h in heldouts.items():
        missing = [d for d in h if d not in demos]
        if missing:
            print("autonomous_ceiling: %s not in %s" % (", ".join(missing), a.data_dir), file=sys.stderr)
            return 1
    report = {"evaluation": {}, "random_splits": {}}
    print("The evaluation's held-out set (mm):\n")
    print("| movement | demonstrations' NN (the bar) | mean | warped mean | warped mean, shortest | medoid | "
          "replay (median) | best replay | policy |")
    print("|---|---|---|---|---|---|---|---|---|")
    for m in MOVEMENTS:
        row = movement_ceiling(arm, demos, m, heldouts[m])
        row["policy_m"] = float(np.median([r["dtw_nearest_m"] for r in detail[m]["runs"]]))
        report["evaluation"][m] = row
        print("| %s | %s |" % (m, " | ".join("%.1f" % (1e3 * row[k]) for k in (
            "demo_nn_m", "mean_m", "warped_mean_m", "warped_mean_shortest_m", "medoid_m", "replay_m", "best_replay_m",
            "policy_m"))), flush=True)
    if a.splits > 0:
        rng = np.random.default_rng(a.seed)
        print("\n%d random held-out sets per movement (seed %d): median over the sets (mm), and in how many "
              "sets the trajectory's median is at most the demonstrations' NN:\n" % (a.splits, a.seed))
        print("| movement | demonstrations' NN | mean | warped mean | warped mean, shortest | medoid |")
        print("|---|---|---|---|---|---|")
        for m in MOVEMENTS:
            names = sorted(d for d in demos if d.startswith(m + "_"))
            rows = []
            for k in range(a.splits):
                h = sorted(rng.choice(names, size=len(heldouts[m]), replace=False).tolist())
                rows.append(movement_ceiling(arm, demos, m, h, replays=False))
                print("  %s set %d/%d" % (m, k + 1, a.splits), file=sys.stderr, flush=True)
            report["random_splits"][m] = rows
            cells = ["%.1f" % (1e3 * np.median([r["demo_nn_m"] for r in rows]))]
            for key in ("mean_m", "warped_mean_m", "warped_mean_shortest_m", "medoid_m"):
                met = sum(1 for r in rows if r[key] <= r["demo_nn_m"])
                cells.append("%.1f (%d of %d)" % (1e3 * np.median([r[key] for r in rows]), met, len(rows)))
            print("| %s | %s |" % (m, " | ".join(cells)), flush=True)
    if a.json:
        with open(a.json, "w", encoding="utf-8") as fh:
            json.dump(report, fh, indent=2, sort_keys=True)
            fh.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
