"""table2.md and the self-contained report.html of one analysis (images embedded, no script)."""

import base64
import html
import json
import math
import os

from . import JOINT_NAMES
from . import stats
from .paper import CITATION, PAPER_TABLE2


def _shown(path):
    """A path as the user named it relative to the working directory: no machine paths in reports."""
    rel = os.path.relpath(os.path.abspath(path))
    return path if rel.startswith("..") else rel

STAT_LABELS = {"pearson_r": "Pearson r", "spearman_rho": "Spearman ρ", "kendall_tau": "Kendall τ-b",
               "mi_bits": "MI [bits]"}


def fmt(x, digits=3):
    return "–" if x is None or not math.isfinite(x) else "%.*f" % (digits, x)


def fmt_p(p):
    if p is None or not math.isfinite(p):
        return "–"
    return "%.3f" % p if p >= 0.001 else "%.1e" % p


def method_lines(options):
    """The method, one item per line, for table2.md, the report and docs/reproduction.md."""
    return [
        "Pair per movement × joint: joint angular velocity `numpy.gradient(q_j, t_s)` (rad/s) over "
        "every tick of ticks.csv, and the attention score `att_j` (last decoder layer, norm-based).",
        "Ticks: those where the policy was bypassed (fault bits human_timeout or policy_nonfinite: "
        "returning home, or a non-finite action) are dropped after the gradient (column n_dropped); "
        "ticks with only no_human keep the policy running on the held reference and are kept.",
        "Trend removal: %s; the same for both series of every row." % stats.describe_detrend(options["detrend"]),
        "Statistics: Pearson r, Spearman ρ (average ranks), Kendall τ-b, and mutual information in bits "
        "(Kraskov–Stögbauer–Grassberger estimator 1, k = %d, max-norm, series standardised, tie-breaking "
        "jitter 1e-10 from a fixed seed; not clipped at 0)." % stats.KSG_K,
    ] + (_pooled_method(options) if options.get("pooled") else _single_method(options)) + [
        "MI beside its null: the median and 95 % quantile of the MI over the null draws (columns "
        "mi_null_median, mi_null_q95), the excess over the median (mi_excess); KSG on smooth series reads "
        "autocorrelation as information, so an MI is evidence of dependence only above the null's 95 % quantile "
        "(mi_above_null). That quantile is the order statistic an MI must exceed for its permutation p-value "
        "(1 + #{null ≥ MI}) / (1 + draws) to fall below 0.05, so the two never disagree. The MI has no bootstrap "
        "interval: a resample repeats ticks, which KSG reads as information.",
        "Seeds: each row's bootstrap and jitter seed is CRC-32 of 'movement/joint/%d'; UMAP random_state 0."
        % options["seed"],
    ]


_P_FROM_INTERVAL = ("p-values of the correlations: read off the same resamples as the interval, the smallest α at "
                    "which the (1 − α) percentile interval excludes 0 (at least 1/(1 + resamples)); p < 0.05 "
                    "exactly when the 95 % interval excludes 0.")


def _single_method(options):
    return [
        "95%% intervals of the correlations: circular block bootstrap (Politis & Romano 1992), %d resamples, "
        "percentile interval; block length per row = the larger of the two series' Politis–White (2004/2009) "
        "automatic block length (column block_len, ticks)." % options["bootstrap"],
        _P_FROM_INTERVAL,
        "MI null: every circular shift s of the attention series with block_len ≤ s ≤ n − block_len (column "
        "n_shifts); one-sided (larger).",
    ]


def _pooled_method(options):
    return [
        "Units: the runs of a movement whose hand paths all lie within %g mm of each other (DTW mean distance "
        "over their common ticks; complete linkage, so no chain of near neighbours joins runs farther apart) "
        "repeat one rollout and form one distinct rollout (columns n_runs, n_units); each unit enters once, as "
        "its longest run, its series detrended on their own; the units are concatenated." % (1e3 * options["unit_dtw_m"]),
        "95%% intervals of the correlations: two-stage bootstrap over distinct rollouts (draw as many units as "
        "there are, with replacement, then resample each drawn unit by circular blocks of its own block length), "
        "%d resamples, percentile interval; none with fewer than 2 units." % options["bootstrap"],
        _P_FROM_INTERVAL,
        "MI null: %d permutations, each shifting every unit's attention series circularly by its own random "
        "shift between its block length and its length minus the block length; one-sided (larger)."
        % options["permutations"],
    ]


