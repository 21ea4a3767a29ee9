#!/usr/bin/python3
"""A prepared data set in which each demonstration is a movement of its own (docs/policy.md,
"Autonomous mode: what was tried"): can the policy make one demonstration's movement in closed
loop when nothing about it is ambiguous?

The first N demonstrations (sorted by name) of each movement of SRC become the movements
<movement><index> of DST, each with COPIES identical copies <movement><index>_000 .. (retarget.csv,
skeleton.csv, calibration.json, meta.json and the .done marker). Trained with a --val-fraction
that leaves copies on both sides (10 copies, 0.2: 8 training, 2 validation), every demonstration
is its own validation demonstration: the movement and
step embeddings then name one trajectory, the selection rollouts start at that trajectory's
start and are scored against it. Then `nao_toolchain cluster --data DST` and the autonomous recipe
(docs/analysis.md) with `--data DST`.

usage: toolchain/analysis/demo_as_movement.py SRC DST N COPIES
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from nao_analysis.dataset import copy_demonstration  # noqa: E402


def main():
    if len(sys.argv) != 5:
        sys.exit(__doc__.strip().splitlines()[-1])
    src, dst = sys.argv[1], sys.argv[2]
    per, copies = int(sys.argv[3]), int(sys.argv[4])
    if per < 1 or copies < 2:
        sys.exit("demo_as_movement.py: N must be >= 1 and COPIES >= 2 (one copy is the validation split)")
    movements = {}
    for name in sorted(os.listdir(src)):
        if "_" in name and os.path.isfile(os.path.join(src, name, "retarget.csv")):
            movements.setdefault(name.rsplit("_", 1)[0], []).append(name)
    if not movements:
        sys.exit("demo_as_movement.py: no <movement>_<index>/retarget.csv in %s" % src)
    os.makedirs(dst, exist_ok=True)
    for movement, names in movements.items():
        for name in names[:per]:
            for c in range(copies):
                out = os.path.join(dst, "%s%s_%03d" % (movement.replace("_", ""), name.rsplit("_", 1)[1], c))
                copy_demonstration(os.path.join(src, name), out)
        print("%s: %d of %d demonstrations, %d copies each" % (movement, min(per, len(names)), len(names), copies))


if __name__ == "__main__":
    main()
