"""`toolchain/nao analyze`: run directories in, table2.csv/md, figures and report.html out."""

import argparse
import os
import shlex
import sys

from . import JOINT_NAMES, AnalysisError
from . import stats
from . import table2 as t2
from .rundir import read_run
from .units import ROBUSTNESS_DTW_M, UNIT_DTW_M

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
    p.add_argument("--table-json", metavar="FILE")
    p.add_argument("--training-seed", type=int)
    p.add_argument("--robustness", action="store_true")
    p.add_argument("--reproduction-from", nargs="+", metavar="JSON")
    p.add_argument("run_dirs", nargs="*", metavar="RUN_DIR")
    args = p.parse_args(argv)
    if args.bootstrap < 100:
        p.error("--bootstrap needs at least 100 resamples, got %d" % args.bootstrap)
    if args.reproduction_from and args.run_dirs:
        p.error("--reproduction-from takes Table 2 files, not run directories (%s)" % args.run_dirs[0])
    if not args.reproduction_from and not args.run_dirs:
        p.error("no RUN_DIR given")
    if args.robustness and not args.table_json:
        p.error("--robustness adds to the --table-json file: give --table-json FILE")
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


def _name(run):
    return os.path.basename(run.path)


def run_models(runs):
    """[{path, checksum, conditioning}] of the models the runs' summary.json name."""
    models = sorted({(str(r.summary.get("model", {}).get("path", "?")),
                      str(r.summary.get("model", {}).get("checksum", "?")),
                      str(r.summary.get("model", {}).get("conditioning", "?"))) for r in runs})
    return [{"path": p, "checksum": c, "conditioning": k} for p, c, k in models]


def _grouping_json(units, separation):
    return dict({"n_units": len(units), "units": [[_name(r) for r in u] for u in units]}, **separation)


def movements_json(groups, units, separation, groupings):
    """The JSON's `movements`: per movement its runs, the distinct rollouts of the analysis and,
    for pooled runs, the groupings at every threshold."""
    out = {}
    for m in sorted(units):
        reps = [u[0] for u in units[m]]
        e = dict({"n_runs": len(groups[m]), "n_units": len(units[m]),
                  "n_ticks": int(sum(int(r.policy_mask().sum()) for r in reps))},
                 **_grouping_json(units[m], separation[m]))
        if m in groupings:
            e["groupings"] = [dict({"unit_dtw_m": t}, **_grouping_json(*groupings[m][t])) for t in sorted(groupings[m])]
        out[m] = e
    return out


def offsets_json(units):
    """The JSON's `attention_offsets` of each movement's distinct rollouts."""
    from . import protocol
    out = {}
    for m in sorted(units):
        share, mean, total = protocol.attention_offsets([u[0] for u in units[m]])
        out[m] = {"n_ticks": total, "top_share": dict(zip(JOINT_NAMES, map(float, share))),
                  "mean_score": dict(zip(JOINT_NAMES, map(float, mean)))}
    return out


def ablation_records(groups):
    """{movement: {run directory name: ablation.run_record or None}} (the JSON's `ablation_runs`)."""
    from . import ablation
    for m, runs in groups.items():
        names = [_name(r) for r in runs]
        if len(set(names)) != len(names):
            raise AnalysisError("two %s run directories share a name (%s): the Table 2 file names runs by their "
                                "directory" % (m, ", ".join(sorted({n for n in names if names.count(n) > 1}))))
    return {m: {_name(r): ablation.run_record(r) for r in groups[m]} for m in sorted(groups)}