def findings_markdown(rows, training_seed, units, ablations, spreads):
    """findings.md of one analysis: the rule's check of each paper row on this seed alone (a
    verdict needs the training seeds together: --reproduction-from), the distinct rollouts, the
    attention's spread and the ablation."""
    from . import verdict

    seed = training_seed if training_seed is not None else 0
    found = verdict.judge({seed: {(r["movement"], r["joint"]): r for r in rows}})
    L = ["# The paper's findings on this analysis", "",
         "Criterion: " + verdict.CRITERION, "",
         "One seed (%s) is analysed here: the verdict over %d seeds comes from `toolchain/nao analyze "
         "--reproduction-from` on their `--table-json` files." % (
             "training seed %d" % training_seed if training_seed is not None else "training seed not given",
             verdict.N_SEEDS), ""]
    for f in found:
        L.append("- (%s) %s:" % (f["id"], f["title"]))
        for movement, joint, _, holds, why, row in f["checks"]:
            L.append("  - %s %s: ρ %s: %s" % (movement, joint, "%s [%s, %s]" % (
                fmt(row["spearman_rho"]), fmt(row["spearman_rho_ci_lo"]), fmt(row["spearman_rho_ci_hi"]))
                if row else "–", "holds" if holds else "does not hold (%s)" % why))
    L += ["", "# The paper's MI statements on this analysis", "", "Criterion: " + verdict.MI_CRITERION, ""]
    for f in verdict.judge_mi({seed: {(r["movement"], r["joint"]): r for r in rows}}):
        L.append("- (%s) %s" % (f["id"], f["statement"]))
        for movement, joint, kind, _, holds, why, row in f["checks"]:
            L.append("  - %s %s (%s): MI %s, null q95 %s: %s" % (
                movement, joint, kind, fmt(row["mi_bits"]) if row else "–", fmt(row["mi_null_q95"]) if row else "–",
                "holds" if holds else "does not hold (%s)" % why))
    L += ["", "# Distinct rollouts", ""]
    for m in sorted(units):
        L.append("- %s: %d run(s), %d distinct rollout(s)" % (m, sum(len(u) for u in units[m]), len(units[m])))
    L += ["", "# Attention spread (attention.bin mass per body part; uniform 0.20)", ""]
    for m in sorted(spreads):
        e = spreads[m]
        L.append("- %s: %s" % (m, "no format-2 masses" if e is None else
                               "%.2f–%.2f over %d ticks; variation over time %s" % (
                                   e["min"], e["max"], e["n_ticks"],
                                   " / ".join("%.0f %%" % (100 * x) for x in e["cv_over_time"]))))
    L += ["", "# Attention against ablation (ablation.csv)", ""]
    for m in sorted(ablations):
        e = ablations[m]
        L.append("- %s: %s" % (m, "not measured: no run has ablation.csv" if e is None else
                               "median per-tick ρ(mass, delta) %s [%s, %s]; top body part matches %s [%s, %s] "
                               "against a chance level of %s [%s, %s] (%s chance); attention %s the ablation" % (
                                   fmt(e["rho_median"]), fmt(e["rho_ci"][0]), fmt(e["rho_ci"][1]),
                                   fmt(e["top_match_rate"]), fmt(e["top_match_ci"][0]), fmt(e["top_match_ci"][1]),
                                   fmt(e["chance"]), fmt(e["chance_ci"][0]), fmt(e["chance_ci"][1]),
                                   "above" if e["above_chance"] else "not above",
                                   "predicts" if e["predicts"] else "does not predict")))
    return "\n".join(L) + "\n"


def table2_markdown(rows, options):
    lines = ["# Table 2: joint angular velocity vs attention score", "",
             "Trend removal: **%s**." % options["detrend"], ""]
    lines += ["- " + m for m in method_lines(options)]
    lines += ["", "Each cell: estimate [95% CI] and its p-value (correlations: from the bootstrap; MI: against "
                  "its null).", ""]
    head = (["movement", "joint"] + [STAT_LABELS[s] for s in stats.STAT_NAMES]
            + ["MI null median / q95", "MI excess", "runs / units", "n (dropped)", "block"])
    lines.append("| " + " | ".join(head) + " |")
    lines.append("|" + "---|" * len(head))
    for r in rows:
        cells = [r["movement"], r["joint"]]
        for s in stats.STAT_NAMES:
            cells.append("%s [%s, %s] p=%s" % (fmt(r[s]), fmt(r[s + "_ci_lo"]), fmt(r[s + "_ci_hi"]),
                                                fmt_p(r[s + "_p"])))
        cells += ["%s / %s" % (fmt(r["mi_null_median"]), fmt(r["mi_null_q95"])),
                  "%s%s" % (fmt(r["mi_excess"]), " (above q95)" if r["mi_above_null"] else ""),
                  "%d / %d" % (r["n_runs"], r["n_units"]),
                  "%d (%d)" % (r["n_ticks"], r["n_dropped"]), str(r["block_len"])]
        lines.append("| " + " | ".join(cells) + " |")
    runs = sorted({(r["run"], r["movement"]) for r in rows})
    lines += ["", "Runs: " + ", ".join("%s (%s)" % (_shown(run), m) for run, m in runs) + ".", ""]
    return "\n".join(lines)


