#!/usr/bin/python3
"""How much of what the policy is trained on is the movement and how much is the noisy rollouts'
way back: per movement and joint, the spread of the expert's labels in the clean and in the noisy
rollouts of an execution cache.

`nao_toolchain train --execution-cache DIR` keeps the executed training sequences in
DIR/<key>.train (docs/training.md "The execution cache"). Each sequence is one rollout of a
training demonstration: rollout 0 the clean one, which follows the demonstration; rollouts 1, 2,
... the noisy ones (--noisy-rollouts, --noise-std), whose labels also carry the way back from the
noise. Per joint: the standard deviation of the labels a(t) (rad per tick) over the movement's
clean ticks and over its noisy ticks, each divided by that joint's standard deviation over every
label of the file (the scale the trainer normalises the labels by). A clean ratio well under the
noisy one says that in this movement the joint's labels are mostly corrections, not motion.

usage: toolchain/analysis/label_spread.py CACHE.train [--names elbow,whole_arm,wrist] [--json OUT]
"""
import argparse
import json
import sys

import numpy as np

JOINTS = ("RShoulderPitch", "RShoulderRoll", "RElbowYaw", "RElbowRoll", "RWristYaw")
HEAD = 8  # demo, movement, rollout, then the lengths of q, a(t-1), r and a, then the expert's worst miss


class CacheError(Exception):
    pass


def read_cache(path):
    """The sequences of an execution cache: dicts of movement, rollout and a (n, 5)."""
    b = np.fromfile(path, dtype="<f8")
    if b.size == 0:
        raise CacheError("%s: empty" % path)
    count, i, seqs = int(b[0]), 1, []
    for _ in range(count):
        if i + HEAD > b.size:
            raise CacheError("%s: truncated" % path)
        head = b[i:i + HEAD]
        i += HEAD
        lengths = [int(x) for x in head[3:7]]
        arrays = []
        for n in lengths:
            if i + 5 * n > b.size:
                raise CacheError("%s: truncated" % path)
            arrays.append(b[i:i + 5 * n].reshape(n, 5))
            i += 5 * n
        seqs.append({"movement": int(head[1]), "rollout": int(head[2]), "a": arrays[3]})
    if i != b.size:
        raise CacheError("%s: trailing data after %d sequences" % (path, count))
    if not seqs:
        raise CacheError("%s: no sequences" % path)
    return seqs


def label_spread(seqs):
    """{movement index: {clean_ratio, noisy_ratio, clean_ticks, noisy_ticks}} and the per-joint
    standard deviation of all labels (rad per tick)."""
    scale = np.concatenate([s["a"] for s in seqs]).std(axis=0)
    out = {}
    for m in sorted({s["movement"] for s in seqs}):
        entry = {}
        for kind, noisy in (("clean", False), ("noisy", True)):
            parts = [s["a"] for s in seqs if s["movement"] == m and (s["rollout"] > 0) == noisy]
            a = np.concatenate(parts) if parts else np.zeros((0, 5))
            with np.errstate(divide="ignore", invalid="ignore"):
                entry[kind + "_ratio"] = (a.std(axis=0) / scale).tolist() if len(a) else [float("nan")] * 5
            entry[kind + "_ticks"] = int(len(a))
        out[m] = entry
    return out, scale


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("cache", help="an execution cache's .train file (nao_toolchain train --execution-cache DIR)")
    ap.add_argument("--names", help="movement names in index order, comma-separated (the model card lists them)")
    ap.add_argument("--json", help="write the numbers here too")
    a = ap.parse_args(argv[1:])
    try:
        report, scale = label_spread(read_cache(a.cache))
    except (OSError, CacheError) as e:
        print("label_spread: %s" % e, file=sys.stderr)
        return 1
    names = a.names.split(",") if a.names else []

    def name(m):
        return names[m] if m < len(names) else str(m)

    print("Label spread per joint (%s), as a share of each joint's spread over all labels (%s rad per tick):\n"
          % (", ".join(JOINTS), " / ".join("%.4f" % s for s in scale)))
    print("| movement | clean rollouts | noisy rollouts | ticks clean / noisy |")
    print("|---|---|---|---|")
    for m, r in report.items():
        print("| %s | %s | %s | %d / %d |" % (name(m), " / ".join("%.2f" % v for v in r["clean_ratio"]),
                                             " / ".join("%.2f" % v for v in r["noisy_ratio"]),
                                             r["clean_ticks"], r["noisy_ticks"]))
    if a.json:
        with open(a.json, "w", encoding="utf-8") as fh:
            json.dump({"scale_rad_per_tick": scale.tolist(),
                       "movements": {name(m): r for m, r in report.items()}}, fh, indent=2, sort_keys=True)
            fh.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
