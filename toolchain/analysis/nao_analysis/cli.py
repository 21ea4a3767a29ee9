"""`toolchain/nao analyze`: run directories in, table2.csv/md, figures and report.html out."""

import argparse
import os
import shlex
import sys

from . import AnalysisError
from . import stats
from . import table2 as t2
from .rundir import read_run

PROG = "nao analyze"


def progress(message):
    print("%s: %s" % (PROG, message), file=sys.stderr, flush=True)


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        # One line, like every other error of the driver; exit 2 = command-line problem.
        print("nao: error: analyze: %s (see toolchain/nao analyze --help)" % message, file=sys.stderr)
        sys.exit(2)


def parse_args(argv):
    p = _Parser(prog=PROG, add_help=False)
    p.add_argument("--detrend", default=stats.DEFAULT_DETREND)
    p.add_argument("--out")
    p.add_argument("--bootstrap", type=int, default=t2.DEFAULT_BOOTSTRAP)
    p.add_argument("--seed", type=int, default=t2.DEFAULT_SEED)
    p.add_argument("--screenshot")
    p.add_argument("--reproduction", action="store_true")
    p.add_argument("run_dirs", nargs="+", metavar="RUN_DIR")
    args = p.parse_args(argv)
    if args.bootstrap < 100:
        p.error("--bootstrap needs at least 100 resamples, got %d" % args.bootstrap)
    return args


def run_labels(runs):
    """Names of the runs in file names and tables: the movement, unless two runs share it."""
    movements = [r.movement for r in runs]
    labels = []
    for r in runs:
        label = r.movement if movements.count(r.movement) == 1 else "%s-%s" % (r.movement, os.path.basename(r.path))
        labels.append("".join(c if c.isalnum() or c in "-_" else "_" for c in label))
    if len(set(labels)) != len(labels):
        raise AnalysisError("two run directories give the same name %s: pass each run once" % labels)
    return labels


