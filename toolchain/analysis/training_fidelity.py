#!/usr/bin/python3
"""Does an autonomous model play its code where it was trained? Code fidelity from the training
demonstrations' own starts, beside evaluate's from the held-out starts.

`nao_toolchain evaluate` scores runs from held-out starts; their code fidelity is the hand-path
DTW from each run to the demonstration its run code names (the medoid of the 5 training
demonstrations nearest its start). This script makes the same runs from training starts:
nao_rt from each training demonstration's first executed pose (retarget.csv qx, as evaluate
starts a held-out run of a synthetic data set), for that demonstration's length, and the DTW
from the run's hand path to the forward kinematics of the named demonstration's features.csv
(run_code in the run's summary.json). With `--starts heldout` it remakes evaluate's own runs instead (detail.json's
start_q and ticks): a cross-check of this script against detail.json's code_fidelity_m.

If the runs from training starts are as far from their code as the held-out ones, the model
lacks fit, not generalisation to new starts.

usage: toolchain/analysis/training_fidelity.py --detail EVAL/detail.json --model FILE
           --nao-rt PATH [--data DIR] [--starts training|heldout] [--per-movement N]
           [--jobs N] [--out JSON]
"""

import argparse
import concurrent.futures
import csv
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from nao_analysis.kinematics import DEFAULT_URDF, hand_position, load_arm_model  # noqa: E402
from nao_analysis.rundir import read_summary, read_ticks  # noqa: E402
from nao_analysis.units import dtw_mean_distances  # noqa: E402
from autonomous_ceiling import read_features  # noqa: E402


def columns(path, names):
    """The named columns of a CSV file as an array (rows, len(names))."""
    with open(path) as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise SystemExit("training_fidelity: %s has no rows" % path)
    missing = [c for c in names if c not in rows[0]]
    if missing:
        raise SystemExit("training_fidelity: %s has no column %s" % (path, ", ".join(missing)))
    return np.array([[float(r[c]) for c in names] for r in rows])


def features(data, demo):
    return read_features(os.path.join(data, demo, "features.csv"))[1]


def training_start(args, demo):
    """A training demonstration's start and length: its first executed pose (retarget.csv qx),
    as evaluate starts a held-out demonstration of a synthetic data set, and its f's length."""
    start = columns(os.path.join(args.data, demo, "retarget.csv"), ["qx_%d" % j for j in range(5)])[0]
    return demo, start, len(features(args.data, demo))


def run(args, arm, movement, start_of, out_dir):
    """nao_rt's autonomous run from a (name, start pose, ticks); returns (run code, hand path):
    the start pose's hand (at rest, clamped to the limits), then every tick's, as evaluate reads a run."""
    demo, start, ticks = start_of
    log = os.path.join(out_dir, movement, demo)
    cmd = [args.nao_rt, "--weights", args.model, "--urdf", args.urdf, "--reference", "none", "--movement",
           movement, "--start-pose", ",".join("%.17g" % x for x in start), "--ticks", str(ticks),
           "--zero-timing", "--log", log]
    done = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if done.returncode != 0:
        raise SystemExit("training_fidelity: nao_rt failed for %s (exit %d):\n%s" % (demo, done.returncode, done.stdout))
    code = read_summary(os.path.join(log, "summary.json")).get("run_code")
    if not code:
        raise SystemExit("training_fidelity: %s has no run codes (an autonomous run-code model is needed)" % args.model)
    ticks_csv = read_ticks(os.path.join(log, "ticks.csv"))
    at_rest = hand_position(arm, np.clip(start, arm.q_min, arm.q_max)[None, :])
    return code, np.vstack([at_rest, np.column_stack([ticks_csv[c] for c in ("ee_x", "ee_y", "ee_z")])])


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--detail", required=True, help="evaluate's detail.json for this model (its split)")
    p.add_argument("--model", required=True, help="the autonomous model.bin evaluate scored")
    p.add_argument("--nao-rt", required=True, help="nao_rt for the model's architecture")
    p.add_argument("--data", default="out/train/data", help="the model's data set")
    p.add_argument("--urdf", default=DEFAULT_URDF)
    p.add_argument("--starts", choices=("training", "heldout"), default="training")
    p.add_argument("--per-movement", type=int, default=16, help="starts per movement (0: all)")
    p.add_argument("--jobs", type=int, default=2, help="nao_rt processes at a time")
    p.add_argument("--out", help="also write the per-run figures here (JSON)")
    args = p.parse_args()
    with open(args.detail) as f:
        detail = json.load(f)
    arm = load_arm_model(args.urdf)
    result = {}
    with tempfile.TemporaryDirectory() as tmp, concurrent.futures.ThreadPoolExecutor(args.jobs) as pool:
        for movement, d in sorted(detail.items()):
            heldout = [r["code_fidelity_m"] for r in d["runs"] if r.get("code_fidelity_m") is not None]
            if args.starts == "training":
                starts = [training_start(args, demo) for demo in d["training_demos"]]
            else:  # evaluate's own runs: its start pose and length
                starts = [(r["start"], np.array(r["start_q"]), r["ticks"]) for r in d["runs"]]
            if args.per_movement > 0:
                starts = starts[: args.per_movement]
            demos = [name for name, _, _ in starts]
            runs = list(pool.map(lambda start_of: run(args, arm, movement, start_of, tmp), starts))
            named = [hand_position(arm, features(args.data, code)) for code, _ in runs]
            fid = dtw_mean_distances([(hand, path) for (_, hand), path in zip(runs, named)])
            result[movement] = {
                "starts": args.starts,
                "runs": [{"start": s, "named_demo": c, "code_fidelity_m": float(x)} for s, (c, _), x in zip(demos, runs, fid)],
                "code_fidelity_m": float(np.median(fid)),
                "named_self": sum(s == c for s, (c, _) in zip(demos, runs)),
                "heldout_code_fidelity_m": float(np.median(heldout)) if heldout else None,
            }
            r = result[movement]
            print("%-10s %2d runs from %s starts: code fidelity median %.1f mm (own demonstration named %d times); "
                  "evaluate's held-out runs %.1f mm" % (movement, len(demos), args.starts, 1e3 * r["code_fidelity_m"],
                                                        r["named_self"], 1e3 * (r["heldout_code_fidelity_m"] or float("nan"))),
                  flush=True)
    if args.out:
        with open(args.out, "w") as f:
            json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
