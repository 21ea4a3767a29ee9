#!/usr/bin/python3
"""A prepared data set in which each demonstration is a movement of its own (docs/autonomous.md):
can the policy make one demonstration's movement in closed loop when nothing about it is
ambiguous?

The first N demonstrations (sorted by name) of each movement of SRC become the movements
<movement><index> of DST, each with COPIES identical copies <movement><index>_000 .. (retarget.csv,
skeleton.csv, calibration.json, meta.json and the .done marker). Trained with a --val-fraction
that leaves copies on both sides (10 copies, 0.2: 8 training, 2 validation), every demonstration
is its own validation demonstration: the movement and
step embeddings then name one trajectory, the selection rollouts start at that trajectory's
start and are scored against it. Then `nao_toolchain cluster --data DST` and the autonomous recipe
(docs/analysis.md) with `--data DST`.

With --pair-nearest-start, movement <movement><index> holds instead the demonstration and the
other demonstration of its movement whose start (first row's qr, rad) is nearest, one copy each
(COPIES is ignored; each partner is used once, drawn from the demonstrations after the first N):
the split puts one in training and one in validation, so the selection run starts at a
demonstration the net never saw, conditioned on its neighbour's movement code. That is the
question a code per demonstration raises for a new start.

usage: toolchain/analysis/demo_as_movement.py SRC DST N COPIES [--pair-nearest-start]
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from nao_analysis.dataset import copy_demonstration  # noqa: E402


def start_of(demo_dir):
    """The retargeted first pose: qr_0..qr_4 of retarget.csv's first row."""
    with open(os.path.join(demo_dir, "retarget.csv")) as f:
        header = f.readline().strip().split(",")
        row = f.readline().strip().split(",")
    return [float(row[header.index("qr_%d" % j)]) for j in range(5)]


def main():
    args = [a for a in sys.argv[1:] if a != "--pair-nearest-start"]
    pair = len(args) != len(sys.argv) - 1
    if len(args) != 4:
        sys.exit(__doc__.strip().splitlines()[-1])
    src, dst = args[0], args[1]
    per, copies = int(args[2]), int(args[3])
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
        pool = names[per:]
        for name in names[:per]:
            label = movement.replace("_", "") + name.rsplit("_", 1)[1]
            members = [name] * copies
            if pair:
                if not pool:
                    sys.exit("demo_as_movement.py: %s has too few demonstrations to pair %d" % (movement, per))
                s0 = start_of(os.path.join(src, name))
                near = min(pool, key=lambda o: sum((a - b) ** 2 for a, b in zip(s0, start_of(os.path.join(src, o)))))
                pool.remove(near)
                members = [name, near]
                print("%s: %s + %s" % (label, name, near))
            for c, member in enumerate(members):
                copy_demonstration(os.path.join(src, member), os.path.join(dst, "%s_%03d" % (label, c)))
        print("%s: %d of %d demonstrations, %s" % (movement, min(per, len(names)), len(names),
                                                   "each with its nearest-start partner" if pair else
                                                   "%d copies each" % copies))


if __name__ == "__main__":
    main()