def _img(out_dir, name, alt):
    with open(os.path.join(out_dir, name + ".png"), "rb") as f:
        data = base64.b64encode(f.read()).decode("ascii")
    return ('<figure><img alt="%s" src="data:image/png;base64,%s"><figcaption>%s '
            '(<code>%s.png</code>, <code>%s.svg</code>)</figcaption></figure>'
            % (html.escape(alt), data, html.escape(alt), name, name))


def _table2_html(rows):
    head = "".join("<th>%s</th><th>95%% CI</th><th>p</th>" % html.escape(STAT_LABELS[s]) for s in stats.STAT_NAMES)
    out = ["<table><thead><tr><th>movement</th><th>joint</th>%s<th>MI null median</th><th>MI null q95</th>"
           "<th>MI excess</th><th>runs</th><th>units</th><th>n</th><th>dropped</th><th>block</th>"
           "<th>shifts</th></tr></thead><tbody>" % head]
    for r in rows:
        cells = ["<td>%s</td><td>%s</td>" % (html.escape(r["movement"]), html.escape(r["joint"]))]
        for s in stats.STAT_NAMES:
            p = r[s + "_p"]
            cls = ' class="sig"' if math.isfinite(p) and p < 0.05 else ""
            cells.append("<td%s>%s</td><td>[%s, %s]</td><td%s>%s</td>"
                         % (cls, fmt(r[s]), fmt(r[s + "_ci_lo"]), fmt(r[s + "_ci_hi"]), cls, fmt_p(p)))
        cls = ' class="sig"' if r["mi_above_null"] else ""
        cells.append("<td>%s</td><td>%s</td><td%s>%s</td><td>%d</td><td>%d</td>"
                     % (fmt(r["mi_null_median"]), fmt(r["mi_null_q95"]), cls, fmt(r["mi_excess"]), r["n_runs"],
                        r["n_units"]))
        cells.append("<td>%d</td><td>%d</td><td>%d</td><td>%d</td>"
                     % (r["n_ticks"], r["n_dropped"], r["block_len"], r["n_shifts"]))
        out.append("<tr>%s</tr>" % "".join(cells))
    out.append("</tbody></table>")
    return "\n".join(out)


def _paper_html(rows):
    ours = {(r["movement"], r["joint"]): r for r in rows}
    out = ["<table><thead><tr><th>movement</th><th>paper joint</th><th>our joint</th>"
           "<th>ρ paper</th><th>ρ ours</th><th>τ paper</th><th>τ ours</th><th>r paper</th><th>r ours</th>"
           "<th>MI paper</th><th>MI ours</th></tr></thead><tbody>"]
    for movement, _, pj, joint, rho, tau, r, mi in PAPER_TABLE2:
        o = ours.get((movement, joint))
        if o is None:
            continue
        out.append("<tr><td>%s</td><td>%s</td><td>%s</td>%s</tr>" % (
            movement, pj, joint, "".join("<td>%.3f</td><td>%s</td>" % (p, fmt(o[s])) for p, s in
                                         ((rho, "spearman_rho"), (tau, "kendall_tau"), (r, "pearson_r"),
                                          (mi, "mi_bits")))))
    out.append("</tbody></table>")
    if len(out) == 2:
        return "<p>No run of the paper's movements (whole_arm, elbow, wrist) in this analysis.</p>"
    return "\n".join(out)


def nao_rt_command(summary, run_path):
    """The nao_rt command line that reproduces a run, from its summary.json (None if unknown)."""
    ref = str(summary.get("reference", ""))
    if not ref.startswith("synthetic:"):
        return None
    args = ["build/bin/nao_rt", "--reference", ref.split()[0], "--seed", str(summary.get("seed", 1))]
    model = summary.get("model", {}).get("path")
    if model and model != "compiled-in":
        args += ["--weights", model]
    if summary.get("realtime"):
        args.append("--realtime")
    return " ".join(args + ["--log", _shown(run_path)])


CSS = """
body { font-family: sans-serif; margin: 1.5em auto; max-width: 1250px; color: #222; line-height: 1.4; }
h1 { font-size: 1.5em; margin-bottom: 0.2em; } h2 { border-bottom: 1px solid #ccc; margin-top: 1.6em; }
table { border-collapse: collapse; font-size: 0.74em; margin: 0.6em 0; }
th, td { border: 1px solid #ccc; padding: 2px 4px; text-align: right; } td { white-space: nowrap; }
th { background: #f0f0f0; } td:first-child, td:nth-child(2), th:first-child, th:nth-child(2) { text-align: left; }
td.sig { background: #e3f2e3; font-weight: bold; }
pre, code { background: #f6f6f6; font-size: 0.85em; } pre { padding: 0.6em; overflow-x: auto; }
figure { margin: 1em 0; } img { max-width: 100%; border: 1px solid #eee; }
figcaption { font-size: 0.85em; color: #555; } .note { color: #555; font-size: 0.9em; }
"""


