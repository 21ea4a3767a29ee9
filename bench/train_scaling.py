#!/usr/bin/env python3
"""Data-parallel training speed: world size 1 vs N on this machine (docs/training.md).

Runs `nao_toolchain train --config paper` for one epoch capped at A and at B global batches
(--max-batches), for each world size, ranks over a file store. The difference B - A cancels
start-up, data loading and the final evaluations, so per global batch:
  wall  = (wall(B) - wall(A)) / (B - A)               (rank 0, the slowest to finish)
  cpu_r = (cpu_r(B) - cpu_r(A)) / (B - A) per rank    (user + system, Gloo's threads included)
Wall time is the speed-up when the cores are free. On a loaded machine, cpu of the busiest
rank is what a batch would take with one free core per rank (a waiting rank sleeps in the
kernel, it burns no CPU), so it is printed too, with the load average before and after.

usage: bench/train_scaling.py DATA [--worlds 1 2] [--batches 10 40] [--tc build/bin/nao_toolchain]
       bench/train_scaling.py DATA --epoch [--recipe autonomous|default] [--worlds 1 2]

--epoch times what the issue's target is about instead: one whole epoch of a committed model's
recipe (toolchain/nao train autonomous or default, --epochs 1) per world size, from rank 0's
own lines: the expert's rollouts before training, the epoch (batches, validation loss and the
validation rollouts of --select rollouts, whose share is printed too) and the whole run.
"""
import argparse
import json
import os
import re
import resource
import subprocess
import sys
import tempfile
import time

OPENBLAS = "/usr/lib/x86_64-linux-gnu/openblas-serial/libopenblas.so.0"


def start_ranks(base, world, store):
    """Starts `world` ranks of the command `base` (serial OpenBLAS preloaded, as toolchain/nao
    train does), over a file store when world > 1; returns their Popen objects, rank order."""
    env = dict(os.environ)
    if os.path.exists(OPENBLAS):
        env["LD_PRELOAD"] = OPENBLAS
    procs = []
    for r in range(world):
        cmd = base + (["--world-size", str(world), "--rank", str(r), "--rendezvous", "file://" + store]
                      if world > 1 else [])
        procs.append(subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT))
    return procs


def run(tc, data, world, batches, out_dir):
    """One timing run; returns (wall of rank 0, [cpu seconds per rank])."""
    store = os.path.join(out_dir, f"store_{world}_{batches}")
    base = [tc, "train", "--config", "paper", "--data", data, "--epochs", "1", "--seed", "1",
            "--max-batches", str(batches), "--out", os.path.join(out_dir, f"m_{world}_{batches}.bin")]
    t0 = time.monotonic()
    procs = start_ranks(base, world, store)
    cpu = [0.0] * world
    wall = 0.0
    for r, p in enumerate(procs):
        # wait4 gives each child's own rusage.
        _, status, usage = os.wait4(p.pid, 0)
        if r == 0:
            wall = time.monotonic() - t0
        cpu[r] = usage.ru_utime + usage.ru_stime
        if status != 0:
            sys.exit(f"rank {r} of world size {world} failed:\n" + p.stdout.read().decode())
    return wall, cpu


# Recipes of the paper configuration, less the epoch count: models/default.bin's (toolchain/nao
# train default) and the autonomous one of the paper configuration (models/autonomous.bin is of
# the small one, trained on one rank: docs/autonomous.md).
# Each: the command-line flags, and the options only a recipe file sets (written beside the run).
RECIPES = {
    "autonomous": (["--conditioning", "autonomous", "--lr", "1e-4", "--select", "rollouts"],
                   {"noisy-rollouts": 0, "chunk": 10}),
    "default": (["--conditioning", "reference", "--lr", "3e-4"], {}),
}


def recipe_args(out_dir, recipe):
    """The flags of a recipe, plus --recipe FILE for its recipe-only options."""
    flags, only = RECIPES[recipe]
    if not only:
        return list(flags)
    path = os.path.join(out_dir, f"recipe_{recipe}.json")
    with open(path, "w") as fh:
        json.dump({"train": only}, fh)
    return list(flags) + ["--recipe", path]