def analyze(args, command):
    """The whole analysis; returns the output directory. Raises AnalysisError."""
    stats.parse_detrend(args.detrend)  # a bad method fails before any work
    runs = []
    for d in args.run_dirs:
        progress("reading %s" % d)
        runs.append(read_run(d))
    labels = run_labels(runs)
    out_dir = os.path.abspath(args.out or os.path.join(args.run_dirs[0], "analysis"))
    try:
        os.makedirs(out_dir, exist_ok=True)
    except OSError as e:
        raise AnalysisError("cannot create the output directory %s: %s" % (out_dir, e.strerror)) from None
    options = {"detrend": args.detrend, "bootstrap": args.bootstrap, "seed": args.seed, "out": out_dir}

    from . import protocol
    pooled = protocol.is_protocol(runs)
    if pooled:
        # The paper's protocol: several runs per movement, pooled with the run as the unit.
        groups = protocol.group_runs(runs)
        progress("protocol: %s" % ", ".join("%s %d run(s)" % (m, len(v)) for m, v in sorted(groups.items())))
        rows_by_prefix = protocol.protocol_rows(runs, args.detrend, args.bootstrap, args.seed, progress)
        rows = rows_by_prefix["att"]
        if "attm" in rows_by_prefix:
            with open(os.path.join(out_dir, "table2_attm.csv"), "w") as f:
                f.write(t2.table2_csv(rows_by_prefix["attm"]))
        found = protocol.findings(rows, groups)
        table, notes = protocol.offsets_markdown(groups, sorted(rows_by_prefix))
        with open(os.path.join(out_dir, "findings.md"), "w") as f:
            f.write("\n".join(["# Findings checklist", ""] + protocol.findings_markdown(found)
                              + ["", "# Attention offsets", ""] + table + [""] + notes) + "\n")
        # Figures of one run per movement (the first); the UMAP takes every run.
        shown = [(r, lab) for r, lab in zip(runs, labels) if r is groups[r.movement][0]]
    else:
        rows = []
        for run, label in zip(runs, labels):
            rows += t2.table2_rows(run, label, args.detrend, args.bootstrap, args.seed, progress)
        shown = list(zip(runs, labels))
    with open(os.path.join(out_dir, "table2.csv"), "w") as f:
        f.write(t2.table2_csv(rows))
    from . import report  # after the statistics: the tables are written even if a figure fails
    with open(os.path.join(out_dir, "table2.md"), "w") as f:
        f.write(report.table2_markdown(rows, options))

    from . import figures, kinematics
    arm = kinematics.load_arm_model()
    made = {}
    for run, label in shown:
        progress("%s: figures" % label)
        made[label] = [
            (figures.figure_ee(run, label, arm, out_dir),
             "%s: hand trajectory (paper Figs. 8–10): green human-derived target FK(q_ref), blue "
             "feature-extracted demonstration ee_ref, red robot ee; a–d mark the instants of the "
             "attention figure" % label),
            (figures.figure_attention(run, label, arm, out_dir),
             "%s: attention per body part over time and the robot pose at a–d (paper Figs. 11–13)" % label),
            (figures.figure_motion(run, label, out_dir),
             "%s: joint angle, velocity, acceleration and attention (paper Figs. 14–16)" % label)]
    progress("UMAP of %d runs' cross-attention outputs (numba compiles first: ~30 s)" % len(runs))
    made["umap"] = [(figures.figure_umap(runs, labels, out_dir),
                     "UMAP of the cross-attention outputs, coloured by run, time and movement phase")]
    profile = figures.figure_age_profile(runs, labels, out_dir)
    if profile is not None:
        made["age_profile"] = [(profile, "temporal attention profile: mean cross-attention mass per age of the "
                                         "attended tick, per movement (band: range over runs)")]
    with open(os.path.join(out_dir, "report.html"), "w") as f:
        f.write(report.report_html(runs, labels, rows, made, options, command))

    if args.screenshot:
        from .screenshot import screenshot_report
        progress("screenshot of report.html with headless Chromium")
        screenshot_report(os.path.join(out_dir, "report.html"), args.screenshot)
    if args.reproduction and pooled:
        from .reproduction import DOC, FIG_DIR, copy_figure
        progress("writing docs/reproduction.md and docs/figures/ (the paper's protocol)")
        names = []
        for run, label in shown:
            names += [("fig_attention_%s" % label, "%s: attention per body part and the robot pose at a–d "
                       "(paper Figs. 11–13), one autonomous rollout" % label),
                      ("fig_motion_%s" % label, "%s: joint angle, velocity, acceleration and attention "
                       "(paper Figs. 14–16), one autonomous rollout" % label)]
        names.append(("fig_umap", "UMAP of the last decoder layer's cross-attention outputs of every rollout, "
                      "by run, time and movement phase"))
        if "age_profile" in made:
            names.append(("fig_age_profile", "temporal attention profile: the last decoder layer's mean "
                          "cross-attention mass per age of the attended tick, per movement"))
        os.makedirs(FIG_DIR, exist_ok=True)
        for name, _ in names:
            copy_figure(os.path.join(out_dir, name + ".png"), os.path.join(FIG_DIR, name + ".png"))
        with open(DOC, "w") as f:
            f.write(protocol.reproduction_markdown(groups, rows_by_prefix, found, command, names))
    elif args.reproduction:
        from .reproduction import write_reproduction
        progress("writing docs/reproduction.md and docs/figures/")
        write_reproduction(out_dir, runs, labels, rows, options, command)
    return out_dir


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    args = parse_args(argv)
    command = os.environ.get("NAO_ANALYZE_COMMAND") or " ".join(
        shlex.quote(a) for a in ["toolchain/analysis/analyze.py"] + list(argv))
    try:
        out_dir = analyze(args, command)
    except AnalysisError as e:
        print("nao: error: analyze: %s" % e, file=sys.stderr)
        return 1
    print("%s: wrote table2.csv, table2.md, report.html and fig_*.png/svg to %s" % (PROG, out_dir))
    return 0