# What a newcomer needs to read the page.
READING_NOTE = (
    "<h2>How to read this page</h2><ul>"
    "<li>The policy reads the arm as five tokens, one per joint (body part), and at every tick "
    "spreads its attention over them: the attention score of a joint is how much of it that body "
    "part gets. The paper asks whether the policy attends to the joints that move.</li>"
    "<li><b>Table 2</b> answers per movement and joint: the correlation (Pearson, Spearman, Kendall) "
    "and the mutual information between the joint's angular velocity and its attention score over "
    "the runs. Shaded cells are significant; the paper's own values stand beside them.</li>"
    "<li><b>Each run</b>: its hand path beside the demonstration's (Figs. 8–10; red is the robot), "
    "the attention per body part over time with the robot's pose at four instants a–d "
    "(Figs. 11–13), and each joint's angle, velocity and acceleration under its attention score "
    "(Figs. 14–16): where attention rises with a joint's speed, the policy watches the part that "
    "moves.</li>"
    "<li><b>UMAP</b>: the cross-attention outputs of every tick in two dimensions, coloured by run, "
    "time and movement phase: how the policy's internal state travels through a movement.</li></ul>")


def report_html(runs, labels, rows, figures, options, command, findings=None):
    """The whole page as one string. figures: {label or 'umap': [(name, caption), ...]};
    findings: findings.md's text, shown as it is."""
    out_dir = options["out"]
    parts = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
             "<title>nao-rt attention–motion analysis</title><style>%s</style></head><body>" % CSS,
             "<h1>nao-rt attention–motion analysis</h1>",
             '<p class="note">Paper Table 2 and Figs. 8–16 from nao_rt runs, with what the '
             "paper lacks: bootstrap confidence intervals, shift-test p-values and the null of every mutual "
             "information (runs that repeat one rollout count once).</p>",
             READING_NOTE,
             "<h2>Command</h2><pre>%s</pre>" % html.escape(command),
             "<p>Runs: %s. Output: <code>%s</code>.</p>" % (
                 ", ".join("<code>%s</code> (%s)" % (html.escape(_shown(r.path)), html.escape(lab)) for r, lab in zip(runs, labels)),
                 html.escape(_shown(out_dir))),
             "<h2>Table 2: angular velocity vs attention score</h2>",
             "<p>Cells with p &lt; 0.05 (shift test) are shaded. Trend removal: <b>%s</b>.</p>"
             % html.escape(options["detrend"]),
             _table2_html(rows),
             "<h3>Method</h3><ul>%s</ul>" % "".join("<li>%s</li>" % html.escape(m).replace("`", "")
                                                      for m in method_lines(options)),
             "<h3>Beside the paper's Table 2</h3>",
             "<p class=\"note\">The paper's “Elbow roll” is NAOqi's RElbowYaw (its Table 1 ranges). "
             "Source: %s.</p>" % html.escape(CITATION),
             _paper_html(rows)]
    if findings:
        parts.append("<h2>Findings, distinct rollouts, attention spread, ablation</h2><pre>%s</pre>"
                     % html.escape(findings))
    for run, lab in zip(runs, labels):
        parts.append("<h2>Run %s</h2>" % html.escape(lab))
        for name, caption in figures.get(lab, []):
            parts.append(_img(out_dir, name, caption))
    if figures.get("umap"):
        parts.append("<h2>UMAP of the cross-attention outputs</h2>")
        for name, caption in figures["umap"]:
            parts.append(_img(out_dir, name, caption))
    parts.append("<h2>Runs: summary.json and commands</h2>")
    for run, lab in zip(runs, labels):
        cmd = nao_rt_command(run.summary, run.path)
        parts.append("<h3>%s</h3>" % html.escape(lab))
        parts.append("<p><code>%s</code>: %d ticks, %d of them dropped from Table 2 (policy bypassed).</p>"
                     % (html.escape(_shown(run.path)), run.n_ticks, run.n_ticks - int(run.policy_mask().sum())))
        if cmd:
            parts.append("<p>nao_rt command (rebuilt from summary.json):</p><pre>%s</pre>" % html.escape(cmd))
        parts.append("<pre>%s</pre>" % html.escape(json.dumps(run.summary, indent=2)))
    parts.append("<p class=\"note\">Joint order: %s. Files: table2.csv, table2.md, fig_*.png/svg in "
                 "the output directory.</p>" % ", ".join(JOINT_NAMES))
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"
