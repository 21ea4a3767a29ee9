#!/usr/bin/python3
"""Where the feature trajectory is unpredictable: at the key-pose switches.

The feature trajectory f is the key-pose blend (docs/policy.md):
    f(t+1) - f(t) = 0.49 (f(t) - f(t-1)) + 0.09 (c(t) - f(t)),   c(t) = centroid label(t).
Its next step is therefore exact given the history and the current key pose. This predicts every
step from the *previous* key pose c(t-1) (what the history shows) and prints, per movement of a
data set (DATA/centroids.json, DATA/<movement>_<index>/features.csv of `nao_toolchain cluster`):
how often the key pose switches, the largest error where it does not (rounding only), and that
predictor's squared error over the steps' squared size, beside repeat-the-last-step's
(docs/evaluate.md "The rollouts are the demonstrations' mean").

usage: toolchain/analysis/keypose_switches.py [DATA_DIR (out/train/data)]
"""
import csv
import glob
import json
import os
import sys

import numpy as np

POLE = 0.7  # kFeatureBlendPole: pole^2 = 0.49, (1 - pole)^2 = 0.09


def main(argv):
    data = argv[1] if len(argv) > 1 else "out/train/data"
    try:
        with open(os.path.join(data, "centroids.json"), encoding="utf-8") as f:
            centroids = json.load(f)["movements"]
    except (OSError, ValueError, KeyError) as e:
        print(f"keypose_switches: {e}", file=sys.stderr)
        return 1
    print("| movement | demos | ticks with a key-pose switch | ticks between switches | largest error off a switch (rad) | "
          "error / signal, previous key pose | error / signal, repeat last step |")
    print("|---|---|---|---|---|---|---|")
    for movement in sorted(centroids):
        c = np.array(centroids[movement]["centroids"])
        paths = sorted(glob.glob(os.path.join(data, f"{movement}_*", "features.csv")))
        switch = still = 0
        worst = err = signal = repeat = 0.0
        for p in paths:
            with open(p, newline="", encoding="utf-8") as f:
                rows = list(csv.DictReader(f))
            fx = np.array([[float(r[f"f_{j}"]) for j in range(5)] for r in rows])
            label = np.array([int(r["label"]) for r in rows])
            d = np.diff(fx, axis=0)  # d[t] = f(t+1) - f(t)
            for t in range(1, len(d)):
                pred = POLE**2 * d[t - 1] + (1 - POLE) ** 2 * (c[label[t - 1]] - fx[t])
                e = d[t] - pred
                err += float(e @ e)
                signal += float(d[t] @ d[t])
                repeat += float((d[t] - d[t - 1]) @ (d[t] - d[t - 1]))
                if label[t] != label[t - 1]:
                    switch += 1
                else:
                    still += 1
                    worst = max(worst, float(np.abs(e).max()))
        n = switch + still
        if n == 0:
            continue
        print(f"| {movement} | {len(paths)} | {100 * switch / n:.1f} % | {n / max(switch, 1):.1f} | {worst:.1e} | "
              f"{err / signal:.3f} | {repeat / signal:.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