def robustness_variants(args, groupings, rows, progress=None):
    """Table 2 (`att`) at the other distinct-rollout thresholds (this analysis' trend removal) and
    with the other trend removals (this threshold): [{unit_dtw_m, detrend, table2: {"att": rows}}].
    A movement whose units do not change with the threshold keeps its rows."""
    from . import protocol
    if not groupings:
        return []
    name = stats.parse_detrend(args.detrend)[0]
    cases = [(t, args.detrend) for t in sorted(next(iter(groupings.values()))) if t != UNIT_DTW_M]
    cases += [(UNIT_DTW_M, d) for d in ("linear", "highpass", "none") if d != name]
    variants = []
    for t, detrend in cases:
        if progress:
            progress("robustness: Table 2 at %g mm, --detrend %s" % (1e3 * t, detrend))
        out = []
        for m in sorted(groupings):
            units, main = groupings[m][t][0], groupings[m][UNIT_DTW_M][0]
            same = detrend == args.detrend and [[r.path for r in u] for u in units] == [[r.path for r in u] for u in main]
            out += ([r for r in rows if r["movement"] == m] if same else
                    protocol.pooled_rows(units, m, detrend, args.bootstrap, args.seed, "att", progress))
        variants.append({"unit_dtw_m": t, "detrend": detrend, "table2": {"att": out}})
    return variants


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

    from . import ablation, protocol
    pooled = protocol.is_protocol(runs)
    groups = protocol.group_runs(runs)
    thresholds = sorted(set(ROBUSTNESS_DTW_M) | {UNIT_DTW_M})
    groupings = {}
    if pooled:
        # The paper's protocol: several runs per movement, pooled with the distinct rollout as the unit.
        progress("protocol: %s; grouping near-copies into distinct rollouts (hand-path DTW)"
                 % ", ".join("%s %d run(s)" % (m, len(v)) for m, v in sorted(groups.items())))
        groupings = protocol.movement_groupings(runs, thresholds)
        units = {m: g[UNIT_DTW_M][0] for m, g in groupings.items()}
        separation = {m: g[UNIT_DTW_M][1] for m, g in groupings.items()}
        progress("distinct rollouts: %s" % ", ".join("%s %d of %d" % (m, len(units[m]), len(groups[m]))
                                                      for m in sorted(units)))
        prefixes = protocol.score_prefixes(runs)
        rows_by_prefix = protocol.protocol_rows(units, args.detrend, args.bootstrap, args.seed, prefixes, progress)
        rows = rows_by_prefix["att"]
        if "attm" in rows_by_prefix:
            with open(os.path.join(out_dir, "table2_attm.csv"), "w") as f:
                f.write(t2.table2_csv(rows_by_prefix["attm"]))
        # Figures of one run per movement (the first); the UMAP takes every run.
        shown = [(r, lab) for r, lab in zip(runs, labels) if r is groups[r.movement][0]]
    else:
        rows = []
        for run, label in zip(runs, labels):
            rows += t2.table2_rows(run, label, args.detrend, args.bootstrap, args.seed, progress)
        rows_by_prefix = {"att": rows}
        units = {m: [[r] for r in v] for m, v in groups.items()}
        separation = {m: {"max_dtw_within_unit_m": None, "min_dtw_between_units_m": None} for m in groups}
        shown = list(zip(runs, labels))
    options.update({"pooled": pooled, "permutations": protocol.N_PERM if pooled else "every shift",
                    "resampling_unit": "distinct rollout" if pooled else "circular block of ticks",
                    "unit_dtw_m": UNIT_DTW_M})
    progress("ablation and attention spread")
    records = ablation_records(groups)
    ablations = {m: ablation.summary_from_records([records[m][_name(u[0])] for u in units[m]], args.bootstrap,
                                                  args.seed) for m in sorted(units)}
    spreads = {m: ablation.mass_spread(units[m]) for m in sorted(units)}
    with open(os.path.join(out_dir, "table2.csv"), "w") as f:
        f.write(t2.table2_csv(rows))
    from . import report  # after the statistics: the tables are written even if a figure fails
    with open(os.path.join(out_dir, "table2.md"), "w") as f:
        f.write(report.table2_markdown(rows, options))
    findings = report.findings_markdown(rows, args.training_seed, units, ablations, spreads)
    with open(os.path.join(out_dir, "findings.md"), "w") as f:
        f.write(findings)
    if args.table_json:
        from .table_json import table_document, write_table_json
        variants = robustness_variants(args, groupings, rows_by_prefix["att"], progress) if args.robustness else ()
        doc = table_document(args.training_seed, run_models(runs), options, command,
                             movements_json(groups, units, separation, groupings), rows_by_prefix,
                             offsets_json(units), spreads, ablations, records, variants)
        write_table_json(args.table_json, doc)
        progress("wrote %s" % args.table_json)

    from . import figures, kinematics
    arm = kinematics.load_arm_model()
    made = {}
    for run, label in shown:
        progress("%s: figures" % label)
        made[label] = [
            (figures.figure_ee(run, label, arm, out_dir), figures.hand_path_caption(run, label)),
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
        f.write(report.report_html(runs, labels, rows, made, options, command, findings))

    if args.screenshot:
        from .screenshot import screenshot_report
        progress("screenshot of report.html with headless Chromium")
        screenshot_report(os.path.join(out_dir, "report.html"), args.screenshot)
    return out_dir


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    args = parse_args(argv)
    command = os.environ.get("NAO_ANALYZE_COMMAND") or " ".join(
        shlex.quote(a) for a in ["toolchain/analysis/analyze.py"] + list(argv))
    try:
        if args.reproduction_from:
            from .reproduction import DOC, write_reproduction
            doc, found, found_mi = write_reproduction(args.reproduction_from, command, args.out or DOC)
            print("%s: wrote %s: %s" % (PROG, doc, ", ".join("(%s) %s, MI %s" % (f["id"], f["verdict"], g["verdict"])
                                                            for f, g in zip(found, found_mi))))
            return 0
        out_dir = analyze(args, command)
    except AnalysisError as e:
        print("nao: error: analyze: %s" % e, file=sys.stderr)
        return 1
    print("%s: wrote table2.csv, table2.md, report.html and fig_*.png/svg to %s" % (PROG, out_dir))
    return 0
