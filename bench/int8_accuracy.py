#!/usr/bin/env python3
"""Closed-loop cost of int8 weights (docs/policy.md "int8 weights"): nao_rt with --precision fp32
and --precision int8 on the same recorded references, per movement and seed: demonstration 0 of
run seed 1000000 + S (held out, as toolchain/nao demo makes them), synthesised and triangulated
into a 10 Hz skeleton CSV by nao_toolchain (--tc), run with --reference file:PATH.

For every run pair it reads summary.json (hand RMSE against the reference's feature-extracted
target, mm) and ticks.csv (actions a_j, rad per step; hand path ee_*), and prints:
  rmse fp32 / int8 and their difference (the issue's check: int8 within +0.5 mm of fp32),
  max |a_int8 - a_fp32| over the run (closed loop: the states drift apart, so this also holds
  the difference the int8 error makes to where the arm is), and the max hand distance between
  the two runs.
The open-loop action difference (same inputs) is a counter of BM_Policy_Int8 (nao_bench).

usage: bench/int8_accuracy.py [--rt build/bin/nao_rt] [--tc build/bin/nao_toolchain] [--seeds 1 2 3]
                              [--weights FILE] [--out DIR]
"""
import argparse
import csv
import json
import math
import os
import subprocess
import sys
import tempfile

MOVEMENTS = ["whole_arm", "elbow", "wrist"]


def check_call(cmd):
    p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if p.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed ({p.returncode}):\n{p.stdout}")


def reference(tc, movement, seed, out_dir):
    """The skeleton CSV of demonstration 0 of run seed 1000000 + seed (made once)."""
    demos = os.path.join(out_dir, f"references_{seed}")
    skeleton = os.path.join(demos, f"{movement}_000", "skeleton.csv")
    if not os.path.exists(skeleton):
        check_call([tc, "synth", "--movement", movement, "--per-movement", "1", "--seed", str(1000000 + seed),
                    "--out", demos])
        check_call([tc, "triangulate", "--demo", os.path.join(demos, f"{movement}_000"), "--max-gap", "0",
                    "--out", skeleton])
    return skeleton


def run(rt, skeleton, movement, seed, precision, weights, out_dir):
    log = os.path.join(out_dir, f"{movement}_{seed}_{precision}")
    cmd = [rt, "--reference", f"file:{skeleton}", "--movement", movement, "--precision", precision,
           "--zero-timing", "--log", log]
    if weights:
        cmd += ["--weights", weights]
    p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if p.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed ({p.returncode}):\n{p.stdout}")
    with open(os.path.join(log, "summary.json")) as f:
        summary = json.load(f)
    with open(os.path.join(log, "ticks.csv")) as f:
        rows = list(csv.DictReader(f))
    return summary, rows


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rt", default="build/bin/nao_rt")
    ap.add_argument("--tc", default="build/bin/nao_toolchain", help="nao_toolchain (synth, triangulate)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--weights", default="", help="model.bin (default: the compiled-in model)")
    ap.add_argument("--out", default="", help="keep the run directories here (default: a temporary one)")
    a = ap.parse_args()
    out_dir = a.out or tempfile.mkdtemp(prefix="nao_int8_")
    print(f"# nao_rt --reference file:SKELETON(M, 1000000 + S) --movement M --precision fp32|int8 --zero-timing"
          f"{' --weights ' + a.weights if a.weights else ''}")
    print(f"{'movement':10} {'seed':>4} {'rmse fp32 mm':>12} {'rmse int8 mm':>12} {'diff mm':>8} "
          f"{'max |da| mrad':>13} {'max |dee| mm':>12}")
    worst = {}
    for m in MOVEMENTS:
        for s in a.seeds:
            skeleton = reference(a.tc, m, s, out_dir)
            s32, r32 = run(a.rt, skeleton, m, s, "fp32", a.weights, out_dir)
            s8, r8 = run(a.rt, skeleton, m, s, "int8", a.weights, out_dir)
            if s32["model"]["precision"] != "fp32" or s8["model"]["precision"] != "int8":
                sys.exit("nao_rt did not run the precision it was asked for")
            da = max(abs(float(x[f"a_{j}"]) - float(y[f"a_{j}"])) for x, y in zip(r8, r32) for j in range(5))
            dee = max(math.dist([float(x[k]) for k in ("ee_x", "ee_y", "ee_z")],
                                [float(y[k]) for k in ("ee_x", "ee_y", "ee_z")]) for x, y in zip(r8, r32))
            e32, e8 = 1e3 * s32["ee_rmse_m"], 1e3 * s8["ee_rmse_m"]
            worst[m] = max(worst.get(m, -math.inf), e8 - e32)
            print(f"{m:10} {s:>4} {e32:12.3f} {e8:12.3f} {e8 - e32:+8.3f} {1e3 * da:13.3f} {1e3 * dee:12.3f}")
    print("# worst int8 - fp32 hand RMSE per movement (target <= +0.5 mm): " +
          ", ".join(f"{m} {worst[m]:+.3f} mm" for m in MOVEMENTS))
    return 0 if all(v <= 0.5 for v in worst.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
