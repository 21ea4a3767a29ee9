"""Figures of the embodiment gap (docs/retargeting.md) from `nao_toolchain gap --out DIR`.

usage: gap_figures.py DIR [--out FIGDIR] [--seq N]

For each DIR/gap_<movement>.csv: one figure FIGDIR/fig_gap_<movement>.png with
  (a) the hand paths in NAO's torso frame, frontal (y-z) and sagittal (x-z) views: the scaled
      human hand x_target, NAO's hand at the human's angles clamped to its limits, and at q_r;
  (b) the hand miss of both over time;
  (c) q_r - clamped human angles per joint over time: where NAO departs from the human.
"""

import argparse
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

JOINTS = ["RShoulderPitch", "RShoulderRoll", "RElbowYaw", "RElbowRoll", "RWristYaw"]
MOVEMENTS = ["whole_arm", "elbow", "wrist"]


def read_gap(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise SystemExit("gap_figures: %s has no rows" % path)

    def col(name):
        return np.array([float(r[name]) for r in rows])

    out = {"seq": col("seq").astype(int), "t": col("t_s")}
    for p in ("xt", "pc", "pr"):
        out[p] = np.stack([col(p + "_x"), col(p + "_y"), col(p + "_z")], axis=1)
    for q in ("qc", "qr"):
        out[q] = np.stack([col("%s_%d" % (q, j)) for j in range(5)], axis=1)
    return out


def figure(movement, g, seq, path):
    sel = g["seq"] == seq
    if not sel.any():
        raise SystemExit("gap_figures: no sequence %d for %s" % (seq, movement))
    t = g["t"][sel]
    xt, pc, pr = (1e3 * g[k][sel] for k in ("xt", "pc", "pr"))
    fig = plt.figure(figsize=(13, 7.5))
    fig.suptitle("Embodiment gap, %s (held-out demonstration %d): hand priority q_r vs the clamped human angles"
                 % (movement, seq))
    views = [((1, 2), "frontal plane (y-z)", "y [mm]"), ((0, 2), "sagittal plane (x-z)", "x [mm]")]
    for i, ((a, b), title, xlabel) in enumerate(views):
        ax = fig.add_subplot(2, 3, 1 + i)
        ax.plot(xt[:, a], xt[:, b], color="k", lw=2.0, label="scaled human hand x_target")
        ax.plot(pc[:, a], pc[:, b], color="tab:red", lw=1.0, label="FK(human angles clamped)")
        ax.plot(pr[:, a], pr[:, b], color="tab:blue", lw=1.0, ls="--", label="FK(q_r)")
        ax.set_title(title)
        ax.set_xlabel(xlabel)
        ax.set_ylabel("z [mm]")
        ax.set_aspect("equal", adjustable="datalim")
        if i == 0:
            ax.legend(fontsize=8, loc="best")
    ax = fig.add_subplot(2, 3, 3)
    ax.plot(t, np.linalg.norm(pc - xt, axis=1), color="tab:red", label="clamped human angles")
    ax.plot(t, np.linalg.norm(pr - xt, axis=1), color="tab:blue", label="q_r")
    ax.set_title("hand miss |FK(q) - x_target|")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("mm")
    ax.legend(fontsize=8)
    ax = fig.add_subplot(2, 1, 2)
    dq = g["qr"][sel] - g["qc"][sel]
    for j in range(5):
        ax.plot(t, dq[:, j], label=JOINTS[j])
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set_title("q_r - clamped human angles: where NAO departs from the human to keep the hand on the path")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("rad")
    ax.legend(fontsize=8, ncol=5)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv):
    p = argparse.ArgumentParser(prog="gap_figures.py", description=__doc__.splitlines()[0])
    p.add_argument("dir")
    p.add_argument("--out", default=None, help="figure directory (default: DIR)")
    p.add_argument("--seq", type=int, default=0, help="which demonstration to draw (default 0)")
    a = p.parse_args(argv)
    out = a.out or a.dir
    os.makedirs(out, exist_ok=True)
    made = 0
    for m in MOVEMENTS:
        path = os.path.join(a.dir, "gap_%s.csv" % m)
        if not os.path.exists(path):
            continue
        target = os.path.join(out, "fig_gap_%s.png" % m)
        figure(m, read_gap(path), a.seq, target)
        print("gap_figures: %s" % os.path.relpath(target))
        made += 1
    if made == 0:
        print("gap_figures: error: no gap_<movement>.csv in %s (run nao_toolchain gap --out DIR)" % a.dir,
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
