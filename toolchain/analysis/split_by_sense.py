#!/usr/bin/python3
"""A prepared data set with every movement split in two by its rotation sense (docs/autonomous.md).

The sense is read from the joints alone, so it works on any recording: per movement, the
principal plane of all demonstrations' middle stretches (20-80 % of each retarget.csv's qr_0..qr_4,
each centred on its own mean), and the sign of the area each demonstration's stretch sweeps in
that plane (shoelace). Demonstration <movement>_<index> of SRC becomes <movement>p_<index> or
<movement>n_<index> of DST, with its retarget.csv, skeleton.csv, calibration.json and meta.json
(and the .done marker), ready for `nao_toolchain cluster --data DST` and training. Where
meta.json carries a synthesiser's motion.direction, the script prints how often the two senses
agree (up to the plane's arbitrary orientation).

usage: toolchain/analysis/split_by_sense.py SRC DST
"""
import csv
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from nao_analysis.dataset import copy_demonstration  # noqa: E402


def middle_stretch(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    q = np.array([[float(r["qr_%d" % j]) for j in range(5)] for r in rows])
    mid = q[int(0.2 * len(q)):int(0.8 * len(q))]
    return mid - mid.mean(axis=0)


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__.strip().splitlines()[-1])
    src, dst = sys.argv[1], sys.argv[2]
    demos = {}
    for name in sorted(os.listdir(src)):
        path = os.path.join(src, name, "retarget.csv")
        if "_" not in name or not os.path.isfile(path):
            continue
        demos.setdefault(name.rsplit("_", 1)[0], []).append((name, middle_stretch(path)))
    if not demos:
        sys.exit("split_by_sense.py: no <movement>_<index>/retarget.csv in %s" % src)
    os.makedirs(dst, exist_ok=True)
    for movement, items in demos.items():
        _, _, vt = np.linalg.svd(np.vstack([m for _, m in items]), full_matrices=False)
        agree = known = 0
        counts = {"p": 0, "n": 0}
        for name, m in items:
            p = m @ vt[:2].T
            area = 0.5 * np.sum(p[:-1, 0] * p[1:, 1] - p[1:, 0] * p[:-1, 1])
            sense = "p" if area > 0 else "n"
            counts[sense] += 1
            out = os.path.join(dst, "%s%s_%s" % (movement, sense, name.rsplit("_", 1)[1]))
            copy_demonstration(os.path.join(src, name), out)
            meta = os.path.join(src, name, "meta.json")
            if os.path.isfile(meta):
                direction = json.load(open(meta)).get("motion", {}).get("direction")
                if direction is not None:
                    known += 1
                    agree += (area > 0) == (direction > 0)
        line = "%s: %d demonstrations, %d p, %d n" % (movement, len(items), counts["p"], counts["n"])
        if known:
            line += "; the synthesiser's sense agrees on %d/%d" % (max(agree, known - agree), known)
        print(line)


if __name__ == "__main__":
    main()
