#!/usr/bin/python3
"""How faithfully an autonomous model's runs play the demonstration their run code names.

An autonomous model with run codes (`nao_toolchain train --run-latent K`) plays, from a start,
the variant of one training demonstration: the controller picks the medoid of the 5 training
starts nearest the run's, the demonstration the medoid replay tracks (docs/evaluate.md), and
each run's summary.json names it (`run_code`). Per movement of an `nao_toolchain evaluate`
output, over its runs (medians):

- named: hand-path DTW from the run to the demonstration its code names (that demonstration's
  feature trajectory DATA/<name>/features.csv, f_0..f_4, through the arm's forward kinematics);
- held-out: hand-path DTW from the run to its nearest held-out demonstration
  (<movement>/demos/<name>.csv), what evaluate's autonomous DTW measures;
- replay: evaluate's medoid replay DTW (detail.json), when the directory has it.

A run that played its named demonstration faithfully would be near 0 on the first and near the
replay on the second. The run's hand path is ticks.csv's ee_x/y/z (the runtime's forward
kinematics); the demonstrations' come from toolchain/analysis/nao_analysis/kinematics.py on the
same URDF. DTW is rt::dtwMeanDistance's (mean distance per matched pair).

usage: toolchain/analysis/code_fidelity.py [EVAL_DIR (out/eval)] [DATA_DIR (out/train/data)]
                                          [--urdf FILE] [--json OUT]
"""
import argparse
import csv
import glob
import json
import os
import sys

import numpy as np

from nao_analysis.kinematics import DEFAULT_URDF, hand_position, load_arm_model
from nao_analysis.units import dtw_mean_distances


class FidelityError(Exception):
    pass


def _rows(path):
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def read_columns(path, names):
    """(n, len(names)) floats of a CSV's columns; FidelityError naming the file otherwise."""
    rows = _rows(path)
    try:
        out = np.array([[float(r[c]) for c in names] for r in rows], dtype=float)
    except (KeyError, TypeError, ValueError) as e:
        raise FidelityError("%s: no usable %s columns (%s)" % (path, ",".join(names), e))
    if len(out) == 0:
        raise FidelityError("%s: no rows" % path)
    return out


def movement_fidelity(eval_dir, movement, data_dir, arm):
    """{'runs', 'named_dtw_m', 'heldout_dtw_m', 'replay_dtw_m' (or None), 'per_run'} of one movement."""
    mdir = os.path.join(eval_dir, movement)
    demos = {os.path.splitext(os.path.basename(p))[0]: hand_position(arm, read_columns(p, ["q_%d" % j for j in range(5)]))
             for p in sorted(glob.glob(os.path.join(mdir, "demos", "*.csv")))}
    if not demos:
        raise FidelityError("%s: no held-out demonstrations in demos/" % mdir)
    replay = {}
    detail = os.path.join(eval_dir, "detail.json")
    if os.path.exists(detail):
        with open(detail, encoding="utf-8") as fh:
            d = json.load(fh)
        for r in d.get(movement, {}).get("runs", []):
            if "run_dir" in r and "medoid_replay_dtw_m" in r:
                replay[os.path.basename(r["run_dir"])] = r["medoid_replay_dtw_m"]
    named_paths = {}
    runs = []  # (run, code, hand path)
    for rdir in sorted(glob.glob(os.path.join(mdir, "autonomous", "*", ""))):
        run = os.path.basename(os.path.dirname(rdir))
        with open(os.path.join(rdir, "summary.json"), encoding="utf-8") as fh:
            code = json.load(fh).get("run_code")
        if not isinstance(code, str) or not code:
            raise FidelityError("%s: summary.json names no run_code (a model without run codes?)" % rdir)
        if code not in named_paths:
            f = os.path.join(data_dir, code, "features.csv")
            if not os.path.exists(f):
                raise FidelityError("%s: run code %s, but %s does not exist (the model's training data?)" % (rdir, code, f))
            named_paths[code] = hand_position(arm, read_columns(f, ["f_%d" % j for j in range(5)]))
        runs.append((run, code, read_columns(os.path.join(rdir, "ticks.csv"), ["ee_x", "ee_y", "ee_z"])))
    # Every DTW of the movement in one batch: per run, its named demonstration, then each held-out one.
    held = list(demos.values())
    pairs = [pair for _, code, hand in runs for pair in [(hand, named_paths[code])] + [(hand, p) for p in held]]
    dist = dtw_mean_distances(pairs).reshape(len(runs), 1 + len(held)) if runs else np.empty((0, 1))
    per_run = [{"run": run, "run_code": code, "named_dtw_m": float(dist[i, 0]), "heldout_dtw_m": float(dist[i, 1:].min()),
                "replay_dtw_m": replay.get(run)} for i, (run, code, _) in enumerate(runs)]
    if not per_run:
        raise FidelityError("%s: no runs in autonomous/" % mdir)
    replays = [r["replay_dtw_m"] for r in per_run if r["replay_dtw_m"] is not None]
    return {"runs": len(per_run),
            "named_dtw_m": float(np.median([r["named_dtw_m"] for r in per_run])),
            "heldout_dtw_m": float(np.median([r["heldout_dtw_m"] for r in per_run])),
            "replay_dtw_m": float(np.median(replays)) if len(replays) == len(per_run) else None,
            "per_run": per_run}


def eval_fidelity(eval_dir, data_dir, urdf=DEFAULT_URDF):
    arm = load_arm_model(urdf)
    movements = sorted(os.path.basename(os.path.dirname(m)) for m in glob.glob(os.path.join(eval_dir, "*", "autonomous")))
    if not movements:
        raise FidelityError("%s: no <movement>/autonomous/ directories (an nao_toolchain evaluate output?)" % eval_dir)
    return {m: movement_fidelity(eval_dir, m, data_dir, arm) for m in movements}


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("eval_dir", nargs="?", default="out/eval", help="an nao_toolchain evaluate output (default out/eval)")
    ap.add_argument("data_dir", nargs="?", default="out/train/data",
                    help="the model's training data set, whose DATA/<name>/features.csv the codes name (default out/train/data)")
    ap.add_argument("--urdf", default=DEFAULT_URDF, help="robot description for the demonstrations' hand paths")
    ap.add_argument("--json", help="write the numbers here too")
    a = ap.parse_args(argv[1:])
    try:
        report = eval_fidelity(a.eval_dir, a.data_dir, a.urdf)
    except (OSError, ValueError, FidelityError) as e:
        print("code_fidelity: %s" % e, file=sys.stderr)
        return 1
    print("Hand-path DTW of the runs (%s), medians over runs, mm:\n" % a.eval_dir)
    print("| movement | runs | to the demonstration its code names | to the nearest held-out demonstration | medoid replay |")
    print("|---|---|---|---|---|")
    for m, r in report.items():
        rep = "%.1f" % (1e3 * r["replay_dtw_m"]) if r["replay_dtw_m"] is not None else "-"
        print("| %s | %d | %.1f | %.1f | %s |" % (m, r["runs"], 1e3 * r["named_dtw_m"], 1e3 * r["heldout_dtw_m"], rep))
    if a.json:
        with open(a.json, "w", encoding="utf-8") as fh:
            json.dump(report, fh, indent=2, sort_keys=True)
            fh.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