def run_epoch(tc, data, world, out_dir, recipe):
    """One epoch of a recipe; returns rank 0's (execution, epoch, rollouts, total) seconds
    (rollouts: the validation rollouts of --select rollouts, 0 without them)."""
    store = os.path.join(out_dir, f"store_epoch_{world}")
    base = [tc, "train", "--config", "paper", "--data", data, "--epochs", "1", "--seed", "1",
            "--out", os.path.join(out_dir, f"e_{world}.bin")] + recipe_args(out_dir, recipe)
    procs = start_ranks(base, world, store)
    outs = [p.communicate()[0].decode() for p in procs]
    for r, p in enumerate(procs):
        if p.returncode != 0:
            sys.exit(f"rank {r} of world size {world} failed:\n" + outs[r])
    text = outs[0]
    execution = float(re.search(r"validation \(\d+ ticks\) in (\d+(?:\.\d+)?) s", text).group(1))
    m = re.search(r"epoch 1/1 .*?  (\d+\.\d+) s(?: \(rollouts (\d+\.\d+) s\))?  ", text)
    total = float(re.search(r"ticks -> .*\), (\d+\.\d+) s", text).group(1))
    line = re.search(r"epoch 1/1 [^\r\n]*", text).group(0).strip()
    return execution, float(m.group(1)), float(m.group(2) or 0.0), total, line


def main_epoch(a):
    print(f"# {time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}, {os.cpu_count()} cores")
    print(f"# command: bench/train_scaling.py {a.data} --epoch --recipe {a.recipe} --worlds {' '.join(map(str, a.worlds))}")
    flags, only = RECIPES[a.recipe]
    print(f"# each rank: nao_toolchain train --config paper --epochs 1 --seed 1 {' '.join(flags)}"
          + (f" --recipe R (R: {json.dumps({'train': only})})" if only else ""))
    print(f"# load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print("world  expert rollouts (s)  epoch (s)  of which rollouts (s)  run (s)  speed-up epoch  speed-up run")
    ref = None
    lines = []
    with tempfile.TemporaryDirectory(prefix="nao_scaling_") as d:
        for w in a.worlds:
            ex, ep, ro, tot, line = run_epoch(a.tc, a.data, w, d, a.recipe)
            if ref is None:
                ref = (ep, tot)
            print(f"{w:5d}  {ex:19.1f}  {ep:9.1f}  {ro:21.1f}  {tot:7.1f}  {ref[0] / ep:14.2f}  {ref[1] / tot:12.2f}",
                  flush=True)
            lines.append(f"#   world {w}, rank 0: {line}")
    print(f"# load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print("\n".join(lines))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("data")
    ap.add_argument("--worlds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--batches", type=int, nargs=2, default=[10, 40])
    ap.add_argument("--tc", default="build/bin/nao_toolchain")
    ap.add_argument("--epoch", action="store_true", help="time one whole epoch of a committed model's recipe")
    ap.add_argument("--recipe", choices=sorted(RECIPES), default="autonomous",
                    help="with --epoch: the paper configuration's autonomous recipe (default) or models/default.bin's")
    a = ap.parse_args()
    if a.epoch:
        main_epoch(a)
        return
    lo, hi = a.batches
    print(f"# {time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}, {os.cpu_count()} cores")
    print(f"# command: bench/train_scaling.py {a.data} --worlds {' '.join(map(str, a.worlds))} "
          f"--batches {lo} {hi}")
    print(f"# load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print("world  wall/batch (s)  cpu/batch per rank (s)  speed-up wall  speed-up cpu (busiest rank)")
    ref_wall = ref_cpu = None
    with tempfile.TemporaryDirectory(prefix="nao_scaling_") as d:
        for w in a.worlds:
            wall_lo, cpu_lo = run(a.tc, a.data, w, lo, d)
            wall_hi, cpu_hi = run(a.tc, a.data, w, hi, d)
            wall = (wall_hi - wall_lo) / (hi - lo)
            cpu = [(h - l) / (hi - lo) for h, l in zip(cpu_hi, cpu_lo)]
            if ref_wall is None:
                ref_wall, ref_cpu = wall, max(cpu)
            print(f"{w:5d}  {wall:14.3f}  {' '.join(f'{c:.3f}' for c in cpu):>22}  "
                  f"{ref_wall / wall:13.2f}  {ref_cpu / max(cpu):27.2f}", flush=True)
    print(f"# load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
