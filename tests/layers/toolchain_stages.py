#!/usr/bin/env python3
"""The toolchain's stages include only earlier stages (toolchain/CMakeLists.txt).

usage: toolchain_stages.py [REPOSITORY]

toolchain/src holds one folder per stage of the offline pipeline, in this order:

  common    the command registry and the helpers every stage shares
  data      synthesiser, OpenPose, calibration, triangulation, replay, synthetic references
  retarget  Ceres retargeting, the embodiment gap
  cluster   k-means key poses
  policy    policy data set, policy execution, linear AR, arm copy
  eval      nao_toolchain evaluate (src/eval)
  train     the trainer (src/torch): its model selection runs the evaluation's measures
  app       nao_toolchain's main (toolchain/app)

A public header nao/tools/X.hpp (toolchain/include) is in the stage of the source that implements
it (X.cpp), or, header-only, in HEADER_ONLY's stage; a header in neither fails, so a new one must
be placed. A private header ("X.hpp" of a stage folder) is in its folder's stage; any other
quoted header is another target's (the runtime's). Every source
and header of the stages, and every public header, may include the runtime (nao/...) and headers
of its own or an earlier stage only. Exit 0 when all holds, 1 with one line per problem.
"""
import pathlib
import re
import sys

STAGES = [
    ("common", "toolchain/src/common"),
    ("data", "toolchain/src/data"),
    ("retarget", "toolchain/src/retarget"),
    ("cluster", "toolchain/src/cluster"),
    ("policy", "toolchain/src/policy"),
    ("eval", "toolchain/src/eval"),
    ("train", "toolchain/src/torch"),
    ("app", "toolchain/app"),
]
ORDER = {name: i for i, (name, _) in enumerate(STAGES)}

# Public headers with no source of their own: the stage that first needs them.
HEADER_ONLY = {
    "csv": "common",                 # the runtime's CSV reader
    "splitmix": "common",            # the one seeded generator
    "stats": "common",               # the runtime's median
    "camera": "data",                # the runtime's camera model
    "skeleton_csv": "data",          # the runtime's skeleton CSV
    "human_scale": "retarget",       # a demonstration's human scale
    "toolchain_dims": "policy",      # the policy dimensions run in process
    "attention_ablation": "eval",    # the evaluation's ablation probe
    "baseline_laws": "eval",         # the evaluation's closed-form baselines
}

INCLUDE = re.compile(r'^\s*#\s*include\s*([<"])([^">]+)[">]')


def main(root):
    problems = []
    src = root / "toolchain" / "src"
    known = {(root / d).resolve(): name for name, d in STAGES}
    for entry in sorted(src.iterdir()):
        if entry.is_dir() and entry.resolve() not in known:
            problems.append(f"{entry.relative_to(root)}: a folder that is no stage (known: "
                            f"{', '.join(name for name, _ in STAGES)})")
        elif entry.is_file() and entry.suffix in (".cpp", ".hpp"):
            problems.append(f"{entry.relative_to(root)}: outside the stage folders; move it to its stage")

    files = {}  # path -> stage
    implemented = {}  # base name -> stages of the sources of that name
    for name, d in STAGES:
        for f in sorted((root / d).glob("*.[ch]pp")):
            files[f.resolve()] = name
            if f.suffix == ".cpp":
                implemented.setdefault(f.stem, set()).add(name)

    public = root / "toolchain" / "include" / "nao" / "tools"
    header_stage = {}
    for h in sorted(public.glob("*.hpp")):
        stages = implemented.get(h.stem, set())
        where = f"toolchain/include/nao/tools/{h.name}"
        if h.stem in HEADER_ONLY:
            if stages:
                problems.append(f"{where}: in HEADER_ONLY and implemented by {h.stem}.cpp; keep one")
            stage = HEADER_ONLY[h.stem]
        elif len(stages) == 1:
            stage = next(iter(stages))
        elif stages:
            problems.append(f"{where}: {h.stem}.cpp in several stages ({', '.join(sorted(stages))})")
            continue
        else:
            problems.append(f"{where}: no stage (no {h.stem}.cpp in a stage folder); "
                            "add it to HEADER_ONLY in tests/layers/toolchain_stages.py")
            continue
        header_stage[h.stem] = stage
        files[h.resolve()] = stage
    for stem in sorted(set(HEADER_ONLY) - {h.stem for h in public.glob("*.hpp")}):
        problems.append(f"HEADER_ONLY names nao/tools/{stem}.hpp, which does not exist")

    for f, stage in sorted(files.items()):
        rel = f.relative_to(root)
        for n, line in enumerate(f.read_text(encoding="utf-8").splitlines(), 1):
            m = INCLUDE.match(line)
            if not m:
                continue
            delim, name = m.groups()
            if name.startswith("nao/tools/"):
                stem = name[len("nao/tools/"):]
                stem = stem[:-len(".hpp")] if stem.endswith(".hpp") else stem
                target = header_stage.get(stem)
                if target is None:
                    problems.append(f"{rel}:{n}: {name}: no such placed header")
                    continue
            elif delim == "<" or name.startswith("nao/"):
                continue  # a system or third-party header, or the runtime
            else:
                local = (f.parent / name).resolve()
                if local in files:
                    target = files[local]
                else:
                    # Not beside its includer: a header on another target's include path, the
                    # runtime's or a stage folder's (nao_eval_lib exports src/eval).
                    others = {files[g] for g in files if g.name == pathlib.PurePath(name).name and g.parent != public}
                    if not others:
                        continue
                    target = max(others, key=ORDER.get)
            if ORDER[target] > ORDER[stage]:
                problems.append(f"{rel}:{n}: stage {stage} includes {name} of the later stage {target} "
                                f"(order: {' < '.join(name for name, _ in STAGES)})")

    for p in problems:
        print(p)
    if not problems:
        print(f"{len(files)} files in {len(STAGES)} stages: every include is of its own or an earlier stage")
    return 1 if problems else 0


if __name__ == "__main__":
    root = pathlib.Path(sys.argv[1]) if len(sys.argv) > 1 else pathlib.Path(__file__).resolve().parents[2]
    sys.exit(main(root.resolve()))
