#!/usr/bin/python3
"""One training seed's Table 2 file for docs/reproduction.md, from its model: the autonomous
rollouts (`nao_toolchain evaluate`), then `toolchain/nao analyze` with the robustness variants.

usage: toolchain/analysis/seed_table.py --model FILE --training-seed N [--out JSON]
           [--eval DIR] [--analysis DIR] [--jobs N] [--nao-toolchain PATH [--nao-rt PATH] [--data DIR]]

  --model FILE         the seed's model.bin
  --training-seed N    the seed it was trained with (recorded in the file)
  --out JSON           the Table 2 file (default docs/reproduction/seed_N.json)
  --eval DIR           where the rollouts go (default out/eval_seedN; emptied first)
  --analysis DIR       analyze's tables and figures (default out/analysis/seed_N)
  --jobs N             nao_rt processes at a time in evaluate (default: evaluate's)
  --nao-toolchain PATH run this nao_toolchain's evaluate directly instead of
                       `toolchain/nao evaluate` (which builds build/ and makes the data set); then
                       --nao-rt PATH names the nao_rt for the model (default: the last line of
                       `toolchain/nao build --model FILE`) and --data DIR its data set
                       (default out/train/data, made by `toolchain/nao train data`)

Runs from the repository root, so the run directories in the file's command are relative.
Then `toolchain/nao analyze --reproduction-from docs/reproduction/seed_*.json --out
docs/reproduction.md` remakes the page (docs/analysis.md, "Regenerating docs/reproduction.md").
"""

import argparse
import glob
import os
import shlex
import shutil
import subprocess
import sys

REPO = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
NAO = "toolchain/nao"


def run(cmd, capture=False):
    """Runs cmd (a list) from the repository root, echoing it; exits on failure."""
    print("+ " + " ".join(shlex.quote(c) for c in cmd), file=sys.stderr, flush=True)
    done = subprocess.run(cmd, cwd=REPO, stdout=subprocess.PIPE if capture else None, text=True)
    if done.returncode != 0:
        sys.exit("seed_table: %s failed (exit %d)" % (cmd[0], done.returncode))
    return done.stdout


def main(argv=None):
    p = argparse.ArgumentParser(prog="toolchain/analysis/seed_table.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--model", required=True)
    p.add_argument("--training-seed", type=int, required=True)
    p.add_argument("--out")
    p.add_argument("--eval")
    p.add_argument("--analysis")
    p.add_argument("--jobs", type=int)
    p.add_argument("--nao-toolchain")
    p.add_argument("--nao-rt")
    p.add_argument("--data", default="out/train/data")
    args = p.parse_args(argv)
    seed = args.training_seed
    out = args.out or "docs/reproduction/seed_%d.json" % seed
    eval_dir = args.eval or "out/eval_seed%d" % seed
    analysis = args.analysis or "out/analysis/seed_%d" % seed
    model = os.path.relpath(os.path.abspath(args.model), REPO)

    # Old rollouts would be analysed with the new ones.
    shutil.rmtree(os.path.join(REPO, eval_dir), ignore_errors=True)
    evaluate = ["evaluate", "--model", model, "--no-reference", "--out", eval_dir]
    if args.jobs:
        evaluate += ["--jobs", str(args.jobs)]
    if args.nao_toolchain:
        nao_rt = args.nao_rt or run([NAO, "build", "--model", model], capture=True).strip().splitlines()[-1]
        run([args.nao_toolchain] + evaluate + ["--nao-rt", nao_rt, "--data", args.data])
    else:
        run([NAO] + evaluate)
    runs = sorted(os.path.relpath(d, REPO) for d in glob.glob(os.path.join(REPO, eval_dir, "*", "autonomous", "*"))
                  if os.path.isdir(d))
    if not runs:
        sys.exit("seed_table: evaluate wrote no run directory under %s/*/autonomous/" % eval_dir)
    run([NAO, "analyze", "--training-seed", str(seed), "--robustness", "--table-json", out, "--out", analysis] + runs)
    return 0


if __name__ == "__main__":
    sys.exit(main())
